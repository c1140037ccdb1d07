# Batch runs over a folder of logs: one output per log (per chamber, per domain), `make -j N` runs
# N at once, a rerun remakes only what is older than its log. Each goal ends with the merged table
# BATCH_OUT/<command>.batch.csv and its report page (.pdf), written by `diegocal batch` once every
# output has been tried. Outputs go to BATCH_OUT, never beside the logs.
#
#   make -j2 calibrate LOGS=folder      stac           -> BATCH_OUT/<log>.calib.yaml
#   make -j2 identify LOGS=folder       sgp-fit        -> BATCH_OUT/<log>.sgp/
#   make -j2 pneumatic-models LOGS=folder   pneumatic-fit, one target per chamber
#                                       -> BATCH_OUT/<log>.chambers/<chamber>.yaml, merged into <log>.pneumatic.yaml
#   make -j2 diagnoses LOGS=folder      diagnose, one target per log and domain -> BATCH_OUT/<log>.<domain>.diagnosis.yaml
#   make -j2 batch LOGS=folder          all four
#
# A log that fails never stops the others: each goal makes its outputs in a second make run with -k
# (--keep-going), then writes the table whatever failed; `diegocal batch` puts each failure in it
# (one line each on the terminal too: a log that cannot be read, a calibration that did not
# converge) and exits 1, so make ends with an error. After a fix the rerun remakes only what failed.
#
# One output by its name: make BATCH_OUT/<log>.calib.yaml (e.g. make
# out/batch/sample_data/diego_kinematics.calib.yaml), or make out/<log>.calib.yaml for a log of LOGS
# (out/diego_kinematics.calib.yaml; also .sgp/sgp.yaml and .<domain>.diagnosis.yaml).
#
# Only the logs a command can use are taken (`diegocal batch COMMAND LOGS --list`), so a folder may
# mix kinematic, dynamic and pneumatic sessions. BATCH_ROBOT=DIR names the robot when the logs'
# `robot` attribute does not; BATCH_ARGS go to every fit (e.g. BATCH_ARGS='--loss huber' for stac alone).
# Expects BIN, DIEGOCAL, OUT and STAMP from the main Makefile.

LOGS ?= sample_data
BATCH_OUT ?= out/batch/$(notdir $(abspath $(LOGS)))
BATCH_ROBOT ?=
BATCH_ARGS ?=
robot_arg = $(if $(BATCH_ROBOT),--robot $(BATCH_ROBOT))
BATCH_GOALS := calibrate identify pneumatic-models diagnoses batch
DOMAINS := kinematics dynamics pneumatics

.PHONY: $(BATCH_GOALS) $(addsuffix -outputs,$(BATCH_GOALS))

# The logs a command applies to; asked only when a batch goal is being made.
batch_logs = $(shell $(DIEGOCAL) batch $(1) $(LOGS) --list $(if $(2),-- $(2)) 2>/dev/null)
stems = $(basename $(notdir $(1)))
batch_table = mkdir -p $(BATCH_OUT) && $(DIEGOCAL) batch $(1) $(LOGS) -o $(BATCH_OUT) -q -- $(robot_arg) $(BATCH_ARGS)
# A goal: its outputs by a second make that keeps going past a failure (-k), then the table.
keep_going = +-@$(MAKE) --no-print-directory -k $(1)-outputs

# Each list is asked for (one `diegocal batch --list` call) only when the second make needs it.
wants = $(filter $(1)-outputs,$(MAKECMDGOALS))
ifneq ($(call wants,calibrate),)
CALIB_FILES := $(patsubst %,$(BATCH_OUT)/%.calib.yaml,$(call stems,$(call batch_logs,stac)))
endif
ifneq ($(call wants,identify),)
SGP_FILES := $(patsubst %,$(BATCH_OUT)/%.sgp/sgp.yaml,$(call stems,$(call batch_logs,sgp-fit)))
endif
ifneq ($(call wants,diagnoses),)
DIAGNOSIS_FILES := $(foreach d,$(DOMAINS),\
	$(patsubst %,$(BATCH_OUT)/%.$(d).diagnosis.yaml,$(call stems,$(call batch_logs,diagnose,--domain $(d)))))
endif
PNEUMATIC_MODELS :=
ifneq ($(call wants,pneumatic-models),)
PNEU_BATCH_LOGS := $(call batch_logs,pneumatic-fit)
-include $(BATCH_OUT)/pneumatic.mk
endif

# Pattern rules per log suffix and output folder: each output depends on the log it was made from.
define batch_rules
$(2)/%.calib.yaml: $(LOGS)/%.$(1) | $(STAMP)
	@mkdir -p $$(@D)
	$(DIEGOCAL) stac $$< -o $$@ -q $$(robot_arg) $(BATCH_ARGS)
$(2)/%.sgp/sgp.yaml: $(LOGS)/%.$(1) | $(STAMP)
	@mkdir -p $$(@D)
	$(DIEGOCAL) sgp-fit $$< -o $$(@D) -q $$(robot_arg) $(BATCH_ARGS)
endef
define diagnose_rule
$(3)/%.$(2).diagnosis.yaml: $(LOGS)/%.$(1) | $(STAMP)
	@mkdir -p $$(@D)
	$(DIEGOCAL) diagnose $$< --domain $(2) -o $$@ -q $$(robot_arg) $(BATCH_ARGS)
endef
$(foreach dir,$(sort $(BATCH_OUT) $(OUT)),$(foreach ext,h5 hdf5 csv,$(eval $(call batch_rules,$(ext),$(dir)))\
	$(foreach d,$(DOMAINS),$(eval $(call diagnose_rule,$(ext),$(d),$(dir))))))

# Per-chamber rules depend on each log's chambers: generated, then included (make restarts once).
$(BATCH_OUT)/pneumatic.mk: $(PNEU_BATCH_LOGS) | $(STAMP)
	@mkdir -p $(@D)
	$(BIN)/python -m diegocal.batch.make pneumatic $(BATCH_OUT) $(PNEU_BATCH_LOGS) $(robot_arg) > $@.tmp
	mv $@.tmp $@

calibrate:
	$(call keep_going,calibrate)
	$(call batch_table,stac)
calibrate-outputs: $(CALIB_FILES)

identify:
	$(call keep_going,identify)
	$(call batch_table,sgp-fit)
identify-outputs: $(SGP_FILES)

pneumatic-models:
	$(call keep_going,pneumatic-models)
	$(call batch_table,pneumatic-fit)
pneumatic-models-outputs: $(PNEUMATIC_MODELS)

diagnoses:
	$(call keep_going,diagnoses)
	$(call batch_table,diagnose)
diagnoses-outputs: $(DIAGNOSIS_FILES)

batch: calibrate identify pneumatic-models diagnoses
