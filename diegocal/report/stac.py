"""Report section for calib.yaml (thesis ch. 2; registers itself on import).

What the section recognises and how it is listed; its pages, tables and words are in
:mod:`diegocal.report.stac_pages`, its plots in :mod:`diegocal.report.stac_plots`.
"""

from __future__ import annotations

from pathlib import Path

from diegocal.io.bundle import load_bundle
from diegocal.report.registry import Section, is_bundle, register_section
from diegocal.report.stac_pages import HELDOUT_STREAMS, abstract, headline, pages


def recognise(path: Path) -> bool:
    return is_bundle(path, "kinematics")


def describe(path: Path) -> dict:
    """Title-page facts from the bundle header ({log, robot, command, created}; legacy ``meta``)."""
    bundle = load_bundle(path)
    data = bundle.data
    meta = data.get("meta") or {}
    out = {k: data.get(k, meta.get(k)) for k in ("log", "command", "created")}
    rec = bundle.robot
    out["robot"] = rec["dir"] or rec["name"]
    return {k: v for k, v in out.items() if v}


def heldout_needs(path: Path) -> list:
    """The calibration's robot and the streams a held-out log needs (markers predicted from pots)."""
    return [(load_bundle(path).robot, HELDOUT_STREAMS)]


register_section(
    Section(
        "stac",
        recognise,
        lambda path, pdf, context: pages(Path(path), pdf, context),
        describe,
        heading="Kinematic calibration (STAC)",
        abstract=lambda path, context: abstract(Path(path), context),
        headline=lambda path, context: headline(Path(path), context),
        heldout_needs=heldout_needs,
    )
)
