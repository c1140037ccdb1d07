"""Diagnosis pages: several findings share a page when they fit whole, none is split across pages.

A real diagnosis of a simulated 3-link arm with three injected effects (seeded), read back with pymupdf.
"""

from __future__ import annotations

import re

import pytest
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.io import load_yaml
from tests.report.checks import check_pages, front_pages, page_texts

pymupdf = pytest.importorskip("pymupdf")
runner = CliRunner()


def _cli(*args):
    r = runner.invoke(app, [str(a) for a in args])
    assert r.exit_code == 0, r.output


@pytest.fixture(scope="module")
def diagnosis(tmp_path_factory):
    d = tmp_path_factory.mktemp("diag")
    effects = ["position_friction:joint3", "torque_offset:joint1", "spring:joint2"]
    _cli(
        "simulate", "dynamics", "--robot", "arm3", "--duration", 20, "--rate", 50, "--seed", 5,
        *[a for e in effects for a in ("--effect", e)], "-o", d / "arm.h5", "-q",
    )  # fmt: skip
    _cli("diagnose", d / "arm.h5", "-o", d / "arm.diagnosis.yaml", "-q")
    _cli("report", d / "arm.diagnosis.yaml", "-o", d / "r.pdf", "-q")
    return load_yaml(d / "arm.diagnosis.yaml"), pymupdf.open(d / "r.pdf")


def test_findings_are_kept_whole_and_share_pages(diagnosis):
    d, doc = diagnosis
    findings = d["findings"]
    assert len(findings) >= 2, "the simulated effects should be found"
    check_pages(doc)
    pages = page_texts(doc)

    def page_of(pattern: str) -> list[int]:
        return [i for i, t in enumerate(pages) if re.search(pattern, t)]

    for k, f in enumerate(findings, start=1):
        head = page_of(rf"Finding {k}: {f['cause']} on {f['channel']}")
        assert len(head) == 1, (k, head)
        # the finding's plot title and its runners-up (or the words saying there are none) on its page
        assert f"{f['cause']} on {f['channel']}: residual on the validation" in pages[head[0]]
        if f.get("runners_up"):
            assert "Runners-up of this round" in pages[head[0]]
            last = f["runners_up"][-1]
            assert f"{last['cause']} {last['channel']}" in pages[head[0]]  # the table's last row too
    # the section's first page (after the contents and summary) holds the first finding when it fits,
    # so the section has fewer pages than findings + 1
    front = front_pages(doc)
    assert front >= 1 and "Contents" in pages[0] and "Summary" in pages[0]
    first = page_of(r"Finding 1:")
    assert first in ([front], [front + 1])
    if first == [front + 1]:  # only where the section's first page lacks the room
        assert _free_height(doc[front]) < _finding_height(doc[front + 1])
    else:
        assert max(page_of(r"Finding \d+:")) - front + 1 < len(findings) + 1  # then the detection limits
    assert "Detection limits (an effect found 80 % of the time" in " ".join(" ".join(pages[-1:]).split())


def _text_blocks(page):
    """The page's text blocks above its footer, and the footer's top."""
    blocks = page.get_text("blocks")
    footer = max(b[1] for b in blocks)
    return [b for b in blocks if b[1] < footer], footer


def _free_height(page) -> float:
    """The height left between a page's last text and its footer."""
    body, footer = _text_blocks(page)
    return footer - max(b[3] for b in body)


def _finding_height(page) -> float:
    """The height of the first finding on a page: from its heading to the page's last text."""
    body, _ = _text_blocks(page)
    top = min(b[1] for b in body if b[4].startswith("Finding "))
    return max(b[3] for b in body) - top


def test_small_findings_share_a_page(diagnosis, tmp_path):
    """Findings without runners-up (a round that tested one candidate) are small: two fit on a page,
    each with its caption, the second referring to the first's where its figure draws the same."""
    from diegocal.io import save_yaml

    d, _ = diagnosis
    small = {**d, "findings": [{**f, "runners_up": []} for f in d["findings"]]}
    save_yaml(small, tmp_path / "small.diagnosis.yaml")
    _cli("report", tmp_path / "small.diagnosis.yaml", "-o", tmp_path / "s.pdf", "-q")
    doc = pymupdf.open(tmp_path / "s.pdf")
    check_pages(doc)
    pages = page_texts(doc)
    shared = [t for t in pages if len(re.findall(r"Finding \d+: ", t)) >= 2]
    assert shared, "no page holds two findings"
    for t in shared:
        captions = t.count("Mean residual on the validation") + t.count("Lines, bands and shading as in Finding")
        assert captions == len(re.findall(r"Finding \d+: ", t)), t
        assert t.count("No runner-up is recorded for this finding") == len(re.findall(r"Finding \d+: ", t))
    holding = [i for i, t in enumerate(pages) if re.search(r"Finding \d+: ", t)]
    assert holding[-1] - front_pages(doc) + 1 <= (len(d["findings"]) + 2) // 2  # the detection limits after


def test_a_finding_without_curves_says_so_instead_of_an_empty_plot(diagnosis, tmp_path):
    """A fault, or a cause tried whole (a mocap clock seconds off), stores no residual curve: its
    page says why in words and draws no axes for it."""
    from diegocal.io import save_yaml

    d, _ = diagnosis
    first = d["findings"][0]
    bare = {**first, "evidence": {k: v for k, v in first["evidence"].items() if k != "curves"}}
    save_yaml({**d, "findings": [bare]}, tmp_path / "bare.diagnosis.yaml")
    _cli("report", tmp_path / "bare.diagnosis.yaml", "-o", tmp_path / "b.pdf", "-q")
    doc = pymupdf.open(tmp_path / "b.pdf")
    check_pages(doc)
    page = page_texts(doc)[front_pages(doc)]
    assert "No residual curve" in " ".join(page.split())
    assert "residual on the validation" not in page  # no plot title: no empty plot
    assert "samples in 0 bins" not in page


def test_a_fitted_value_has_the_digits_its_standard_error_gives_it():
    from diegocal.report.finding_notes import parameters_text

    def text(value, se):
        seconds = {"value": value, "stderr": se, "unit": "s"}
        return parameters_text({"cause": "time_offset", "parameters": {"seconds": seconds}})

    assert text(-0.999627869784981, 0.00027) == " Fitted: seconds = -0.99963 ± 0.00027 s."  # was "-1 ± 0.00027"
    assert text(0.0452634, 0.0007) == " Fitted: seconds = 0.04526 ± 0.0007 s."
    assert text(1234.5, 30.0) == " Fitted: seconds = 1234 ± 30 s."
    assert text(0.0452634, None) == " Fitted: seconds = 0.0453 s."


def test_a_gain_against_identified_inertias_says_it_is_relative():
    from diegocal.report.diagnose import sentence

    gain = {"value": 0.1005, "stderr": 0.0007, "unit": "1"}
    f = {"cause": "torque_gain", "channel": "joint2", "parameters": {"gain_error": gain}, "unit": "N·m",
         "gain": {"rmse_before": 0.265, "rmse_after": 0.103, "reduction": 0.61}}
    assert "against the other joints'" not in sentence(f)  # against the URDF's inertias: absolute
    said = sentence(f | {"extra": {"relative": True}})
    assert "joint2's gain against the other joints'" in said and "--inertia nominal" in said


def test_findings_of_one_round_show_its_runners_up_once(diagnosis, tmp_path):
    """A report review: TIAGo's three findings, chosen in one round, each repeated the same table."""
    from diegocal.io import save_yaml

    d, _ = diagnosis
    shared = d["findings"][0]["runners_up"]
    same = {**d, "findings": [{**f, "runners_up": shared} for f in d["findings"]]}
    save_yaml(same, tmp_path / "same.diagnosis.yaml")
    _cli("report", tmp_path / "same.diagnosis.yaml", "-o", tmp_path / "same.pdf", "-q")
    text = " ".join(page_texts(pymupdf.open(tmp_path / "same.pdf")))
    assert text.count("Runners-up of this round") == len(d["findings"])  # one table, then references
    assert "Runners-up of this round: as in Finding 1's table." in text
