"""A term on a prismatic joint reads in its own units: a force in N, a stiffness in N/m, a viscous
coefficient in N·s/m, an armature in kg (the registry's units are a revolute joint's; a Panda
finger's position friction had been written in N·m)."""

from __future__ import annotations

import numpy as np

from diegocal.causes import slide_unit
from diegocal.robot import load_robot
from diegocal.sgp.model import DynamicsModel, SGPOptions
from diegocal.terms import make_term
from tests.sgp.conftest import write_robot
from tests.sgp.test_angle_units import MIXED_URDF


def test_a_revolute_unit_reads_as_a_slides():
    assert [slide_unit(u) for u in ("N·m", "N·m·s/rad", "N·m/rad", "kg·m²", "rad", "rad/s", "s", "1")] == [
        "N", "N·s/m", "N/m", "kg", "m", "m/s", "s", "1"]


def test_a_fitted_term_on_a_slide_has_its_units(tmp_path):
    robot = load_robot(write_robot(tmp_path / "mixed", MIXED_URDF))
    rng = np.random.default_rng(0)
    T = 400
    q = np.column_stack([rng.uniform(-3, 3, T), rng.uniform(0.0, 0.3, T), rng.uniform(-2, 2, T)])
    qd, qdd = rng.normal(size=(T, 3)), rng.normal(size=(T, 3))
    tau = rng.normal(size=(T, 3))
    terms = (make_term("spring", "slide", {"stiffness": 0.0}), make_term("armature", "slide", {"inertia": 0.0}),
             make_term("spring", "elbow", {"stiffness": 0.0}))
    model = DynamicsModel(robot, SGPOptions(kind="pr"), robot.joint_names, terms).fit_arrays(q, qd, qdd, tau)
    units = {(t.cause, t.channel): [p.unit for p in t.parameters] for t in model.fitted_terms()}
    assert units == {
        ("spring", "slide"): ["N/m", "m"], ("armature", "slide"): ["kg"], ("spring", "elbow"): ["N·m/rad", "rad"]
    }
