"""Log files (HDF5, CSV), YAML parameter files and validation: the only code that opens files."""

from diegocal.io.files import (
    atomic_path,
    dump_yaml,
    load_log,
    load_yaml,
    q_log_path,
    save_log,
    save_logs,
    save_yaml,
    write_text,
)
from diegocal.io.log import JOINT_STREAMS, Log, Stream, Truth, check_log, make_stream, split_log

__all__ = [
    "q_log_path",
    "JOINT_STREAMS",
    "Log",
    "Stream",
    "Truth",
    "atomic_path",
    "check_log",
    "dump_yaml",
    "load_log",
    "load_yaml",
    "make_stream",
    "split_log",
    "save_log",
    "save_logs",
    "save_yaml",
    "write_text",
]
