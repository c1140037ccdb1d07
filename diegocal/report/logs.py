"""The report's log section: what a log holds (in words and as a table) and its stream traces.

A log ``diegocal predict`` wrote (its ``source`` names the command, model and log) is said to be a
prediction, not a recording. Pots are in V except encoders, which read their joint's angle in rad
(the robot's sensors.yaml says which channels are encoders).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from diegocal.io import load_log
from diegocal.io.describe import LogSummary, describe_log
from diegocal.io.files import log_robot
from diegocal.report.layout import Column, Sheet, table_sheets
from diegocal.report.registry import Section, register_section
from diegocal.report.style import STREAM_UNITS, axes_or_new, save_page, trace_style
from diegocal.robot.resolve import pot_kinds
from diegocal.stac.calibration import READING_UNITS

LOG_SUFFIXES = (".h5", ".hdf5", ".csv")
MAX_CHANNELS = 12  # traces per plot


def summary_lines(s: LogSummary, source: dict | None = None) -> list[str]:
    """The log in plain words: robot, length, rate, streams and occlusion; ``source`` (the log's, see
    :class:`diegocal.io.Log`): what made a derived log, a prediction."""
    streams = ", ".join(f"{st.name} ({len(st.names)} channels)" for st in s.streams) or "no stream"
    verb = "holds a prediction for" if source else "records"
    text = (
        f"This log {verb} robot {s.robot or '(not named)'} for {s.duration:.3g} s at {s.rate_hz:.4g} Hz "
        f"({s.n_samples} samples): {streams}."
    )
    markers = next((st for st in s.streams if st.name == "markers"), None)
    if markers is not None and len(markers.names):
        occ = 100 * np.asarray(markers.nan_fraction)
        worst = int(np.argmax(occ))
        if not occ.any():
            text += " No marker sample is missing (NaN)." if source else " No marker is ever occluded (no NaN sample)."
        else:
            text += (
                f" Markers are occluded {occ.mean():.0f} % of the time on average (NaN samples), "
                f"{markers.names[worst]} the most ({occ[worst]:.0f} %)."
            )
    if source:
        text += " " + prediction_words(source)
    else:
        text += (
            " It is simulated: /truth holds the true parameters, which no fit reads."
            if s.has_truth
            else " It has no ground truth (/truth): a recorded log."
        )
    return [text]


def prediction_words(source: dict) -> str:
    """What made a prediction log, from its ``source`` record (command, model, log)."""
    model, log = (Path(str(source[k])).name if source.get(k) else None for k in ("model", "log"))
    made = "It is a prediction, not a recording: diegocal predict wrote it"
    made += f" with the model {model}" if model else ""
    made += f" for the log {log}" if log else ""
    command = f" (command: {source['command']})" if source.get("command") else ""
    return f"{made}{command}; its streams are the model's, to compare with that log's measurements."


def pot_units(log) -> dict:
    """{pot channel: unit} of the log's pots that do not read V (encoders: rad), from its robot's
    sensors.yaml; {} when the robot or its sensors.yaml is not found."""
    if not log.has("pots") or not log.robot:
        return {}
    kinds = pot_kinds(None, log.robot)
    units = {n: READING_UNITS.get(kinds.get(n, ""), "V") for n in log.streams["pots"].names}
    return {n: u for n, u in units.items() if u != "V"}


def _unit(name: str, others: dict) -> str:
    """A stream's unit, naming the pots that read another one (``others``: :func:`pot_units`)."""
    unit = STREAM_UNITS.get(name, "?")
    if name != "pots" or not others:
        return unit
    parts = [unit]
    for u in sorted(set(others.values())):
        names = [n for n, v in others.items() if v == u]
        parts.append(f"{u} ({', '.join(names[:3])}{', …' if len(names) > 3 else ''})")
    return "; ".join(parts)


def stream_table(s: LogSummary, others: dict | None = None) -> tuple[list[Column], list[list]]:
    """One row per stream: channels, unit, range and missing samples (``others``: :func:`pot_units`)."""
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
        rows.append([st.name, len(st.names), _unit(st.name, others or {}), low, high, f"{nan:.1f}", names])
    return columns, rows


def plot_stream(log, name: str, ax=None, max_channels: int = MAX_CHANNELS, others: dict | None = None):
    """Traces of the first channels of one stream against time, with the stream's unit (``others``: the
    pots in another unit, :func:`pot_units`); each trace its own colour and line style
    (:func:`~diegocal.report.style.trace_style`)."""
    ax = axes_or_new(ax)
    s = log.streams[name]
    data = s.data if s.data.ndim == 2 else np.linalg.norm(s.data, axis=2)
    shown = min(max_channels, len(s.names))
    for k in range(shown):
        ax.plot(log.time, data[:, k], lw=0.6, label=s.names[k], **trace_style(k))
    unit = _unit(name, others or {}) if name in STREAM_UNITS else "sensor unit"
    ax.set_xlabel(f"time [s]  ({log.n_samples} samples)")
    ax.set_ylabel(f"distance from mocap origin [{unit}]" if s.data.ndim == 3 else f"{name} [{unit}]")
    of = f"first {shown} of {len(s.names)} channels" if shown < len(s.names) else f"{shown} channels"
    vector = " (|x|: distance of each marker from the mocap origin)" if s.data.ndim == 3 else ""
    ax.set_title(f"{name}: {of}{vector}")
    ax.legend(ncol=1, fontsize=6, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    return ax


def log_pages(path: Path, pdf, context) -> None:
    log = load_log(path)
    summary, others = describe_log(log), pot_units(log)
    columns, rows = stream_table(summary, others)
    sheets = table_sheets(f"Log: {path.name}", columns, rows, intro=summary_lines(summary, log.source))
    for name in log.streams:  # below the table while there is room, then on pages of their own
        if sheets[-1].room() < 0.25:
            sheets.append(Sheet(f"Log: {path.name}: streams"))
        plot_stream(log, name, ax=sheets[-1].axes(0.25, left=0.1, right=0.8), others=others)
    for sheet in sheets:
        save_page(pdf, sheet.fig)


def _describe(path: Path) -> dict:
    return {"log": str(path), "robot": log_robot(path)}


def _abstract(path: Path, context=None) -> list[str]:
    log = load_log(path)
    return summary_lines(describe_log(log), log.source)


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
