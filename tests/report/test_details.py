"""Details a reader of the report notices (issue #32): every trace told apart, names shortened so
that they stay distinct, curves beside each other drawn at the same rate, an uncertainty band that
can be seen and a caption that says what it does, captions that describe only what is drawn, the
runners-up of a diagnosis, the front page of a one-result report.

Checked on the figures the sections draw (their axes and artists) and on the PDF's text."""

from __future__ import annotations

import re
from types import SimpleNamespace

import matplotlib.pyplot as plt
import numpy as np
import pytest
from matplotlib.patches import Polygon, Rectangle

from diegocal.io import load_yaml, save_yaml
from diegocal.report import ReportContext
from diegocal.report.diagnose import plot_evidence
from diegocal.report.layout import Column, table_sheets, text_width
from diegocal.report.logs import plot_stream
from diegocal.report.pdf import Document
from diegocal.report.registry import section_for
from diegocal.terms import Region, make_term
from tests.report.checks import check_pages, front_pages, page_texts
from tests.report.conftest import cli

pymupdf = pytest.importorskip("pymupdf")


def _pages(path, context: ReportContext | None = None):
    """The figures a result's section draws."""
    doc = Document()
    section_for(path).pages(path, doc, context or ReportContext())
    return doc.pages


def _fig_text(fig) -> str:
    """A figure's text: its own (headings, paragraphs, captions) and its axes' titles and labels."""
    texts = [t.get_text() for t in fig.texts]
    for ax in fig.axes:
        texts += [ax.get_title(), ax.get_xlabel(), ax.get_ylabel()] + [t.get_text() for t in ax.texts]
    return " ".join(" ".join(texts).split())


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


# ----------------------------------------------------------------------------- 1. traces
def test_twelve_traces_are_twelve_styles():
    """The log page's 12 channels (a 10-colour cycle gave two markers one colour): each trace, and
    its legend entry, has its own colour and line style."""
    names = [f"m{k:02d}" for k in range(1, 13)]
    t = np.linspace(0.0, 1.0, 50)
    log = SimpleNamespace(
        time=t, n_samples=t.size, streams={"pots": SimpleNamespace(names=names, data=np.outer(t, np.arange(12)))}
    )
    ax = plot_stream(log, "pots")
    styles = [(str(line.get_color()), line.get_linestyle()) for line in ax.get_lines()]
    assert len(styles) == 12 and len(set(styles)) == 12, styles
    handles = ax.get_legend().legend_handles
    assert len({(str(h.get_color()), h.get_linestyle()) for h in handles}) == 12


# ----------------------------------------------------------------------------- 2. names
CHAMBERS = [f"{side}_shoulder_{axis}.{kind}" for side in "rl" for axis in ("pitch", "roll") for kind in ("flex", "ext")]


def test_shortened_names_stay_distinct():
    """Names that share a long prefix ("r_shoulder_pitch.flex", "r_shoulder_pitch.ext") are cut in
    the middle: every shortened name is different and keeps the name's head and its end."""
    from diegocal.report.layout import shorten_distinct  # new: the module imports on the code before it

    for width in range(8, 22):
        short = shorten_distinct(CHAMBERS, lambda s, w=width: len(s) <= w)
        assert len(set(short)) == len(CHAMBERS), (width, short)
        for name, s in zip(CHAMBERS, short, strict=True):
            if s != name:
                head, tail = s.split("…")
                assert name.startswith(head) and name.endswith(tail) and len(s) <= width, (name, s)


def test_a_table_too_wide_keeps_its_names_apart():
    """The pneumatic parameter table's case: a wide table shortens its name column, and two
    chambers never read alike."""
    columns = [Column("chamber", align="left")] + [Column(f"c{k}", "kPa·s/V") for k in range(1, 13)]
    rows = [[name] + [f"{-1234.5678 * k:.6g}" for k in range(1, 13)] for name in CHAMBERS]
    (sheet,) = table_sheets("Fitted parameters per chamber", columns, rows, size=7)
    cells = [t.get_text() for t in sheet.fig.texts if re.fullmatch(r"[rl]_.*", t.get_text())]
    assert len(cells) == len(CHAMBERS)
    assert any("…" in c for c in cells), "the table was meant to be too wide"
    assert len(set(cells)) == len(cells), cells
    assert all(text_width(c, 6.5) < 0.3 for c in cells)


# ----------------------------------------------------------------------------- 3. drift rates
def _drift_axes(results, heldout: bool):
    context = ReportContext(heldout=(results["air_heldout.h5"],) if heldout else ())
    for fig in _pages(results["air.pneumatic.yaml"], context):
        for ax in fig.axes:
            if ax.get_title().startswith("Drift of open-loop pressure prediction"):
                return ax
    raise AssertionError("no drift figure")


def test_fit_log_and_held_out_drift_are_drawn_at_the_same_rate(results):
    """Fig. 4.13: the fit log's curves and the held-out one are drawn at the same points in time
    (once: the fit log's every 0.1 s beside the held-out log's every 10 ms), and the axis says the step."""
    ax = _drift_axes(results, heldout=True)
    lines = {line.get_label(): line for line in ax.get_lines()}
    fit = lines["all chambers pooled (fit log)"].get_xdata()
    held = lines["all chambers pooled (held-out log)"].get_xdata()
    one = lines["one chamber (fit log)"].get_xdata()
    step = np.median(np.diff(fit))
    assert np.allclose(np.diff(held), step) and np.allclose(np.diff(one), step)
    np.testing.assert_allclose(held, fit[: held.size])
    assert f"a point every {1000 * step:.0f} ms" in ax.get_xlabel()


def test_stored_drift_curves_are_said_at_their_step(results, tmp_path):
    """Without the fit log (moved away) the stored curves are drawn, a point every 0.1 s, and the
    held-out curve at the same points."""
    model = load_yaml(results["air.pneumatic.yaml"])
    model["meta"]["log"] = str(tmp_path / "moved.h5")
    save_yaml(model, tmp_path / "moved.pneumatic.yaml")
    context = ReportContext(heldout=(results["air_heldout.h5"],))
    (ax,) = [
        ax
        for fig in _pages(tmp_path / "moved.pneumatic.yaml", context)
        for ax in fig.axes
        if ax.get_title().startswith("Drift of open-loop")
    ]
    lines = {line.get_label(): line for line in ax.get_lines()}
    fit = lines["all chambers pooled (fit log)"].get_xdata()
    held = lines["all chambers pooled (held-out log)"].get_xdata()
    assert np.allclose(np.diff(fit), 0.1) and np.allclose(np.diff(held), 0.1)
    assert "a point every 0.1 s" in ax.get_xlabel()


# ----------------------------------------------------------------------------- 4. uncertainty band
def _slice_figures(results, model: str):
    figs = _pages(results["swing_models"] / model)
    return [f for f in figs if "uncertainty in state space" in _fig_text(f)]


@pytest.mark.parametrize("model", ["pr.sgp", "sgp.sgp"])
def test_the_band_is_visible_and_its_caption_says_what_it_does(results, model):
    """Fig. 3.10's band can be a hair's breadth beside the torque: its width is drawn on its own
    axis from zero, scaled to it; the caption gives, per joint, its width at the training angles and
    beyond them, and says "grows away from the data" only where it does."""
    figs = _slice_figures(results, model)
    assert figs
    for fig in figs:
        caption = _fig_text(fig)
        assert "The uncertainty should grow away from the data" not in caption
        widths = [ax for ax in fig.axes if any(line.get_label() == "2σ (latent)" for line in ax.get_lines())]
        assert widths
        for ax in widths:
            (line,) = [line for line in ax.get_lines() if line.get_label() == "2σ (latent)"]
            q, w = line.get_xdata(), line.get_ydata()
            low, high = ax.get_ylim()
            assert low == 0 and w.max() <= high <= 1.5 * w.max()  # the axis is the band's
            (span,) = [p for p in ax.patches if isinstance(p, (Polygon, Rectangle))]
            x0, x1 = _xrange(span)
            inside = (q >= x0) & (q <= x1)
            joint = ax.get_xlabel().split(".", 1)[1].split(" ")[0]
            words = re.search(rf"{joint}: 2σ is ([\d.e-]+) N·m among the training angles(.*?)(;|\.(?: |$))", caption)
            assert words, caption
            assert float(words.group(1)) == pytest.approx(np.median(w[inside]), rel=0.06)
            if (~inside).any():
                ratio = w[~inside].max() / np.median(w[inside])
                assert ("grows away from the data" in words.group(2)) == (ratio >= 1.5), (ratio, words.group(0))


def test_the_band_words_follow_the_band():
    """ "Grows away from the data" is said of a band that does, "stays about flat" of one that does not."""
    from diegocal.report.sgp_plots import AngleSlice

    q = np.linspace(-3.0, 3.0, 61)
    seen = np.linspace(-0.5, 0.5, 40)
    grows = AngleSlice("j", "sgp", "N·m", q, 0 * q, 0.01 + 0.02 * q**2, seen, gp=True)
    flat = AngleSlice("j", "pr", "N·m", q, 0 * q, 0.01 + 0 * q, seen, gp=False)
    assert "it grows away from the data" in grows.words() and "flat" not in grows.words()
    assert "it stays about flat" in flat.words() and "grows" not in flat.words()
    assert "no Gaussian process on this joint" in flat.words()
    whole = AngleSlice("j", "sgp", "N·m", q, 0 * q, 0.01 + 0 * q, q, gp=True)
    assert "span the whole range shown" in whole.words()


# ----------------------------------------------------------------------------- 5. captions
def _finding(region: bool, variable: str = "q.joint3") -> dict:
    x = np.linspace(0.2, 1.6, 8)
    curve = {"variable": variable, "centre": list(x), "mean": list(0.05 * np.sin(x)), "se": [0.01] * 8}
    return {
        "cause": "position_friction" if region else "torque_offset",
        "channel": "joint3",
        "region": {"variable": "q.joint3", "low": 0.9, "high": 1.3} if region else None,
        "unit": "N·m",
        "gain": {"rmse_before": 0.11, "rmse_after": 0.02, "reduction": 0.8},
        "evidence": {"variable": variable, "curves": {"before": curve, "after": curve, "unit": "N·m"}},
        "domain": "dynamics",
    }


def _xrange(span) -> tuple[float, float]:
    """The x extent of an axvspan (a Rectangle, or a Polygon in older matplotlib), data units."""
    if isinstance(span, Rectangle):
        return span.get_x(), span.get_x() + span.get_width()
    x = np.asarray(span.get_xy())[:, 0]
    return float(x.min()), float(x.max())


def _has_region(ax) -> bool:
    return any(isinstance(p, (Polygon, Rectangle)) for p in ax.patches)


@pytest.mark.parametrize(
    ("region", "variable", "green"), [(True, "q.joint3", True), (False, "q.joint3", False), (True, "qd.joint3", False)]
)
def test_a_caption_describes_what_is_drawn(region, variable, green):
    """Green is in the caption exactly when the region is drawn (a region of another variable is
    said to be not drawn); a finding without a region has no green region in its caption."""
    from diegocal.report.diagnose import evidence_caption

    f = _finding(region, variable)
    ax = plot_evidence(f)
    drawn = any(isinstance(p, (Polygon, Rectangle)) for p in ax.patches)
    assert drawn == green
    caption = evidence_caption(ax, f)
    assert ("green" in caption) == green
    assert ("is not drawn" in caption) == (region and not green)


def test_a_friction_curve_says_it_is_signed_and_a_region_the_shown_blocks_miss():
    """A curve taken times sign(qd) says so on its axis and in its caption; a region found outside
    the bins the validation and held-out blocks fill is said to lie outside them."""
    from diegocal.report.diagnose import evidence_caption

    f = _finding(True)
    f["evidence"]["curves"]["signed_by"] = "qd.joint3"
    f["evidence"]["curves"]["before"]["count"] = [100] * 8
    ax = plot_evidence(f)
    assert "× sign(qd.joint3)" in ax.get_ylabel()
    caption = evidence_caption(ax, f)
    assert caption.startswith("Mean residual times the sign of qd.joint3 (friction")
    assert "lies outside them" not in caption
    f["region"] = {"variable": "q.joint3", "low": 1.7, "high": 2.3}  # beyond the last bin (1.6)
    caption = evidence_caption(plot_evidence(f), f)
    assert "reach q.joint3 from 0.2 to 1.6 only: the region found lies outside them" in caption
    f["evidence"]["curves"]["reach"] = [0.1, 1.75]  # the samples' extent reaches into it
    assert "lies outside them" not in evidence_caption(plot_evidence(f), f)
    f["region"] = {"variable": "q.joint3", "low": -1.0, "high": 0.0}  # below the samples, ending at 0
    assert "from 0.1 to 1.75 only" in evidence_caption(plot_evidence(f), f)


def test_every_diagnosis_caption_matches_its_figure(results, tmp_path):
    """In a report of findings with and without regions, no page speaks of a green region it does
    not draw, and a caption refers to the figure above only when that figure draws the same."""
    d = load_yaml(results["swing.diagnosis.yaml"])
    findings = [_finding(False), _finding(True), _finding(True), _finding(False)]
    for f in findings:
        f.pop("domain")
        f["runners_up"] = []
    save_yaml({**d, "findings": findings}, tmp_path / "mixed.diagnosis.yaml")
    shown = 0
    for fig in _pages(tmp_path / "mixed.diagnosis.yaml"):
        text = _fig_text(fig)
        evidence = [ax for ax in fig.axes if "residual on the validation" in ax.get_title()]
        shown += len(evidence)
        assert text.count("green, the region") <= sum(map(_has_region, evidence))
        if "as in Finding" in text:  # a reference: the figures on the sheet draw the same
            assert len({_has_region(ax) for ax in evidence}) == 1
        captions = text.count("Mean residual on the validation") + text.count("as in Finding")
        assert captions == len(evidence) == len(re.findall(r"Finding \d+: ", text))
    assert shown == len(findings)


def test_the_comparison_caption_says_hatched_only_beside_held_out(results):
    """Without a held-out log the nMSE bars are all solid, and the caption does not speak of hatching."""
    for heldout, hatched in (((), False), ((results["swing_heldout.h5"],), True)):
        figs = _pages(results["swing_models"], ReportContext(heldout=heldout))
        (fig,) = [f for f in figs if any(ax.get_title() == "nMSE per joint and model" for ax in f.axes)]
        (ax,) = [ax for ax in fig.axes if ax.get_title() == "nMSE per joint and model"]
        assert any(bar.get_hatch() for bar in ax.patches) == hatched
        assert ("hatched" in _fig_text(fig)) == hatched


def test_the_dotted_lines_are_where_the_prediction_restarts(results):
    """Fig. 4.12's dotted lines stand where the open-loop prediction is re-initialised with the
    measured pressure (there the two curves meet exactly)."""
    figs = _pages(results["air.pneumatic.yaml"])
    axes = [ax for f in figs for ax in f.axes if "open-loop pressure from the dotted grid lines" in ax.get_title()]
    assert axes
    for ax in axes:
        lines = {line.get_label(): line for line in ax.get_lines()}
        measured, model = lines["measured"], lines["model integrated open loop"]
        t = measured.get_xdata()
        dotted = [line.get_xdata()[0] for line in ax.get_lines() if line.get_linestyle() == ":"]
        assert dotted
        for x in dotted:
            k = int(np.argmin(np.abs(t - x)))
            assert abs(t[k] - x) < 1e-9 and model.get_ydata()[k] == pytest.approx(measured.get_ydata()[k])


# ----------------------------------------------------------------------------- 6. runners-up
def _pneumatic_diagnosis(results, tmp_path, runners) -> str:
    """A pneumatic diagnosis (a late valve on one chamber) whose finding stores ``runners`` (None:
    no runners_up key, as the pneumatic diagnosis wrote it), reported; the PDF's text."""
    d = load_yaml(results["swing.diagnosis.yaml"])
    x = list(np.linspace(-0.02, 0.03, 8))
    curve = {"variable": "du.r_elbow.flex", "centre": x, "mean": [1.0] * 8, "se": [0.5] * 8}
    f = {
        "cause": "valve_delay",
        "channel": "r_elbow.flex",
        "region": None,
        "parameters": {"delay_s": {"value": 0.0336, "std": 8.8e-05, "unit": "s"}},
        "gain": {"rmse_before": 63.2, "rmse_after": 15.3, "reduction": 0.76},
        "kind": "term",
        "unit": "kPa",
        "evidence": {"variable": "du.r_elbow.flex", "curves": {"before": curve, "after": curve, "unit": "kPa"}},
    }
    if runners is not None:
        f["runners_up"] = runners
    path = tmp_path / "pneu.diagnosis.yaml"
    save_yaml({**d, "domain": "pneumatics", "findings": [f]}, path)
    cli("report", path, "-o", tmp_path / "pneu.pdf", "-q")
    document = pymupdf.open(tmp_path / "pneu.pdf")
    check_pages(document)
    return " ".join(page_texts(document))


RUNNERS = [
    {"cause": c, "channel": "r_elbow.flex", "region": None, "validation_gain": g, "t": t, "threshold_t": 4.5,
     "significant": False}
    for c, g, t in (("chamber_leak", 0.031, 2.1), ("supply_droop", 0.012, 1.2), ("pressure_offset", 0.004, 0.4))
]  # fmt: skip


def test_a_diagnosis_lists_its_runners_up(results, tmp_path):
    text = _pneumatic_diagnosis(results, tmp_path, RUNNERS)
    assert "Runners-up of this round" in text
    for r in RUNNERS:
        assert f"{r['cause']} r_elbow.flex {100 * r['validation_gain']:.1f}" in text
    assert "No runner-up is recorded" not in text and "not stored" not in text


def test_runners_up_not_stored_are_not_said_untested(results, tmp_path):
    """A file without runners_up does not say what was tested: "not stored", never "none tested"."""
    text = _pneumatic_diagnosis(results, tmp_path, None)
    assert "not stored" in text and "No runner-up is recorded" not in text


def test_no_runners_up_stored_as_none(results, tmp_path):
    text = _pneumatic_diagnosis(results, tmp_path, [])
    # a review: "No other candidate was tested" was said where the round had tested three
    assert "No runner-up is recorded for this finding" in text and "not stored" not in text
    assert "No other candidate was tested" not in text


# ----------------------------------------------------------------------------- 7. front page
def test_a_single_diagnosis_report_has_contents_and_summary(results, tmp_path):
    """`diegocal report X.diagnosis.yaml` opens as a report of many does: contents, summary in plain words."""
    cli("report", results["swing.diagnosis.yaml"], "-o", tmp_path / "d.pdf", "-q")
    document = pymupdf.open(tmp_path / "d.pdf")
    check_pages(document)
    pages = page_texts(document)
    front = front_pages(document)
    assert front >= 1
    assert "Contents" in pages[0] and "Summary" in pages[0]
    entry = re.search(r"Diagnosis \S*swing\.diagnosis\.yaml swing\.h5 (\d+)", pages[0])
    assert entry and int(entry.group(1)) == front + 1
    assert "Domain dynamics, log swing.h5" in " ".join(pages[:front])  # the summary in plain words
    assert pages[front].startswith("Diagnosis, dynamics: swing.diagnosis.yaml")


def test_a_minor_fault_is_said_but_is_no_finding():
    from diegocal.report.diagnose import summary_lines

    d = {
        "domain": "kinematics",
        "baseline": {"model": "stac", "heldout_rmse": {"m2": 0.002}, "unit": "m"},
        "extended": {"model": "stac", "heldout_rmse": {"m2": 0.002}, "unit": "m"},
        "findings": [],
        "minor_faults": [
            {
                "cause": "marker_outliers",
                "channel": "m2",
                "readings": 14,
                "gain": {"reduction": 0.0004},
                "written_off": True,
            }
        ],
        "blocks": {"train": [[0, 6]], "validation": [[6, 8]], "heldout": [[8, 10]]},
        "options": {"alpha": 0.01, "min_gain": 0.05},
    }
    text = " ".join(summary_lines(d))
    assert "Nothing significant" in text
    assert "no finding: some marker readings are outliers (ghosts, reflections) on m2 (14 flagged)" in text
    assert "by -0.0%" in text and "written off all the same" in text


def _no_finding(domain: str, model: str, heldout: dict, unit: str, residual_tests: dict) -> dict:
    """A diagnosis.yaml mapping with no finding: the baseline is the extended model."""
    fit = {"model": model, "heldout_rmse": heldout, "unit": unit}
    return {"domain": domain, "baseline": fit, "extended": dict(fit), "findings": [],
            "blocks": {"train": [[0, 6]], "validation": [[6, 8]], "heldout": [[8, 10]]},
            "options": {"alpha": 0.01, "min_gain": 0.05}, "residual_tests": residual_tests}


def test_no_cause_named_is_not_nothing_significant_when_a_term_was_declined_or_a_residual_shifts():
    """A user trial's pot whose gain drifted (CUSUM p 1e-29 on pot3) and a cogging whose best terms
    wanted a negative friction both printed "nothing significant ... as good as this log can tell".
    The words now say what was seen; a clean diagnosis keeps its sentence."""
    from diegocal.diagnose.output import shifting_channels
    from diegocal.report.diagnose import summary_lines

    tests = {f"pot{k}": {"change_point": {"p": 0.02, "time": 3.0}} for k in range(18)}
    d = _no_finding("kinematics", "stac", {"pot3": 0.02}, "V", tests)
    assert shifting_channels(d) == [] and "Nothing significant" in " ".join(summary_lines(d))
    tests["pot3"] = {"change_point": {"p": 1.2e-29, "time": 21.3}}
    text = " ".join(summary_lines(d))
    assert shifting_channels(d) == [("pot3", 1.2e-29, 21.3)]
    assert "Nothing significant" not in text
    assert "The residual of pot3 shifts in time (CUSUM test p 1e-29, at 21.3 s)" in text
    assert shifting_channels({**d, "findings": [{"channel": "pot1"}]}) == []  # a finding changes the others' fit
    tests["pot3"] = {"change_point": {"p": 0.02, "time": 3.0}}
    why = "significant on validation, but the held-out error rose by 0.8% with it"  # one of _decline's
    d["declined"] = [{"cause": "armature", "channel": "joint3", "why": why}]
    text = " ".join(summary_lines(d))
    assert "Nothing significant" not in text and f"Declined: armature on joint3: {why}." in text


def test_significant_binned_structure_under_the_gain_is_not_nothing_significant(tmp_path):
    """A user trial's cogging on a Talos wrist: the summary said "nothing significant" while its
    residual test was significant (8 % of the validation error, under what a finding needs)."""
    from diegocal.diagnose.output import weak_structure
    from diegocal.report.diagnose import headline, summary_lines

    test = {"t": 6.06, "threshold_t": 3.84, "validation_gain": 0.08, "significant": True}
    tests = {"talos/j5": {"variables": {"q.j5": test, "qd.j5": {**test, "significant": False}}}}
    d = {**_no_finding("dynamics", "rigid_body", {"j5": 0.05}, "N·m", tests), "log": "talos.h5"}
    assert weak_structure(d) == [("talos/j5", "q.j5", 0.08)]
    text = " ".join(summary_lines(d))
    assert "Nothing significant" not in text and "significant on talos/j5 against q.j5 (8% of the validation" in text
    save_yaml(d, tmp_path / "d.yaml")
    assert "1 significant binned residual" in headline(tmp_path / "d.yaml")
    test["significant"] = False
    assert weak_structure(d) == [] and "Nothing significant" in " ".join(summary_lines(d))


def test_a_finding_the_data_cannot_place_says_where_else_it_fits():
    from diegocal.diagnose.selection import TWIN
    from diegocal.report.diagnose import sentence

    f = {
        "cause": "link_offset",
        "channel": "l_hip_yaw",
        "gain": {"reduction": 0.22, "rmse_before": 0.004, "rmse_after": 0.0031},
        "unit": "m",
        "evidence": {"indistinguishable_from": ["l_knee"]},
    }
    text = sentence(f)
    assert "cannot tell it from the same cause on l_knee" in text
    assert f"to within {TWIN * 100:g} % or 2 paired standard errors" in text
    assert "cannot tell" not in sentence({**f, "evidence": {}})
    other = sentence({**f, "evidence": {"indistinguishable_causes": ["marker_slip:m2"]}})
    assert "The data cannot tell it from marker_slip:m2" in other and "either may be the cause" in other


def test_a_slip_in_a_gauge_says_which_of_its_numbers_the_data_fix():
    from diegocal.report.diagnose import sentence

    f = {
        "cause": "marker_slip",
        "channel": "m4",
        "region": {"variable": "time", "low": 9.5, "high": float("inf")},
        "parameters": {k: {"value": 0.01, "stderr": 0.0003, "unit": "m"} for k in ("dx", "dy", "dz")},
        "gain": {"reduction": 0.6, "rmse_before": 0.004, "rmse_after": 0.0016},
        "unit": "m",
        "extra": {"gauge": {"joint": "dip", "axis": [0, 1, 0], "length": {"value": 0.01732, "stderr": 0.0003},
                            "along_axis": {"value": 0.01, "stderr": 0.0003}}},
    }
    text = sentence(f)
    assert "(time from 9.5 on)" in text
    assert "about joint dip's axis is the calibration's convention" in text
    assert "its length, 0.01732 ± 0.0003 m" in text and "along the axis, 0.01000 ± 0.0003 m" in text
    assert "convention" not in sentence({**f, "extra": {}})


def test_a_runner_up_with_an_open_region_is_listed():
    """A slip's region runs to the end of the log: written .inf (a NaN alone is written null), read
    as open also from files that wrote it null; the report lists it rather than stopping."""
    from diegocal.diagnose.output import finding_dict
    from diegocal.report.diagnose import runners_table

    runner = {"cause": "marker_slip", "channel": "m1", "region": {"variable": "time", "low": 10.65, "high": np.inf},
              "validation_gain": 0.004, "t": 2.6, "threshold_t": 3.6, "significant": False}
    f = SimpleNamespace(term=make_term("marker_slip", "m4", region=Region("time", 12.4, np.inf)), kind="term",
                        evidence={"t": np.nan}, runners_up=(runner,), gain=dict)
    d = finding_dict(f, {})
    assert d["region"]["high"] == np.inf and d["runners_up"][0]["region"]["high"] == np.inf
    assert d["evidence"]["t"] is None
    for high in (np.inf, None):
        _, rows = runners_table({"runners_up": [{**runner, "region": {**runner["region"], "high": high}}]})
        assert rows[0][1] == "m1 [10.7..inf]"


def test_a_stand_in_says_what_beat_it_a_flexible_model_or_a_declined_term():
    from diegocal.report.finding_notes import stand_in_text

    flexible = {"channel": "dip", "evidence": {"validation_gain": 0.8, "stand_in": {"term": "backlash:dip",
                                                                                    "validation_gain": 0.2}}}
    assert "a flexible function of dip's own state explains 80%" in stand_in_text(flexible)
    declined = {
        "channel": "shoulder.ext",
        "evidence": {
            "validation_gain": 0.74,
            "stand_in": {"term": "supply_droop:shoulder.ext", "validation_gain": 0.48},
            "declined": {"term": "pressure_offset:shoulder.ext", "why": "the held-out error rose by 0.8% with it"},
        },
    }
    text = stand_in_text(declined)
    assert "pressure_offset:shoulder.ext explained 74% and was declined (the held-out error rose" in text
    assert "flexible" not in text and "48%" in text
    rival = {
        "channel": "elbow.flex",
        "evidence": {
            "validation_gain": 0.79,
            "stand_in": {"term": "supply_droop:elbow.flex", "validation_gain": 0.31},
            "rival": {"model": "the pressure read through a first-order filter (τ 45 ms)", "tau_s": 0.045,
                      "open_loop_validation_gain": 0.79, "term_open_loop_validation_gain": 0.12},
        },
    }
    text = stand_in_text(rival)
    assert "supply_droop:elbow.flex, removes 12% of the open-loop validation error" in text
    assert "first-order filter (τ 45 ms), a shape no cause names, removes 79%" in text
    from diegocal.report.diagnose import sentence

    assert "it accounts for 79% of the open-loop validation error" in sentence({**rival, "kind": "unexplained",
                                                                                "cause": "unexplained"})


def test_a_lasting_supply_sag_says_it_is_also_a_sensor_span_error():
    from diegocal.report.diagnose import sentence

    f = {"cause": "supply_droop", "channel": "elbow.ext", "kind": "term", "extra": {"span_error": -0.0104},
         "parameters": {"droop": {"value": 5.42, "stderr": 0.08, "unit": "kPa"}}, "evidence": {}}
    text = sentence(f)
    assert "droop = 5.420 ± 0.08 kPa" in text
    assert "a pressure sensor reading 1.04% of its span low: the data cannot tell the two apart" in text
    orifice = {**f, "extra": {"shape": "orifice"}}  # a sag through a restriction has no such twin
    assert "span" not in sentence(orifice)
    assert "span" not in sentence({**f, "extra": {"shape": "orifice", "span_error": -0.0104}})  # an edited file


def test_the_term_that_stood_in_is_listed_as_such_among_the_runners_up():
    """Under an unexplained finding its one runner-up is the stand-in: the table says so rather than
    the generic reason for a significant candidate not added, and the reason names what beat it."""
    from types import SimpleNamespace as NS

    from diegocal.diagnose.stand_ins import stood_in_why
    from diegocal.report.diagnose import runners_table

    flex = NS(test=NS(gain=0.79))
    rival = {"rival": {"model": "the pressure read through a first-order filter (τ 45 ms)",
                       "open_loop_validation_gain": 0.79, "term_open_loop_validation_gain": 0.19}}
    why = stood_in_why("elbow.flex", flex, rival)
    assert why == ("stood in: the pressure read through a first-order filter (τ 45 ms) removes 79% of the "
                   "open-loop validation error, this term 19%")
    declined = {"declined": {"term": "pressure_offset:shoulder.ext", "why": "no held-out gain"}}
    assert stood_in_why("shoulder.ext", flex, declined).startswith("stood in: pressure_offset:shoulder.ext explained")
    assert stood_in_why("dip", flex, None) == "stood in: a flexible function of dip's own state explains 79%"
    runner = {"cause": "supply_droop", "channel": "elbow.flex", "region": None, "validation_gain": 0.14, "t": 5.0,
              "threshold_t": 3.0, "significant": True}
    _, rows = runners_table({"runners_up": [{**runner, "why_not": why}]})
    assert rows[0][-1] == "yes; stood in"
    _, rows = runners_table({"runners_up": [{**runner, "why_not": "supply_droop explains more of the error"}]})
    assert rows[0][-1] == "yes; less on its channel"
    refitted = "refitted into the model, torque_offset:joint2 leaves less of the validation error of joint1, joint2"
    _, rows = runners_table({"runners_up": [{**runner, "why_not": refitted}]})
    assert rows[0][-1] == "yes; less refitted"
    twin = "the data cannot tell it from spring (the same validation fit, to within the noise)"
    _, rows = runners_table({"runners_up": [{**runner, "why_not": twin}]})
    assert rows[0][-1] == "yes; the same fit"  # not "less on its channel": it removed as much


def test_only_chambers_beyond_the_thesis_bound_are_still_open(results, tmp_path):
    """The pneumatic abstract's "Still open" names the chambers whose 2-s drift is 4 % or more of
    Pc − Pr, with their drift, and says nothing of drift when every chamber is under it."""
    from diegocal.report.pneumatic import abstract
    from diegocal.report.registry import ReportContext

    model = load_yaml(results["air.pneumatic.yaml"])
    names = list(model["chambers"])
    for k, name in enumerate(names):
        model["chambers"][name]["drift_2s"] = 0.01 + 0.001 * k
    save_yaml(model, tmp_path / "calm.pneumatic.yaml")
    text = " ".join(abstract(tmp_path / "calm.pneumatic.yaml", ReportContext()))
    assert "drift beyond" not in text
    model["chambers"][names[0]]["drift_2s"] = 0.073
    save_yaml(model, tmp_path / "one.pneumatic.yaml")
    text = " ".join(abstract(tmp_path / "one.pneumatic.yaml", ReportContext()))
    assert f"Still open: the chambers that drift beyond 4 % on the fit's own log are {names[0]} (7.3 %)" in text


def test_a_parameter_at_the_end_of_its_search_is_said_to_be_there():
    """TIAGo's torso lift gave torque_lag = 0.49995 s, the upper bound of the lag's search: the
    report says the data want more, not only the value."""
    from diegocal.report.finding_notes import parameters_text

    f = {"cause": "torque_lag", "parameters": {"lag": {"value": 0.49995, "stderr": 0.028, "unit": "s"}}}
    assert "the end of its search, 0.5: the data want more" in parameters_text(f)
    f["parameters"]["lag"]["value"] = 0.012
    assert "end of its search" not in parameters_text(f)


def test_a_shared_motors_finding_names_the_other_joint_it_acts_on():
    # a report review: coupled friction on joint_6 credited joint_6 alone; joint_5 gained more
    from diegocal.report.diagnose import sentence

    gain = {"reduction": 0.57, "rmse_before": 1.62, "rmse_after": 0.70}
    f = {"cause": "coupled_friction", "channel": "joint_6", "gain": gain, "unit": "N·m",
         "evidence": {"gain_channels": ["joint_6", "joint_5"]}}
    assert "It acts on joint_5 too (their held-out RMSE in the table of channels)." in sentence(f)
    assert "It acts on" not in sentence({**f, "evidence": {"gain_channels": ["joint_6"]}})


def test_an_sgp_fit_that_did_not_converge_says_so():
    # a report review: sgp.yaml's converged: false (2 of 29 ML-II runs at their cap) was said nowhere
    from diegocal.report.sgp_tables import facts_rows

    s = {"converged": False, "ml2_runs": {"runs": 29, "stopped_at_cap": 2}, "n_samples": 10}
    assert ["converged", "no: 2 of 29 ML-II runs stopped at their cap", ""] in facts_rows(s)
    assert ["converged", "yes", ""] in facts_rows({**s, "converged": True})
    assert not [r for r in facts_rows({"n_samples": 10}) if r[0] == "converged"]  # saved again: not said


def test_a_runner_up_declined_in_a_later_round_says_so():
    # a report review: TIAGo's coupled friction on arm_1 read "yes; next round" in the table, though
    # the next round declined it (a negative viscous term), which the PDF never said
    from diegocal.report.diagnose import runners_table

    runner = {"cause": "coupled_friction", "channel": "arm_1_joint", "validation_gain": 0.337, "t": 5.5,
              "threshold_t": 5.5, "significant": True, "why_not": "tested again in the next round, after x"}
    declined = [{"cause": "coupled_friction", "channel": "arm_1_joint", "why": "viscous −4.96 ± 0.52"}]
    _, rows = runners_table({"runners_up": [runner], "declined_later": declined})
    assert rows[0][-1] == "yes; declined next round (Declined)"
    _, rows = runners_table({"runners_up": [runner]})
    assert rows[0][-1] == "yes; next round"
