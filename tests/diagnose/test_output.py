"""diagnosis.yaml and its report section, from a diagnosis of the toy domain."""

from __future__ import annotations

import sys
from pathlib import Path

import yaml

sys.path.insert(0, str(Path(__file__).parent))
from toy import ToyAdapter, make_data  # noqa: E402

from diegocal.diagnose import DiagnoseOptions, Diagnosis  # noqa: E402
from diegocal.diagnose.engine import run_unit  # noqa: E402
from diegocal.evaluate import split_blocks  # noqa: E402
from diegocal.io import save_yaml  # noqa: E402
from diegocal.io.bundle import load_bundle  # noqa: E402


def toy_diagnosis(effects) -> Diagnosis:
    t, x, y = make_data(3, effects=effects)
    adapter = ToyAdapter(t, x, y)
    blocks = split_blocks(len(t))
    unit = run_unit(adapter, blocks)
    return Diagnosis("toy", (unit,), blocks, t, DiagnoseOptions(domain="dynamics"), (adapter,))


def test_diagnosis_yaml_follows_the_contract(tmp_path):
    d = toy_diagnosis([("bump", "c0", 0.5), ("quadratic", "c1", 0.4)]).to_dict(extended_model="x.extended")
    path = tmp_path / "toy.diagnosis.yaml"
    save_yaml({"kind": "diagnosis", **d}, path)
    back = yaml.safe_load(path.read_text())
    assert load_bundle(path).kind == "diagnosis"
    assert back["domain"] == "toy"
    assert set(back["baseline"]["heldout_rmse"]) == {"c0", "c1"}
    top = back["findings"][0]
    for key in ("cause", "channel", "region", "parameters", "gain", "evidence"):
        assert key in top
    assert 0 < top["gain"]["reduction"] < 1
    assert top["gain"]["rmse_after"] < top["gain"]["rmse_before"]
    assert set(back["blocks"]) == {"train", "validation", "heldout"}
    assert back["extended_model"] == "x.extended"


def test_clean_diagnosis_has_an_empty_findings_list(tmp_path):
    d = toy_diagnosis([]).to_dict()
    assert d["findings"] == []


def test_report_section_reads_it(tmp_path):
    from diegocal.report import write_report

    d = toy_diagnosis([("bump", "c0", 0.5)]).to_dict(extended_model=None)
    path = tmp_path / "toy.diagnosis.yaml"
    save_yaml({"kind": "diagnosis", **d}, path)
    out = tmp_path / "r.pdf"
    assert write_report([path], out) == ["diagnosis"]
    assert out.stat().st_size > 10_000
