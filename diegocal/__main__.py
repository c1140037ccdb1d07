from diegocal.cli import main

main()
