"""The report's log section: what a log holds (in words and as a table) and its stream traces."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from diegocal.io import load_log
from diegocal.io.describe import LogSummary, describe_log
from diegocal.io.files import log_robot
from diegocal.report.layout import Column, Sheet, table_sheets
from diegocal.report.registry import Section, register_section
from diegocal.report.style import STREAM_UNITS, axes_or_new, save_page, trace_style

LOG_SUFFIXES = (".h5", ".hdf5", ".csv")
MAX_CHANNELS = 12  # traces per plot


def summary_lines(s: LogSummary) -> list[str]:
    """The log in plain words: robot, length, rate, streams and occlusion."""
    streams = ", ".join(f"{st.name} ({len(st.names)} channels)" for st in s.streams) or "no stream"
    text = (
        f"This log records robot {s.robot or '(not named)'} for {s.duration:.3g} s at {s.rate_hz:.4g} Hz "
        f"({s.n_samples} samples): {streams}."
    )
    markers = next((st for st in s.streams if st.name == "markers"), None)
    if markers is not None and len(markers.names):
        occ = 100 * np.asarray(markers.nan_fraction)
        worst = int(np.argmax(occ))
        text += (
            f" Markers are occluded {occ.mean():.0f} % of the time on average (NaN samples), "
            f"{markers.names[worst]} the most ({occ[worst]:.0f} %)."
        )
    text += (
        " It is simulated: /truth holds the true parameters, which no fit reads."
        if s.has_truth
        else " It has no ground truth (/truth): a recorded log."
    )
    return [text]


def stream_table(s: LogSummary) -> tuple[list[Column], list[list]]:
    """One row per stream: channels, unit, range and missing samples."""
    columns = [
        Column("stream", align="left"),
        Column("channels"),
        Column("unit", align="left"),
        Column("lowest"),
        Column("highest"),
        Column("NaN samples", "%"),
        Column("first channels", align="left"),
    ]
    rows = []
    for st in s.streams:
        names = ", ".join(st.names[:4]) + (f", … ({len(st.names) - 4} more)" if len(st.names) > 4 else "")
        low = float(np.nanmin(st.low)) if np.isfinite(st.low).any() else None
        high = float(np.nanmax(st.high)) if np.isfinite(st.high).any() else None
        nan = 100 * float(np.mean(st.nan_fraction)) if len(st.names) else 0.0
        rows.append([st.name, len(st.names), STREAM_UNITS.get(st.name, "?"), low, high, f"{nan:.1f}", names])
    return columns, rows


def plot_stream(log, name: str, ax=None, max_channels: int = MAX_CHANNELS):
    """Traces of the first channels of one stream against time, with the stream's unit; each trace its
    own colour and line style (:func:`~diegocal.report.style.trace_style`)."""
    ax = axes_or_new(ax)
    s = log.streams[name]
    data = s.data if s.data.ndim == 2 else np.linalg.norm(s.data, axis=2)
    shown = min(max_channels, len(s.names))
    for k in range(shown):
        ax.plot(log.time, data[:, k], lw=0.6, label=s.names[k], **trace_style(k))
    unit = STREAM_UNITS.get(name, "sensor unit")
    ax.set_xlabel(f"time [s]  ({log.n_samples} samples)")
    ax.set_ylabel(f"distance from mocap origin [{unit}]" if s.data.ndim == 3 else f"{name} [{unit}]")
    of = f"first {shown} of {len(s.names)} channels" if shown < len(s.names) else f"{shown} channels"
    vector = " (|x|: distance of each marker from the mocap origin)" if s.data.ndim == 3 else ""
    ax.set_title(f"{name}: {of}{vector}")
    ax.legend(ncol=1, fontsize=6, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    return ax


def log_pages(path: Path, pdf, context) -> None:
    log = load_log(path)
    summary = describe_log(log)
    columns, rows = stream_table(summary)
    sheets = table_sheets(f"Log: {path.name}", columns, rows, intro=summary_lines(summary))
    for name in log.streams:  # below the table while there is room, then on pages of their own
        if sheets[-1].room() < 0.25:
            sheets.append(Sheet(f"Log: {path.name}: streams"))
        plot_stream(log, name, ax=sheets[-1].axes(0.25, left=0.1, right=0.8))
    for sheet in sheets:
        save_page(pdf, sheet.fig)


def _describe(path: Path) -> dict:
    return {"log": str(path), "robot": log_robot(path)}


def _abstract(path: Path, context=None) -> list[str]:
    return summary_lines(describe_log(load_log(path)))


def _headline(path: Path, context=None) -> str:
    s = describe_log(load_log(path))
    streams = ", ".join(st.name for st in s.streams)
    return f"robot {s.robot or '-'}, {s.duration:.3g} s at {s.rate_hz:.4g} Hz; streams {streams}"


register_section(
    Section(
        "log",
        lambda p: p.suffix.lower() in LOG_SUFFIXES and p.is_file(),
        log_pages,
        _describe,
        heading="Log",
        abstract=_abstract,
        headline=_headline,
    )
)
