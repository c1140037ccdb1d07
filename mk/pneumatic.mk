# Pneumatic valve-chamber models (thesis ch. 4): simulate, fit every chamber into its own YAML
# (parallel with `make -j`), merge, predict held-out data and draw the report.
#
#   make -j2 pneumatic-fit-batch            # one fit per chamber, then out/pneumatic/pneumatic.yaml
#   make pneumatic-report                   # out/pneumatic/report.pdf (Fig. 4.10-4.13)
#   make pneumatic-bench                    # bench/bench_pneumatic.py (76 chambers x 10^5 samples)
#
# Override PNEU_LOG / PNEU_ROBOT to fit recorded data instead of the simulated session.
# Expects BIN and DIEGOCAL from the main Makefile.

PNEU_ROBOT ?= robots/diego
PNEU_OUT ?= out/pneumatic
PNEU_LOG ?= $(PNEU_OUT)/flail.h5
PNEU_HELDOUT ?= $(PNEU_OUT)/heldout.h5
PNEU_SWEEP ?= $(PNEU_OUT)/sweep.h5
PNEU_SIM ?= --duration 100 --sessions 2
# Chamber names, read from sensors.yaml (with the .venv's Python) only when a goal below needs them:
# reading the Makefile for any other goal runs no Python (a fresh clone has no .venv yet, and
# `make demo` would open with ".venv/bin/python: not found").
PNEU_GOALS := pneumatic-fit-batch pneumatic-predict pneumatic-report $(PNEU_OUT)/pneumatic.yaml
ifneq ($(filter $(PNEU_GOALS),$(MAKECMDGOALS)),)
PNEU_CHAMBERS := $(shell $(BIN)/python -c "import yaml; print(' '.join(c['name'] for c in yaml.safe_load(open('$(PNEU_ROBOT)/sensors.yaml'))['chambers']))")
endif
PNEU_FILES = $(addprefix $(PNEU_OUT)/chambers/,$(addsuffix .yaml,$(PNEU_CHAMBERS)))

.PHONY: pneumatic-data pneumatic-fit-batch pneumatic-predict pneumatic-report pneumatic-bench

$(PNEU_OUT)/flail.h5: | $(STAMP)
	@mkdir -p $(@D)
	$(DIEGOCAL) simulate pneumatics --robot $(PNEU_ROBOT) -o $@ $(PNEU_SIM) --seed 1 -q

$(PNEU_HELDOUT): | $(STAMP)
	@mkdir -p $(@D)
	$(DIEGOCAL) simulate pneumatics --robot $(PNEU_ROBOT) -o $@ --duration 60 --seed 2 -q

$(PNEU_SWEEP): | $(STAMP)
	@mkdir -p $(@D)
	$(DIEGOCAL) simulate pneumatics --robot $(PNEU_ROBOT) -o $@ --experiment steady-state --duration 60 --seed 3 -q

pneumatic-data: $(PNEU_LOG) $(PNEU_HELDOUT) $(PNEU_SWEEP)

# One chamber per target: `make -j N` runs N fits at once.
$(PNEU_OUT)/chambers/%.yaml: $(PNEU_LOG) $(PNEU_SWEEP)
	@mkdir -p $(@D)
	$(DIEGOCAL) pneumatic-fit $(PNEU_LOG) --robot $(PNEU_ROBOT) --chamber $* --steady-state $(PNEU_SWEEP) -o $@ -q

$(PNEU_OUT)/pneumatic.yaml: $(PNEU_FILES)
	$(DIEGOCAL) pneumatic-merge $^ -o $@ -q

pneumatic-fit-batch: $(PNEU_OUT)/pneumatic.yaml

pneumatic-predict: $(PNEU_OUT)/pneumatic.yaml $(PNEU_HELDOUT)
	$(DIEGOCAL) predict $(PNEU_OUT)/pneumatic.yaml $(PNEU_HELDOUT) -o $(PNEU_OUT)/heldout.prediction.h5

pneumatic-report: $(PNEU_OUT)/pneumatic.yaml
	$(DIEGOCAL) report $< -o $(PNEU_OUT)/report.pdf

pneumatic-bench: | $(STAMP)
	$(BIN)/python bench/bench_pneumatic.py
