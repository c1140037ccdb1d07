"""Batch runs: one command over every log of a folder, locally or on a Dask cluster, and the
merged table of their results (see :mod:`diegocal.batch.jobs` and :mod:`diegocal.batch.table`)."""

from diegocal.batch.jobs import (
    COMMANDS,
    BatchOptions,
    Job,
    Outcome,
    Plan,
    command_line,
    find_logs,
    job_args,
    output_path,
    plan_batch,
    run_batch,
    run_job,
)
from diegocal.batch.table import HEADLINE, read_table, save_table

__all__ = [
    "COMMANDS",
    "HEADLINE",
    "BatchOptions",
    "Job",
    "Outcome",
    "Plan",
    "command_line",
    "find_logs",
    "job_args",
    "output_path",
    "plan_batch",
    "read_table",
    "run_batch",
    "run_job",
    "save_table",
]
