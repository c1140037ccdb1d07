"""How diegocal installs (#32): pip prints no setuptools deprecation for the project table."""

import tomllib
from pathlib import Path

PYPROJECT = Path(__file__).resolve().parents[2] / "pyproject.toml"


def test_the_license_is_an_spdx_expression():
    """setuptools >= 77 deprecates ``license = {text = ...}`` (a warning printed three times by
    every `pip install -e .`); the SPDX string needs setuptools >= 77 at build time."""
    data = tomllib.loads(PYPROJECT.read_text())
    assert data["project"]["license"] == "MIT"
    requires = data["build-system"]["requires"]
    assert "setuptools>=77" in requires and not any(r.startswith("wheel") for r in requires)
