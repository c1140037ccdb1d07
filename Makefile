# diegocal: two commands set everything up on a fresh machine with python3 and make.
#   make demo   -> .venv, install, run the main job on sample_data/, write out/report.pdf
#   make test   -> .venv if needed, run the test suite (slow cases are left to `make bench`)
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
DIEGOCAL := $(BIN)/diegocal
OUT := out

.PHONY: demo test bench lint sample-data robots real-data clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[dev]'
	touch $(STAMP)

# The suite runs on every core, four at most (pytest-xdist; a file's tests stay on one worker,
# which shares its fixtures); TEST_WORKERS=0 runs it in one process.
# pytest exits 5 when it collects no test; that is a failure of the suite, say so clearly.
TEST_WORKERS ?= auto
test: $(STAMP)
	$(BIN)/python -m pytest -q -n $(TEST_WORKERS) --maxprocesses 4 --dist loadfile; rc=$$?; \
	if [ $$rc -eq 5 ]; then echo "no tests were collected"; exit 1; fi; exit $$rc

lint: $(STAMP)
	$(BIN)/ruff check diegocal tests scripts bench experiments

robots: $(STAMP)
	$(BIN)/python scripts/make_robots.py robots
	$(BIN)/python scripts/make_dynamics_robots.py robots

sample-data: $(STAMP)
	$(BIN)/python scripts/make_sample_data.py sample_data

# The real-robot logs in sample_data/real (Stäubli TX40, PAL TIAGo), imported from the published
# recordings with the maps committed beside them. REAL_DATA: where the recordings are.
REAL_DATA ?= ../shared/data/real
real-data: $(STAMP)
	$(DIEGOCAL) import $(REAL_DATA)/tx40/pos_read_data.csv $(REAL_DATA)/tx40/curr_data.csv --map sample_data/real/tx40.map.yaml -o sample_data/real/tx40.h5
	$(DIEGOCAL) import $(REAL_DATA)/tiago/tiago_position.csv $(REAL_DATA)/tiago/tiago_effort.csv --map sample_data/real/tiago.map.yaml -o sample_data/real/tiago.h5

# The main job on the bundled sample data: calibrate, fit, predict held-out, diagnose one hidden
# effect per domain (what the model gets wrong, the named cause, the held-out gain), report; the
# report command ends with the summary in plain words. Held-out sessions of the pneumatic and arm3
# robots are simulated (other seeds, same robots: a pneumatic robot's valves are its own whatever
# the seed, arm3's friction is that of the sample's --seed 1 by --robot-seed); the kinematic one
# is the sample's last 4 s.
DIAGNOSES := $(OUT)/kinematics.diagnosis.yaml $(OUT)/dynamics.diagnosis.yaml $(OUT)/pneumatics.diagnosis.yaml
HELDOUT := sample_data/diego_kinematics_heldout.h5 $(OUT)/pneumatics_heldout.h5 $(OUT)/arm3_heldout.h5
demo: $(STAMP)
	@mkdir -p $(OUT)
	@printf '\n== demo %s\n' "1/7 kinematic calibration (STAC) of the 38 pots and 24 markers of diego"
	$(DIEGOCAL) stac sample_data/diego_kinematics.h5 -o $(OUT)/calib.yaml --quiet
	@printf '\n== demo %s\n' "2/7 held-out check: markers predicted from the pots alone"
	$(DIEGOCAL) predict $(OUT)/calib.yaml sample_data/diego_kinematics_heldout.h5 --from pots --to markers -o $(OUT)/kinematics_prediction.h5
	@printf '\n== demo %s\n' "3/7 pneumatic models of the 76 valve-chamber systems of diego"
	$(DIEGOCAL) pneumatic-fit sample_data/diego_pneumatics.h5 --all --jobs 2 -o $(OUT)/pneumatic.yaml --quiet
	$(DIEGOCAL) simulate pneumatics --robot diego --duration 8 --seed 2 -o $(OUT)/pneumatics_heldout.h5 --quiet
	@printf '\n== demo %s\n' "4/7 torque model of the 3-link arm (SGP)"
	$(DIEGOCAL) sgp-fit sample_data/arm3_dynamics.h5 --model sgp -o $(OUT)/arm3.sgp --quiet
	$(DIEGOCAL) simulate dynamics --robot arm3 --duration 8 --rate 50 --seed 2 --robot-seed 1 --trajectory figure8-horizontal \
		--effect position_friction:joint3 --region joint3:1.3:1.6 -o $(OUT)/arm3_heldout.h5 --quiet
	@printf '\n== demo %s\n' "5/7 diagnosis, kinematics: finger with a hidden pot nonlinearity"
	$(DIEGOCAL) diagnose sample_data/finger_hidden_nonlinearity.h5 -o $(OUT)/kinematics.diagnosis.yaml --quiet
	@printf '\n== demo %s\n' "6/7 diagnosis, dynamics and pneumatics: hidden friction, hidden valve delay"
	$(DIEGOCAL) diagnose sample_data/arm3_hidden_friction.h5 -o $(OUT)/dynamics.diagnosis.yaml --quiet
	$(DIEGOCAL) diagnose sample_data/diego_hidden_valve_delay.h5 -o $(OUT)/pneumatics.diagnosis.yaml --quiet
	@printf '\n== demo %s\n' "7/7 report"
	$(DIEGOCAL) report sample_data/diego_kinematics.h5 $(OUT)/calib.yaml $(OUT)/pneumatic.yaml $(OUT)/arm3.sgp \
		$(DIAGNOSES) $(addprefix --heldout ,$(HELDOUT)) -o $(OUT)/report.pdf

bench: $(STAMP)
	$(BIN)/python -m pytest -q -m slow
	for b in bench/bench_*.py; do echo "== $$b"; $(BIN)/python $$b || exit 1; done

clean:
	rm -rf $(OUT) .pytest_cache

# Domain fragments (e.g. the per-chamber pneumatic batch fit).
-include mk/*.mk
