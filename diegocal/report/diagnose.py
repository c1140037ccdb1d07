"""Report section for diagnosis.yaml (registers itself on import).

Pages: a summary in plain words (what the model gets wrong, the named causes, what fixing them
gained on held-out data) with the held-out RMSE of the baseline and the extended model; for each
finding its evidence (the residual against the variable that localises it, before and after the
term, with ±2 block standard errors) and the runners-up with their validation scores; structure
that no term explains, shown where it is.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np

from diegocal.report.registry import Section, is_bundle, register_section
from diegocal.report.style import COLORS, PAGE_SIZE, axes_or_new, page, save_page

#: What each cause means, in words (DESIGN.md's vocabulary and its extensions).
PHRASES = {
    "position_friction": "friction confined to part of the joint's range",
    "coulomb_friction": "Coulomb friction missing from the model (a torque that follows the sign of the velocity)",
    "viscous_friction": "viscous friction missing from the model (a torque proportional to the velocity)",
    "payload": "an unmodelled mass on this link",
    "spring": "a spring (a torque proportional to the joint angle)",
    "torque_offset": "a constant offset of the torque sensor",
    "armature": "rotor inertia (a torque proportional to the acceleration)",
    "coupled_friction": "friction of a motor that drives both joints",
    "torque_lag": "the measured torque lags the motion",
    "link_offset": "the joint's origin differs from the URDF",
    "sensor_nonlinearity": "the pot's transfer curve is not linear",
    "backlash": "the pot lags by a dead band that depends on the direction of motion",
    "time_offset": "the mocap and pot clocks are shifted",
    "marker_slip": "the marker moved on its link during the session",
    "marker_outliers": "some marker readings are outliers (ghosts, reflections)",
    "swapped_labels": "two markers' labels are swapped in some frames",
    "valve_delay": "the pressure answers the valve command late",
    "chamber_leak": "air escapes the chamber when it is sealed",
    "supply_droop": "the supply pressure sags under high flow",
    "pressure_offset": "the pressure sensor's zero drifted",
    "unexplained": "structured residual that no term of the vocabulary explains",
}


def recognise(path: Path) -> bool:
    return is_bundle(path, "diagnosis")


def describe(path: Path) -> dict:
    from diegocal.io import load_yaml

    d = load_yaml(path)
    robot = d.get("robot") or {}
    return {
        "domain": d.get("domain"),
        "log": d.get("log"),
        "robot": robot.get("name") if isinstance(robot, dict) else robot,
        "findings": len(d.get("findings") or []),
    }


def sentence(f: dict) -> str:
    """One finding in plain words: where, what, and what fixing it gained on held-out data."""
    what = PHRASES.get(f["cause"], f["cause"].replace("_", " "))
    r = f.get("region")
    if r:
        what += f" ({r['variable']} from {r['low']:.3g} to {r['high']:.3g})"
    g = f.get("gain") or {}
    unit = f.get("unit") or ""
    if g.get("reduction") is not None:
        gain = (
            f"; adding it to the model explains {g['reduction']:.0%} of the held-out error "
            f"(RMSE {g['rmse_before']:.3g} → {g['rmse_after']:.3g} {unit})"
        )
    else:
        vg = (f.get("evidence") or {}).get("validation_gain")
        gain = f"; it accounts for {vg:.0%} of the validation error" if vg is not None else ""
    params = _parameters_text(f)
    return f"{f['channel']}: {what}{gain}.{params}"


def _parameters_text(f: dict) -> str:
    p = f.get("parameters") or {}
    if not p or f["cause"] == "unexplained":
        return ""
    hidden = 0
    if len(p) > 4:  # a payload's ten inertial parameters: the identified ones (with a standard error)
        hidden = sum(v.get("std") is None for v in p.values())
        p = dict(list({k: v for k, v in p.items() if v.get("std") is not None}.items())[:4])
    parts = []
    for name, v in p.items():
        if v.get("value") is None:
            continue
        s = f"{name} = {v['value']:.3g}"
        if v.get("std") is not None:
            s += f" ± {v['std']:.2g}"
        parts.append(s + (f" {v['unit']}" if v.get("unit") else ""))
    if hidden:
        parts.append(f"{hidden} parameter(s) not identified by these data")
    return (" Fitted: " + ", ".join(parts) + ".") if parts else ""


def _pooled(rmse: dict) -> float:
    v = np.array([x for x in (rmse or {}).values() if x is not None], float)
    return float(np.sqrt(np.mean(v**2))) if v.size else float("nan")


def summary_lines(d: dict) -> list[str]:
    """The summary page's paragraphs."""
    base, ext = d["baseline"], d["extended"]
    unit = base.get("unit", "")
    findings = d.get("findings") or []
    blocks = d.get("blocks") or {}
    held = sum(b[1] - b[0] for b in blocks.get("heldout", []))
    train = sum(b[1] - b[0] for b in blocks.get("train", []))
    val = sum(b[1] - b[0] for b in blocks.get("validation", []))
    out = [
        f"Domain: {d['domain']}. Baseline model: {base['model']}, fitted on {train:.1f} s of training blocks; "
        f"candidate terms were chosen on {val:.1f} s of validation blocks and every gain below is measured on "
        f"{held:.1f} s of held-out blocks that were used for nothing else (contiguous blocks in time, interleaved).",
    ]
    if not findings:
        out.append(
            "Nothing significant: no term of the vocabulary and no binned structure improves the validation "
            f"error beyond chance (family-wise false-alarm rate {d['options']['alpha']:g}) and by at least "
            f"{d['options']['min_gain']:.0%}. The baseline is as good as this log can tell."
        )
    else:
        out.append(
            f"{len(findings)} finding(s), most important first. Held-out RMSE over all channels: baseline "
            f"{_pooled(base['heldout_rmse']):.4g} {unit}, extended model {_pooled(ext['heldout_rmse']):.4g} {unit} "
            f"({ext['model']})."
        )
        out += [f"{k + 1}. " + sentence(f) for k, f in enumerate(findings)]
    return out


def paragraph_page(title: str, paragraphs, width: int = 100):
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=PAGE_SIZE)
    fig.text(0.07, 0.95, title, fontsize=14, fontweight="bold", va="top")
    y = 0.91
    for p in paragraphs:
        lines = textwrap.wrap(p, width=width) or [""]
        fig.text(0.07, y, "\n".join(lines), fontsize=9, va="top")
        y -= 0.018 * len(lines) + 0.015
        if y < 0.08:
            break
    return fig


# ----------------------------------------------------------------------------- plots
def plot_evidence(f: dict, ax=None):
    """The residual's mean per bin of the localising variable, before (and after) the finding,
    with ±2 block standard errors; the region shaded."""
    ax = axes_or_new(ax)
    ev = f.get("evidence") or {}
    curves = ev.get("curves") or {}
    unit = curves.get("unit") or f.get("unit") or ""
    for key, color, label in (("before", COLORS["baseline"], "before"), ("after", COLORS["model"], "after")):
        c = curves.get(key)
        if not c:
            continue
        x = np.array([np.nan if v is None else v for v in c["centre"]], float)
        m = np.array([np.nan if v is None else v for v in c["mean"]], float)
        s = np.array([np.nan if v is None else v for v in c["se"]], float)
        ax.fill_between(x, m - 2 * s, m + 2 * s, color=color, alpha=0.2, lw=0)
        ax.plot(x, m, "o-", color=color, ms=3, lw=1, label=f"{label} (±2 block SE)")
    r = f.get("region")
    if r and r.get("variable") == ev.get("variable"):
        ax.axvspan(r["low"], r["high"], color=COLORS["truth"], alpha=0.12, label="region found")
    ax.axhline(0.0, color="0.5", lw=0.6)
    ax.set_xlabel(str(ev.get("variable", "")))
    magnitude = " (magnitude)" if curves.get("before") and _is_norm(f) else ""
    ax.set_ylabel(f"mean residual{magnitude} [{unit}]")
    ax.set_title(f"{f['cause']} on {f['channel']}: residual on validation + held-out blocks")
    ax.legend(fontsize=6)
    return ax


def _is_norm(f: dict) -> bool:
    return f.get("unit") == "m"


def runners_table(f: dict, ax=None):
    """The runners-up of a finding's round with their validation scores, as a table."""
    ax = axes_or_new(ax)
    ax.axis("off")
    rows = []
    for r in f.get("runners_up") or []:
        region = r.get("region")
        where = r["channel"] + (f" [{region['low']:.3g}..{region['high']:.3g}]" if region else "")
        rows.append(
            [
                r["cause"],
                where,
                f"{r['validation_gain']:.1%}",
                f"{r['t']:.1f}",
                f"{r['threshold_t']:.1f}",
                "yes" if r["significant"] else "no",
            ]
        )
    if not rows:
        ax.text(0.0, 0.5, "no other candidate was tested in this round", fontsize=8)
        return ax
    table = ax.table(
        cellText=rows,
        colLabels=["cause", "channel [region]", "validation gain", "t", "threshold t", "significant"],
        loc="upper center",
        cellLoc="left",
    )
    table.auto_set_font_size(False)
    table.set_fontsize(7)
    table.scale(1.0, 1.3)
    ax.set_title("runners-up (fitted on training blocks, scored on validation blocks)", fontsize=8)
    return ax


def pages(path: Path, pdf, context) -> None:
    from diegocal.io import load_yaml

    d = load_yaml(path)
    save_page(pdf, paragraph_page(f"Diagnosis: {d['domain']}", summary_lines(d)))
    findings = d.get("findings") or []
    for k in range(0, len(findings), 2):
        chunk = findings[k : k + 2]
        fig, axes = page(
            2 * len(chunk),
            1,
            title=f"Diagnosis: evidence ({d['domain']})",
            gridspec_kw={"height_ratios": [3, 2] * len(chunk)},
        )
        for i, f in enumerate(chunk):
            plot_evidence(f, axes[2 * i, 0])
            axes[2 * i, 0].set_title(textwrap.shorten(f"{k + i + 1}. {sentence(f)}", 150), fontsize=7)
            runners_table(f, axes[2 * i + 1, 0])
        save_page(pdf, fig)


register_section(Section("diagnosis", recognise, pages, describe))
