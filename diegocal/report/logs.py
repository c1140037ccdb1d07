"""The report's log section: an `inspect`-style page per log and its stream traces."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from diegocal.io import load_log
from diegocal.io.describe import LogSummary, describe_log
from diegocal.io.files import log_robot
from diegocal.report.registry import Section, register_section
from diegocal.report.style import axes_or_new, page, save_page, text_page

LOG_SUFFIXES = (".h5", ".hdf5", ".csv")


def summary_lines(s: LogSummary) -> list[str]:
    lines = [
        f"robot: {s.robot or '-'}",
        f"samples: {s.n_samples}",
        f"duration: {s.duration:.3f} s",
        f"rate: {s.rate_hz:.4g} Hz",
        f"ground truth (/truth): {'yes' if s.has_truth else 'no'}",
        "",
    ]
    for st in s.streams:
        lines.append(f"{st.name}: {len(st.names)} channels, shape {st.shape}")
        if st.name == "markers":
            occ = ", ".join(f"{n} {100 * f:.0f}%" for n, f in zip(st.names, st.nan_fraction, strict=True))
            lines += _wrap(f"  occluded: {occ}")
        else:
            lines += _wrap("  " + ", ".join(st.names))
    return lines


def _wrap(text: str, width: int = 95) -> list[str]:
    out, line = [], ""
    for word in text.split(" "):
        if len(line) + len(word) + 1 > width:
            out.append(line)
            line = "    "
        line += word + " "
    return out + [line]


def plot_stream(log, name: str, ax=None, max_channels: int = 12):
    """Traces of the first channels of one stream against time."""
    ax = axes_or_new(ax)
    s = log.streams[name]
    data = s.data if s.data.ndim == 2 else np.linalg.norm(s.data, axis=2)
    for k in range(min(max_channels, len(s.names))):
        ax.plot(log.time, data[:, k], lw=0.6, label=s.names[k])
    ax.set_xlabel("time [s]")
    ax.set_title(
        f"{name}"
        + (" (|x|)" if s.data.ndim == 3 else "")
        + (f", first {max_channels}" if len(s.names) > max_channels else "")
    )
    if len(s.names) <= max_channels:
        ax.legend(ncol=3, fontsize=6)
    return ax


def log_pages(path: Path, pdf, context) -> None:
    log = load_log(path)
    save_page(pdf, text_page(f"Log: {path.name}", summary_lines(describe_log(log))))
    names = list(log.streams)
    for start in range(0, len(names), 4):
        chunk = names[start : start + 4]
        fig, axes = page(len(chunk), 1, title=f"Log: {path.name}: streams")
        for ax, name in zip(axes[:, 0], chunk, strict=True):
            plot_stream(log, name, ax=ax)
        save_page(pdf, fig)


def _describe(path: Path) -> dict:
    return {"log": str(path), "robot": log_robot(path)}


register_section(Section("log", lambda p: p.suffix.lower() in LOG_SUFFIXES and p.is_file(), log_pages, _describe))
