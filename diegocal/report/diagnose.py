"""Report section for diagnosis.yaml (registers itself on import).

Pages: a summary in plain words (what the model gets wrong, the named causes, what fixing them
gained on held-out data) with the held-out RMSE of the baseline and the extended model; for each
finding its evidence (the residual against the variable that localises it, before and after the
term, with ±2 block standard errors) and the runners-up with their validation scores; structure
that no term explains, shown where it is.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from diegocal.causes import phrase
from diegocal.diagnose.limits import limits_words
from diegocal.diagnose.output import shifting_channels, weak_structure
from diegocal.diagnose.selection import SIMPLER_SHARE, TWIN, TWIN_SE
from diegocal.io import load_yaml
from diegocal.report.diagnose_notes import CHANNEL_NOTE, NO_CURVE, NO_RUNNERS, NOT_STORED, RUNNERS_NOTE
from diegocal.report.finding_notes import notes, parameters_text
from diegocal.report.layout import Column, Sheet, table_sheets
from diegocal.report.registry import Section, is_bundle, register_section
from diegocal.report.style import COLORS, axes_or_new, save_page


def meaning(cause: str) -> str:
    """A cause in plain words: the registry's phrase (:func:`diegocal.causes.phrase`), else its name."""
    return phrase(cause) or cause.replace("_", " ")


def recognise(path: Path) -> bool:
    return is_bundle(path, "diagnosis")


def describe(path: Path) -> dict:
    d = load_yaml(path)
    robot = d.get("robot") or {}
    name = robot.get("name") if isinstance(robot, dict) else robot
    return {"domain": d.get("domain"), "log": d.get("log"), "robot": name, "findings": len(d.get("findings") or [])}


def sentence(f: dict) -> str:
    """One finding in plain words: where, what, and what fixing it gained on held-out data."""
    what = meaning(f["cause"])
    r = f.get("region")
    if r:
        end = "on" if r["high"] == float("inf") else f"to {r['high']:.3g}"
        what += f" ({r['variable']} from {r['low']:.3g} {end})"
    g = f.get("gain") or {}
    unit = f.get("unit") or ""
    if g.get("reduction") is not None:
        absorbs = f["cause"] == "unexplained"
        how = "the extended model's non-parametric part" if absorbs else "adding it to the model"
        red = g["reduction"]
        moves = f"lowers the held-out RMSE by {red:.0%}" if red >= 0 else f"raises the held-out RMSE by {-red:.0%}"
        gain = f"; {how} {moves} ({g['rmse_before']:.3g} → {g['rmse_after']:.3g} {unit})"
        span = (f.get("evidence") or {}).get("heldout_leaves_out")
        if span:  # a region's edge in a span without training data: where it is, the data do not say
            gain += f", outside {span[0]:.3g}-{span[1]:.3g} s, where no training data place its edge"
    else:
        ev = f.get("evidence") or {}
        vg, which = ev.get("validation_gain"), "open-loop validation" if ev.get("rival") else "validation"
        gain = f"; it accounts for {vg:.0%} of the {which} error" if vg is not None else ""
    params = parameters_text(f)
    others = [c for c in (f.get("evidence") or {}).get("gain_channels") or () if c != f.get("channel")]
    if others and g.get("reduction") is not None:  # a motor shared by two joints: its gain on its own one only
        params += f" It acts on {', '.join(others)} too (their held-out RMSE in the table of channels)."
    twins = (f.get("evidence") or {}).get("indistinguishable_from")
    if twins:  # the same cause elsewhere fits the data the same: which one, the log cannot say
        params += (
            f" The data cannot tell it from the same cause on {', '.join(twins)} (each removes as much of "
            f"the validation error, to within {TWIN * 100:g} % or {TWIN_SE:g} paired standard errors)."
        )
    rivals = (f.get("evidence") or {}).get("indistinguishable_causes")
    if rivals:  # another cause fits the data the same: which one, the log cannot say
        params += (
            f" The data cannot tell it from {', '.join(rivals)} (each removes as much of the validation error, "
            f"to within {TWIN * 100:g} %, or {SIMPLER_SHARE * 100:g} % and {TWIN_SE:g} paired standard errors): "
            "either may be the cause."
        )
    restated = (f.get("evidence") or {}).get("restated")
    if restated:  # the fitted values named another cause than the candidate's (a payload no body can be)
        params += f" {restated[0].upper()}{restated[1:]}."
    return f"{f['channel']}: {what}{gain}.{params}{notes(f)}"


def pooled_rmse(d: dict) -> dict:
    """{unit: (baseline, extended)} held-out RMSE pooled over the channels of each unit (never across
    units: a kinematic diagnosis mixes pots in V and markers in m)."""
    base, ext = d.get("baseline") or {}, d.get("extended") or {}
    units = base.get("units") or {}
    out = {}
    for unit in dict.fromkeys(units.values() or [base.get("unit", "")]):
        pair = []
        for block in (base, ext):
            x = [
                v for c, v in (block.get("heldout_rmse") or {}).items() if v is not None and units.get(c, unit) == unit
            ]
            pair.append(float(np.sqrt(np.mean(np.square(x)))) if x else float("nan"))
        out[unit] = tuple(pair)
    return out


def limits_lines(d: dict) -> list[str]:
    """What the data could not have shown, in words (:mod:`diegocal.diagnose.limits`)."""
    words = limits_words(d.get("detection_limits") or [])
    return [f"Detection limits (an effect found 80 % of the time; `detection_limits`): {words}."] if words else []


def summary_lines(d: dict) -> list[str]:
    """The section's opening paragraphs: what was fitted on what, the findings, what they gained."""
    base, ext = d["baseline"], d["extended"]
    findings = d.get("findings") or []
    blocks = d.get("blocks") or {}
    held = sum(b[1] - b[0] for b in blocks.get("heldout", []))
    train = sum(b[1] - b[0] for b in blocks.get("train", []))
    val = sum(b[1] - b[0] for b in blocks.get("validation", []))
    log = Path(str(d.get("log") or "the log")).name
    out = [
        f"Domain {d['domain']}, log {log}. The baseline model ({base['model']}) was fitted on {train:.1f} s of "
        f"training blocks; candidate terms were chosen on {val:.1f} s of validation blocks, and every gain below is "
        f"measured on {held:.1f} s of held-out blocks used for nothing else (contiguous blocks in time, interleaved).",
    ]
    pooled = "; ".join(f"{b:.4g} → {e:.4g} {u}" for u, (b, e) in pooled_rmse(d).items())
    declined, shifting = d.get("declined") or [], shifting_channels(d)
    weak = [] if findings or declined or shifting else weak_structure(d)
    if weak:  # significant binned structure, each under the gain a finding needs: not "nothing"
        out.append(
            f"No cause named (held-out RMSE over all channels {pooled}). Binned structure in the baseline's "
            "residual is significant on " + ", ".join(f"{c} against {v} ({g:.0%} of the validation error)"
                                                     for c, v, g in weak)
            + ", each under the share of the validation error a finding needs (`residual_tests`)."
        )
    elif not findings and not declined and not shifting:
        out.append(
            "Nothing significant: no term of the vocabulary and no binned structure against the channels' "
            f"states improves the validation error beyond chance (family-wise false-alarm rate "
            f"{d['options']['alpha']:g}) and by at least {d['options']['min_gain']:.0%}, and no channel's "
            f"residual shifts in time. The baseline is as good as these tests can tell "
            f"(held-out RMSE over all channels {pooled})."
        )
    elif not findings:
        out.append(f"No cause named (held-out RMSE over all channels {pooled}); what the tests did see is below.")
    else:
        out.append(
            f"{len(findings)} finding(s), most important first. Held-out RMSE over all channels, baseline → "
            f"extended model ({ext['model']}): {pooled}."
        )
        out += [f"{k + 1}. " + sentence(f) for k, f in enumerate(findings)]
    out += [f"Declined: {x['cause']} on {x['channel']}: {x['why']}." for x in declined]
    if not findings:  # with findings, after them (:func:`pages`)
        out += limits_lines(d)
    out += [
        f"The residual of {channel} shifts in time (CUSUM test p {p:.1g}{f', at {t:.3g} s' if t is not None else ''}): "
        "structure no term names, a drift or an effect that part of the session's motion excites."
        for channel, p, t in shifting
    ]
    for f in d.get("minor_faults") or []:
        red = (f.get("gain") or {}).get("reduction")
        out.append(
            f"Minor data fault, no finding: {meaning(f['cause'])} on {f['channel']} "
            f"({f.get('readings')} flagged); writing them off changes the held-out error by "
            f"{f'{-red:+.1%}' if red is not None else 'nothing measurable'}, under what a finding must remove"
            + ("; written off all the same." if f.get("written_off") else "; left in the data.")
        )
    late = [] if d.get("converged", True) else d.get("unconverged") or ["a fit stopped before it converged"]
    if late:
        out.append(f"Not converged: {'; '.join(late)}; the figures above are not at that fit's tolerance.")
    return out


# ----------------------------------------------------------------------------- plots
#: The evidence plot's legend labels, and what each says in its caption (:func:`evidence_caption`).
BEFORE, AFTER = "before (±2 block SE)", "after (±2 block SE)"
REGION, ZERO = "region found", "zero: nothing left to explain"
DRAWN_WORDS = {
    BEFORE: "orange, the residual of the baseline model",
    AFTER: "blue, that of the extended model",
    REGION: "green, the region the finding is confined to",
    ZERO: "grey line, zero",
}


def plot_evidence(f: dict, ax=None):
    """The residual's mean per bin of the localising variable, before (and after) the finding,
    with ±2 block standard errors; the region shaded when it is a range of that variable."""
    ax = axes_or_new(ax)
    ev = f.get("evidence") or {}
    curves = ev.get("curves") or {}
    unit = curves.get("unit") or f.get("unit") or ""
    for key, color, label in (("before", COLORS["baseline"], BEFORE), ("after", COLORS["model"], AFTER)):
        c = curves.get(key)
        if not c:
            continue
        x = np.array([np.nan if v is None else v for v in c["centre"]], float)
        m = np.array([np.nan if v is None else v for v in c["mean"]], float)
        s = np.array([np.nan if v is None else v for v in c["se"]], float)
        ax.fill_between(x, m - 2 * s, m + 2 * s, color=color, alpha=0.2, lw=0)
        ax.plot(x, m, "o-", color=color, ms=3, lw=1, label=label)
    r = f.get("region")
    if r and r.get("variable") == ev.get("variable"):
        ax.axvspan(r["low"], min(r["high"], ax.get_xlim()[1]), color=COLORS["truth"], alpha=0.12, label=REGION)
    ax.axhline(0.0, color="0.5", lw=0.6, label=ZERO)
    counts = (curves.get("before") or {}).get("count") or []
    variable = str(ev.get("variable", ""))
    ax.set_xlabel(
        f"{variable} [{variable_unit(variable, f.get('domain', ''), _slides(f))}]  "
        f"(bin medians; {sum(counts)} samples in {len(counts)} bins)"
    )
    magnitude = " (magnitude)" if curves.get("before") and _is_norm(f) else ""
    signed = f" × sign({curves['signed_by']})" if curves.get("signed_by") else ""
    label = f"mean residual{magnitude}{signed} [{unit}]"
    ax.set_ylabel(label.replace(" × ", "\n× ") if len(label) > 40 else label)  # a long one on two lines
    ax.set_title(f"{f['cause']} on {f['channel']}: residual on the validation and held-out blocks")
    ax.legend(fontsize=6)
    return ax


def _shown_reach(f: dict) -> tuple[float, float] | None:
    """The extent of the evidence variable on the samples shown (``curves.reach``; files written
    before it: the lowest and highest bin medians that hold samples; None: none)."""
    curves = (f.get("evidence") or {}).get("curves") or {}
    if curves.get("reach"):
        return tuple(curves["reach"])
    c = curves.get("before") or {}
    centres = [x for x, n in zip(c.get("centre") or [], c.get("count") or [], strict=False) if n and x is not None]
    return (min(centres), max(centres)) if centres else None


def _is_norm(f: dict) -> bool:
    return f.get("unit") == "m"


def _slides(f: dict) -> set:
    """The finding's joint when it is prismatic (its effort in N): its coordinate is in m."""
    return {f.get("channel")} if f.get("unit") == "N" else set()


def variable_unit(variable: str, domain: str, slides=frozenset()) -> str:
    """The unit of an evidence variable ("q.joint3" rad, "p.fds" V, "du.r_elbow.flex" V per step);
    ``slides``: prismatic joints, whose q is in m."""
    head, _, joint = variable.partition(".")
    if head == "p":
        return "kPa" if domain == "pneumatics" else "V"
    if joint in slides and head in ("q", "qd", "qdd"):
        return {"q": "m", "qd": "m/s", "qdd": "m/s²"}[head]
    units = {"time": "s", "q": "rad", "qd": "rad/s", "qdd": "rad/s²", "u": "V", "du": "V per step", "v": "V"}
    return units.get(head, "V/s" if head == "vd" else "?")


def runners_table(f: dict) -> tuple[list[Column], list[list]]:
    """The runners-up of a finding's round: each candidate term with its validation score."""
    columns = [
        Column("candidate cause", align="left"),
        Column("channel [region]", align="left"),
        Column("validation gain", "%"),
        Column("t"),
        Column("threshold t"),
        Column("significant", align="left"),
    ]
    rows = []
    later = {(x["cause"], x["channel"]) for x in f.get("declined_later") or ()}  # declined in a later round
    for r in f.get("runners_up") or []:
        verdict = _significant(r)
        if verdict == "yes; next round" and (r["cause"], r["channel"]) in later:
            verdict = "yes; declined next round (Declined)"
        region = r.get("region")
        high = np.inf if region and region["high"] is None else (region or {}).get("high")  # null: open (older files)
        where = r["channel"] + (f" [{region['low']:.3g}..{high:.3g}]" if region else "")
        score = [f"{100 * r['validation_gain']:.1f}", f"{r['t']:.1f}", f"{r['threshold_t']:.1f}"]
        rows.append([r["cause"], where, *score, verdict])
    return columns, rows


def _significant(r: dict) -> str:
    """A runner-up's significance and, when it was significant, why it was not added (short)."""
    if not r["significant"]:
        return "no"
    why = r.get("why_not") or ""
    if why.startswith("tested again"):
        return "yes; next round"
    if why.startswith("stood in"):
        return "yes; stood in"
    if why.startswith("refitted"):
        return "yes; less refitted"
    if why.startswith("the data cannot tell"):
        return "yes; the same fit"
    return "yes; less on its channel" if why else "yes"


def channel_table(d: dict) -> tuple[list[Column], list[list]]:
    """Held-out RMSE of every channel, baseline and extended model."""
    base, ext = d["baseline"], d["extended"]
    units = base.get("units") or {}
    columns = [
        Column("channel", align="left"),
        Column("unit", align="left"),
        Column("held-out RMSE, baseline"),
        Column("held-out RMSE, extended"),
        Column("change", "%"),
    ]
    rows = []
    for c, b in (base.get("heldout_rmse") or {}).items():
        e = (ext.get("heldout_rmse") or {}).get(c)
        change = "–" if b is None or e is None or b < EXACT else _percent(100 * (e - b) / b)
        rows.append([c, units.get(c, base.get("unit", "")), _g(b), _g(e), change])
    return columns, rows


#: Below this an RMSE is zero to rounding: the model reproduces the channel exactly (a pot that alone
#: determines its joint's angle), and a relative change is not defined.
EXACT = 1e-12


def _percent(x: float) -> str:
    return "0" if abs(x) < 0.5 else f"{x:+.0f}"


def _g(v) -> str:
    return "–" if v is None else "0 (exact)" if v < EXACT else f"{v:.4g}"


def evidence_caption(ax, f: dict) -> str:
    """What finding ``f``'s evidence plot ``ax`` shows, said from what was drawn on it (its legend's
    labels): no colour or region is described that the plot does not hold."""
    labels = ax.get_legend_handles_labels()[1]
    drawn = [DRAWN_WORDS[label] for label in DRAWN_WORDS if label in labels]
    signed = ((f.get("evidence") or {}).get("curves") or {}).get("signed_by")
    what = (
        f"Mean residual times the sign of {signed} (friction opposes the motion)"
        if signed
        else "Mean residual"
    )
    text = (
        f"{what} on the validation and held-out blocks in bins of the variable that localises the finding "
        "(points at the bin medians): " + "; ".join(drawn) + "."
    )
    if BEFORE in labels or AFTER in labels:
        text += (
            " Bands: ±2 standard errors over contiguous sub-blocks (correlated samples are not counted as "
            "independent). A curve that follows zero within its band has nothing left to explain."
        )
    r = f.get("region")
    reach = _shown_reach(f)
    high = np.inf if r is None or r.get("high") is None else r["high"]
    if r and REGION in labels and reach and (r["low"] > reach[1] or high < reach[0]):
        text += (
            f" The validation and held-out blocks reach {f['evidence']['variable']} from {reach[0]:.3g} to "
            f"{reach[1]:.3g} only: the region found lies outside them (the training blocks placed it), and what is "
            "shown is what the extended model changes elsewhere (the baseline had been fitted to absorb the "
            "structure the region holds)."
        )
    if r and REGION not in labels:
        text += (
            f" The finding's region ({r.get('variable')} from {r['low']:.3g} to {r['high']:.3g}) is not a range of "
            "this variable, so it is not drawn."
        )
    return text


def abstract(path: Path, context=None) -> list[str]:
    return summary_lines(load_yaml(path))


def headline(path: Path, context=None) -> str:
    """One line: the findings (what was found wrong) and what fixing them gained on held-out data."""
    d = load_yaml(path)
    findings = d.get("findings") or []
    log = Path(str(d.get("log") or "")).name
    if not findings:
        seen = len(d.get("declined") or []) + len(shifting_channels(d))
        weak = len(weak_structure(d))
        return f"{d['domain']} ({log}): " + (f"no cause named ({seen} sign(s) of structure)" if seen else
                                             f"no cause named ({weak} significant binned residual(s), "
                                             "each under the gain a finding needs)" if weak else
                                             "nothing significant")
    parts = []
    for f in findings:
        g = f.get("gain") or {}
        gain = (
            f", held-out RMSE {g['rmse_before']:.3g} → {g['rmse_after']:.3g} {f.get('unit', '')}"
            if g.get("rmse_after") is not None
            else ""
        )
        parts.append(f"{f['cause']} on {f['channel']}{gain}")
    return f"{d['domain']} ({log}): " + "; ".join(parts)


#: Height of a finding's evidence plot (fraction of the page), and the least it may shrink to so
#: that the finding fits below what is already on the page.
PLOT_HEIGHT, PLOT_MIN = 0.26, 0.17


@dataclass(frozen=True)
class Drawn:
    """A finding as drawn: the sheets it ends on (more than one only for a runners-up table longer
    than a page), its number, its figure's caption and whether it has a runners-up table."""

    sheets: list
    number: int
    caption: str
    table: bool


def draw_finding(sheet: Sheet, f: dict, k: int, plot_height: float, repeat: bool, after: Drawn | None) -> Drawn:
    """Finding ``k`` (from 0) on ``sheet``: heading, its sentence (unless ``repeat`` is False: the
    summary just above says it), the evidence plot and its caption, the runners-up (or why there are
    none); ``after``: a finding drawn above on the same sheet, whose caption and table notes this one
    refers to where they would say the same."""
    sheet.heading(f"Finding {k + 1}: {f['cause']} on {f['channel']}")
    if repeat:
        sheet.paragraph(sentence(f))
    if (f.get("evidence") or {}).get("curves"):
        caption = evidence_caption(plot_evidence(f, sheet.axes(plot_height)), f)
    else:  # nothing to plot: no residual against one variable chose it
        caption = NO_CURVE
    same = after is not None and after.caption == caption
    sheet.caption(f"Lines, bands and shading as in Finding {after.number}'s figure above." if same else caption)
    columns, rows = runners_table(f)
    if rows and f.get("runners_as"):  # the same round's table, drawn for an earlier finding
        sheet.paragraph(f"Runners-up of this round: as in Finding {f['runners_as']}'s table.", size=8)
        return Drawn([sheet], k + 1, caption, False)
    if "runners_up" not in f:
        sheet.paragraph(NOT_STORED, size=8)
    elif not rows:
        sheet.paragraph(NO_RUNNERS.get(f.get("kind"), NO_RUNNERS["term"]), size=8)
    if not rows:
        return Drawn([sheet], k + 1, caption, False)
    note = f"Columns as in Finding {after.number}'s table above." if after is not None and after.table else RUNNERS_NOTE
    if any(str(r.get("why_not", "")).startswith("stood in") for r in f.get("runners_up") or ()):
        note += " Stood in: the term the finding's sentence names, which something else explained better."
    sheets = table_sheets("Runners-up of this round", columns, rows, sheet=sheet, notes=(note,))
    return Drawn(sheets, k + 1, caption, True)


def finding_height(f: dict, k: int, plot_height: float, repeat: bool, after: Drawn | None) -> float:
    """The height a finding takes on a page (drawn on a scratch sheet and measured); above 1 when it
    does not fit on one page."""
    scratch = Sheet()
    top = scratch.y
    drawn = draw_finding(scratch, f, k, plot_height, repeat, after).sheets
    height = top - drawn[-1].y + (len(drawn) - 1)
    for s in drawn:
        plt.close(s.fig)
    return height


def place_finding(sheets: list[Sheet], f: dict, k: int, title: str, after: Drawn | None) -> Drawn:
    """Finding ``k`` below what the last sheet holds when it fits whole there (its plot shrunk down to
    PLOT_MIN if need be), else from the top of a new sheet: several findings share a page, none is
    split (unless it is longer than a page). ``after``: the finding placed before, if any."""
    sheet = sheets[-1]
    first_sheet = len(sheets) == 1  # the summary above already says the finding in words
    after = after if after is not None and after.sheets[-1] is sheet else None
    for h in (PLOT_HEIGHT, PLOT_MIN):
        if finding_height(f, k, h, not first_sheet, after) <= sheet.room():
            break
    else:
        sheets.append(Sheet(f"{title}: evidence"))
        sheet, h, after = sheets[-1], PLOT_HEIGHT, None
    repeat = not (first_sheet and sheet is sheets[0])
    drawn = draw_finding(sheet, f, k, h, repeat, after)
    sheets[-1:] = drawn.sheets
    return drawn


def pages(path: Path, pdf, context) -> None:
    d = load_yaml(path)
    title = f"Diagnosis, {d['domain']}: {Path(path).name}"
    notes = (
        (CHANNEL_NOTE,) if any(_g(v) == "0 (exact)" for v in (d["baseline"].get("heldout_rmse") or {}).values()) else ()
    )
    sheets = table_sheets(title, *channel_table(d), intro=summary_lines(d), notes=notes)
    drawn, tables = None, {}  # a runners-up table already drawn -> the finding it was drawn for
    for k, f in enumerate(d.get("findings") or []):
        key = repr(f.get("runners_up"))
        f = {**f, "domain": d["domain"], "declined_later": d.get("declined"), "runners_as": tables.get(key)}
        tables.setdefault(key, k + 1)
        drawn = place_finding(sheets, f, k, title, drawn)
    for text in limits_lines(d) if d.get("findings") else ():  # below the last finding, or on a page of its own
        if not sheets[-1].paragraph(text):
            sheets.append(Sheet(f"{title}: detection limits"))
            sheets[-1].paragraph(text)
    for sheet in sheets:
        save_page(pdf, sheet.fig)


register_section(
    Section("diagnosis", recognise, pages, describe, heading="Diagnosis", abstract=abstract, headline=headline)
)
