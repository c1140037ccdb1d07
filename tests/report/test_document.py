"""The report as a document: contents with right page numbers, every section opening in plain words
with held-out numbers, typeset tables split across pages, nothing off the page or overlapping.

Pages are read back with pymupdf (text and its position), as a reader of the PDF would see them.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.cli.testing import one_line_error
from diegocal.report import ReportContext, write_report
from diegocal.report.layout import Column, table_sheets
from tests.report.checks import check_pages

pymupdf = pytest.importorskip("pymupdf")
runner = CliRunner()


@pytest.fixture(scope="module")
def document(results, tmp_path_factory):
    out = tmp_path_factory.mktemp("doc") / "report.pdf"
    write_report(results.found, out, ReportContext(heldout=tuple(results.heldout)), command="diegocal report (test)")
    return pymupdf.open(out)


def test_nothing_runs_off_the_page_or_overlaps(document):
    check_pages(document)


def test_contents_point_at_the_sections(document):
    first = document[0].get_text()
    assert "Contents" in first and "Summary" in first
    total = document.page_count
    for number, page in enumerate(document, start=1):
        assert f"page {number} of {total}" in page.get_text()
    headings = (
        r"Log|Kinematic calibration \(STAC\)|Pneumatic valve-chamber models|Torque model \(SGP\)|"
        r"Held-out torque prediction|Diagnosis"
    )
    entries = re.findall(rf"^({headings})\n(.+)\n(.+)\n(\d+)$", first, flags=re.M)  # section, file, log, page
    assert len(entries) == 6, first
    # provenance: every result names the log it was made from (a prediction, the log it predicted)
    assert [e[2] for e in entries] == ["kin.h5", "kin.h5", "air.h5", "swing.h5", "swing_heldout.h5", "swing.h5"]
    for heading, result, _, number in entries:
        assert heading in document[int(number) - 1].get_text(), (heading, number)
        assert Path(result).name in document[int(number) - 1].get_text()


def test_sections_open_in_plain_words_with_held_out_numbers(document):
    text = " ".join(" ".join(page.get_text() for page in document).split())  # lines rejoined
    assert "calibrated 7 pots" in text  # the finger's: every gain, but not the biases of its two gauges
    assert "It estimated all 7 gains and 5 of the 7 biases (mcp_abd's and dip's are gauges" in text
    assert re.search(
        r"on kin_heldout\.h5 \(\d+ frames\) the markers predicted from the pots alone lie [\d.]+ mm \(mean\) from "
        r"where the cameras saw them",
        text,
    )
    assert "to a mean distance of" not in text
    assert re.search(r"On held-out data \(swing_heldout.h5, \d+ samples\) nMSE", text)
    assert "inside the predicted ±2σ band" in text
    assert "Domain dynamics, log swing.h5" in text
    assert re.search(r"On held-out data \(air_heldout.h5, 4 chambers\) the 2-s drift is", text)
    assert "[1/(s V)]" in text and "10 %: the thesis's bound" in text  # c7's unit (Table 4.1), a drift level
    for unit in ("[mm]", "[V]", "[N·m]", "[s]"):
        assert unit in text


def test_a_long_table_is_split_with_its_header_and_notes():
    columns = [Column("chamber", align="left"), Column("c1", "V"), Column("c2", "1/V")]
    rows = [[f"chamber{k:03d}", f"{k / 10:.2f}", f"{k:.0f}"] for k in range(150)]
    sheets = table_sheets("Parameters", columns, rows, intro=["A table too long for one page."], notes=["Note."])
    assert len(sheets) >= 2
    texts = [" ".join(t.get_text() for t in s.fig.texts) for s in sheets]
    assert all("chamber" in t and "[1/V]" in t for t in texts)  # the header on every page
    assert "(continued)" in texts[1]
    cells = re.findall(r"chamber\d{3}", " ".join(texts))
    assert sorted(cells) == sorted(r[0] for r in rows)  # every row once
    assert "Note." in texts[-1] and "Note." not in texts[0]
    counts = [len(re.findall(r"chamber\d{3}", t)) for t in texts]
    assert counts[-1] >= 0.3 * max(counts)  # the last page is not a stub
    for s in sheets:
        assert s.room() >= 0


def test_report_command_prints_what_was_calibrated_and_found(results, tmp_path):
    heldout = results.heldout
    found = [results["kin.calib.yaml"], results["swing.diagnosis.yaml"]]
    r = runner.invoke(app, ["report", *map(str, found), "--heldout", str(heldout[0]), "-o", str(tmp_path / "r.pdf")])
    assert r.exit_code == 0, r.output
    assert "what was calibrated and what was found wrong" in r.output
    assert "7 pots" in r.output and "dynamics (swing.h5)" in r.output
    missing = tmp_path / "nowhere.h5"
    assert "no such held-out log" in one_line_error(
        runner.invoke(app, ["report", str(found[0]), "--heldout", str(missing), "-o", str(tmp_path / "x.pdf")])
    )
    assert not (tmp_path / "x.pdf").exists()
