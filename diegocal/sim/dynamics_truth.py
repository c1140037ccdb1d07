"""Readers of a simulated torque log's truth params (:func:`diegocal.sim.dynamics.simulate_dynamics`),
for tests and benches that build a second session of the same robot: fitting code never reads
/truth."""

from __future__ import annotations

from diegocal.sgp.regressor import INERTIAL_NAMES


def true_friction(params: dict) -> dict:
    """``{"viscous": {joint: value}, "coulomb": {joint: value}}`` from a simulated log's truth
    params (layout 2's friction terms; layout 1 wrote these two mappings as they are). For tests
    and benches that build a second session of the same robot: fitting code never reads /truth."""
    if "baseline" not in params:
        return {k: dict(params[k]) for k in ("viscous", "coulomb")}
    out = {"viscous": {}, "coulomb": {}}
    for d in params["baseline"]:
        kind = {"viscous_friction": "viscous", "coulomb_friction": "coulomb"}.get(d["cause"])
        if kind:
            out[kind][d["channel"]] = float(d["parameters"][kind]["value"])
    return out


def true_inertial(params: dict) -> dict:
    """``{joint: [m, mc_x, ..., I_zz]}`` (Pinocchio's order) of a simulated log's truth params."""
    if "baseline" not in params:
        return {j: list(v) for j, v in params["inertial"].items()}
    rigid = next(d for d in params["baseline"] if d["cause"] == "rigid_body")["parameters"]
    return {j: [float(rigid[f"{j}.{p}"]["value"]) for p in INERTIAL_NAMES] for j in params["joints"]}
