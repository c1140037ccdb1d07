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

# pytest exits 5 when it collects no test; that is a failure of the suite, say so clearly.
test: $(STAMP)
	$(BIN)/python -m pytest -q; rc=$$?; \
	if [ $$rc -eq 5 ]; then echo "no tests were collected"; exit 1; fi; exit $$rc

lint: $(STAMP)
	$(BIN)/ruff check diegocal tests scripts bench

robots: $(STAMP)
	$(BIN)/python scripts/make_robots.py robots
	$(BIN)/python scripts/make_dynamics_robots.py robots

sample-data: $(STAMP)
	$(BIN)/python scripts/make_sample_data.py sample_data

# The main job on the bundled sample data: calibrate, fit, predict held-out, report.
# The real TX40 and TIAGo logs of ../shared/data/real, converted to diegocal logs (not committed).
real-data: $(STAMP)
	$(BIN)/python scripts/convert_real.py out/real

demo: $(STAMP)
	@mkdir -p $(OUT)
	$(DIEGOCAL) report sample_data/*.h5 -o $(OUT)/report.pdf
	@echo "wrote $(OUT)/report.pdf"

bench: $(STAMP)
	$(BIN)/python -m pytest -q -m slow
	for b in bench/bench_*.py; do echo "== $$b"; $(BIN)/python $$b || exit 1; done

clean:
	rm -rf $(OUT) .pytest_cache

# Domain fragments (e.g. the per-chamber pneumatic batch fit).
-include mk/*.mk
