"""Shared fixtures: small synthetic robots written to a temporary directory (see synth.py)."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))

import synth  # noqa: E402


@pytest.fixture(scope="session")
def tree_dir(tmp_path_factory):
    return synth.make_tree_robot(tmp_path_factory.mktemp("tree"), synth.SMALL_CHAINS, seed=1)


@pytest.fixture(scope="session")
def tree_robot(tree_dir):
    return synth.load(tree_dir)


@pytest.fixture(scope="session")
def finger_dir(tmp_path_factory):
    return synth.make_finger_robot(tmp_path_factory.mktemp("finger"), seed=2)


@pytest.fixture(scope="session")
def finger_robot(finger_dir):
    return synth.load(finger_dir)
