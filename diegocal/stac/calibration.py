"""The calibration result: pot gains and biases, marker positions, mocap frame, noise levels.

Its YAML form is the calib.yaml contract (issue #3; extend, never break)::

    pots:    {NAME: {gain, bias, gain_se, bias_se}}
    markers: {NAME: {link, xyz, xyz_se}}
    mocap:   {R: 3x3, T: [x, y, z]}
    sigma:   {pots, markers}
    fit:     {cost, iterations, converged, seconds}

Extensions written by STAC (optional on read): the bundle header at the top (``kind: calibration``,
``robot: {name, dir, hash}``, ``log``, ``command``, ``version``, ``created``; :mod:`diegocal.io.bundle`),
``sigma.by_group`` (noise level per sensor type, §2.3.5), ``fit.history`` (per-iteration cost and
noise levels), and what the data could not determine::

    unobservable:   # pots whose gain and bias keep their nominal values
      - {pot: neck_yaw, joints: [neck_yaw], reason: no marker moves with joint neck_yaw}
    gauges:         # joint zeros the markers cannot fix
      - {joint: r_wrist, pot: r_wrist, kind: leaf, reason: "every marker joint r_wrist moves is ..."}

Files written before the header existed carry ``meta: {log, robot, command, created}`` instead, and
older ones a ``prediction`` list (cross-sensor MAE rows that ``diegocal predict`` used to add; it no
longer writes into the model it reads).

``terms`` (optional): extra terms of the observation model found by ``diegocal diagnose``
(:mod:`diegocal.stac.terms`), a list of ``{cause, channel, region, parameters, extra}``; ``predict``
honours them.

Simulated logs store the true values in ``/truth`` attribute ``params`` in this same schema.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from diegocal.errors import InputFileError
from diegocal.io.bundle import HEADER_KEYS
from diegocal.robot import Robot

#: Why calib.yaml's ``rejected`` frames were written off (robust losses; stac/robust.py).
REJECTED_REASON = (
    "their pots disagree, far beyond their noise (chi-square tail 1e-6), with the joint angles their "
    "markers need: the markers are not this frame's (another pose's mocap frame?); written off as occluded"
)

#: Why calib.yaml lists a sensor type under ``sigma: unresolved`` (stac/qphase.py floor_factor).
UNRESOLVED_REASON = (
    "its readings keep fewer than sqrt(2N) residual degrees of freedom once q is fitted: the other sensors "
    "cannot tell its noise apart from zero, so sigma is held at that detection limit"
)


def unresolved(groups) -> tuple:
    """calib.yaml's ``sigma: unresolved`` records of the sensor types ``groups``."""
    return tuple({"group": g, "reason": UNRESOLVED_REASON} for g in groups)


@dataclass(frozen=True)
class FitInfo:
    cost: float = float("nan")
    iterations: int = 0
    converged: bool = False
    seconds: float = 0.0


@dataclass(frozen=True)
class Calibration:
    """Sensor parameters θ = [gain, bias, R, T0, d_1:M] (thesis eq. 2.10) with standard errors.

    Attributes
    ----------
    pot_names : (P,) names, in the robot's sensors.yaml order
    gain, bias : (P,) pot gain [V/rad or V/m] and bias [V]
    gain_se, bias_se : (P,) standard errors (NaN when not estimated)
    marker_names, marker_links : (M,)
    marker_xyz : (M, 3) marker positions in their link frames, m
    marker_xyz_se : (M, 3) standard errors, m
    mocap_R : (3, 3) rotation from base link to mocap frame; mocap_T : (3,) translation, m
    sigma_pots, sigma_markers : noise standard deviations (V, m), §2.3.5
    method : 'stac' | 'classical' | 'ekf' | 'nominal'
    sigma_by_group : noise level per sensor type (rotary, linear, tendon, encoder, markers)
    history : per-iteration records as dicts {iteration, cost, sigma_pots, sigma_markers, seconds}
    meta : {log, robot, command, created}, where a legacy calibration came from
    terms : extra terms of the observation model (:mod:`diegocal.stac.terms`), () for STAC's own
    unobservable : ({pot, joints, reason}, ...) pots kept at their nominal gain and bias
    gauges : ({joint, pot, kind, reason}, ...) joint zeros fixed by keeping a pot's bias nominal
    rejected : frame indices (0-based, in the fitted log) whose markers a robust fit wrote off
    sigma_unresolved : ({group, reason}, ...) sensor types whose σ the data do not resolve (held
        at its detection limit, :func:`diegocal.stac.qphase.floor_factor`)
        (:func:`diegocal.stac.robust.gross_frames`)
    header : the bundle header (:func:`diegocal.io.bundle.header`), written first
    """

    pot_names: tuple[str, ...]
    gain: np.ndarray
    bias: np.ndarray
    marker_names: tuple[str, ...]
    marker_links: tuple[str, ...]
    marker_xyz: np.ndarray
    mocap_R: np.ndarray = field(default_factory=lambda: np.eye(3))
    mocap_T: np.ndarray = field(default_factory=lambda: np.zeros(3))
    gain_se: np.ndarray | None = None
    bias_se: np.ndarray | None = None
    marker_xyz_se: np.ndarray | None = None
    sigma_pots: float = float("nan")
    sigma_markers: float = float("nan")
    fit: FitInfo = field(default_factory=FitInfo)
    method: str = "stac"
    sigma_by_group: dict = field(default_factory=dict)
    history: tuple = ()
    meta: dict = field(default_factory=dict)
    terms: tuple = ()
    unobservable: tuple = ()
    gauges: tuple = ()
    rejected: tuple = ()
    sigma_unresolved: tuple = ()
    header: dict = field(default_factory=dict)

    @classmethod
    def nominal(cls, robot: Robot) -> Calibration:
        """The 'manual calibration': sensors.yaml's nominal values, identity mocap frame."""
        pots, markers = robot.sensors.pots, robot.sensors.markers
        return cls(
            pot_names=tuple(p.name for p in pots),
            gain=np.array([p.gain for p in pots], dtype=float),
            bias=np.array([p.bias for p in pots], dtype=float),
            marker_names=tuple(m.name for m in markers),
            marker_links=tuple(m.link for m in markers),
            marker_xyz=np.array([m.xyz for m in markers], dtype=float).reshape(-1, 3),
            method="nominal",
        )

    def to_dict(self) -> dict:
        """The calib.yaml mapping."""
        P, M = len(self.pot_names), len(self.marker_names)
        gse = self.gain_se if self.gain_se is not None else np.full(P, np.nan)
        bse = self.bias_se if self.bias_se is not None else np.full(P, np.nan)
        xse = self.marker_xyz_se if self.marker_xyz_se is not None else np.full((M, 3), np.nan)
        out = {
            **{k: v for k, v in self.header.items()},
            "method": self.method,
            "pots": {
                n: {
                    "gain": float(self.gain[i]),
                    "bias": float(self.bias[i]),
                    "gain_se": _f(gse[i]),
                    "bias_se": _f(bse[i]),
                }
                for i, n in enumerate(self.pot_names)
            },
            "markers": {
                n: {
                    "link": self.marker_links[i],
                    "xyz": [float(v) for v in self.marker_xyz[i]],
                    "xyz_se": [_f(v) for v in xse[i]],
                }
                for i, n in enumerate(self.marker_names)
            },
            "mocap": {
                "R": np.asarray(self.mocap_R, float).tolist(),
                "T": np.asarray(self.mocap_T, float).tolist(),
            },
            "sigma": {"pots": _f(self.sigma_pots), "markers": _f(self.sigma_markers)},
            "fit": {
                "cost": _f(self.fit.cost),
                "iterations": int(self.fit.iterations),
                "converged": bool(self.fit.converged),
                "seconds": _f(self.fit.seconds),
            },
        }
        if self.sigma_by_group:
            out["sigma"]["by_group"] = {k: _f(v) for k, v in self.sigma_by_group.items()}
        if self.sigma_unresolved:
            out["sigma"]["unresolved"] = [dict(u) for u in self.sigma_unresolved]
        if self.history:
            out["fit"]["history"] = [
                {k: (_f(v) if isinstance(v, float) else v) for k, v in h.items()} for h in self.history
            ]
        if self.unobservable:
            out["unobservable"] = [dict(u) for u in self.unobservable]
        if self.gauges:
            out["gauges"] = [dict(g) for g in self.gauges]
        if self.rejected:
            out["rejected"] = {"frames": [int(f) for f in self.rejected], "reason": REJECTED_REASON}
        if self.meta:
            out["meta"] = dict(self.meta)
        if self.terms:
            out["terms"] = [t.to_dict() for t in self.terms]
        return out

    @classmethod
    def from_dict(cls, data: dict, source: str = "calib.yaml") -> Calibration:
        try:
            pots = data.get("pots") or {}
            markers = data.get("markers") or {}
            mocap = data.get("mocap") or {}
            sigma = data.get("sigma") or {}
            fit = data.get("fit") or {}
            names = tuple(pots)
            mnames = tuple(markers)
            return cls(
                pot_names=names,
                gain=np.array([float(pots[n]["gain"]) for n in names]),
                bias=np.array([float(pots[n]["bias"]) for n in names]),
                gain_se=np.array([_nan(pots[n].get("gain_se")) for n in names]),
                bias_se=np.array([_nan(pots[n].get("bias_se")) for n in names]),
                marker_names=mnames,
                marker_links=tuple(str(markers[n]["link"]) for n in mnames),
                marker_xyz=np.array([markers[n]["xyz"] for n in mnames], dtype=float).reshape(-1, 3),
                marker_xyz_se=np.array(
                    [[_nan(v) for v in (markers[n].get("xyz_se") or [None] * 3)] for n in mnames],
                    dtype=float,
                ).reshape(-1, 3),
                mocap_R=np.array(mocap.get("R", np.eye(3)), dtype=float).reshape(3, 3),
                mocap_T=np.array(mocap.get("T", [0.0, 0.0, 0.0]), dtype=float).reshape(3),
                sigma_pots=_nan(sigma.get("pots")),
                sigma_markers=_nan(sigma.get("markers")),
                fit=FitInfo(
                    _nan(fit.get("cost")),
                    int(fit.get("iterations", 0)),
                    bool(fit.get("converged", False)),
                    _nan(fit.get("seconds")),
                ),
                method=str(data.get("method", "stac")),
                sigma_by_group={str(k): _nan(v) for k, v in (sigma.get("by_group") or {}).items()},
                history=tuple(dict(h) for h in (fit.get("history") or ())),
                meta=dict(data.get("meta") or {}),
                terms=_terms(data.get("terms")),
                unobservable=tuple(dict(u) for u in (data.get("unobservable") or ())),
                gauges=tuple(dict(g) for g in (data.get("gauges") or ())),
                rejected=tuple(int(f) for f in ((data.get("rejected") or {}).get("frames") or ())),
                sigma_unresolved=tuple(dict(u) for u in (sigma.get("unresolved") or ())),
                header={k: data[k] for k in HEADER_KEYS if k in data},
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise InputFileError(f"{source}: not a valid calib.yaml ({type(exc).__name__}: {exc})") from None


def _terms(items) -> tuple:
    if not items:
        return ()
    from diegocal.terms import term_from_dict

    return tuple(term_from_dict(d, "calib.yaml terms", "kinematics") for d in items)


def _f(v) -> float | None:
    v = float(v)
    return None if not np.isfinite(v) else v


def _nan(v) -> float:
    return float("nan") if v is None else float(v)
