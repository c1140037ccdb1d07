"""The calibration result: pot gains and biases, marker positions, mocap frame, noise levels.

Its YAML form, calib.yaml (file layout 2), writes every fitted parameter as a term of the
kinematic baseline (:mod:`diegocal.causes`), ``{name: {value, stderr, unit}}`` like every other
file of diegocal::

    kind: calibration             # + the bundle header (robot, log, command, version, created)
    layout: 2
    method: stac
    baseline:
      - {cause: pot_transfer, channel: r_elbow, parameters: {gain: {value, stderr, unit: V/rad}, bias: {...}}}
      - {cause: marker_position, channel: m01, parameters: {x, y, z}, extra: {link: r_upper_arm}}
      - {cause: mocap_frame, channel: markers, parameters: {x, y, z (m), rx, ry, rz (rad, rotation vector)}}
    sigma:   {pots, markers, by_group}
    fit:     {cost, iterations, converged, seconds, history}
    stderr:  {method: block_sandwich, blocks, block_s}   # how the standard errors were estimated

A parameter whose estimate trades off with another's (|ρ| ≥ 0.9: a pot's gain and bias when its
joint stays on one side of zero) carries ``correlated: {<channel>.<parameter>: ρ}`` beside its
value and standard error (:mod:`diegocal.stac.covariance`).

Layout 1 (files without ``layout``) wrote ``pots: {NAME: {gain, bias, gain_se, bias_se}}``,
``markers: {NAME: {link, xyz, xyz_se}}`` and ``mocap: {R, T}``; :meth:`Calibration.from_dict`
reads both. ``sigma.by_group`` is the noise level per sensor type (§2.3.5), ``fit.history`` the
per-iteration cost and noise levels; what the data could not determine::

    unobservable:   # pots whose gain and bias keep their nominal values
      - {pot: neck_yaw, joints: [neck_yaw], reason: no marker moves with joint neck_yaw}
      - {pot: r_elbow, joints: [r_elbow], reason: no channel in the log}
    gauges:         # joint zeros the markers cannot fix
      - {joint: r_wrist, pot: r_wrist, kind: leaf, reason: "every marker joint r_wrist moves is ..."}

and what a fit wrote off: ``rejected: {frames, reason}`` (single frames, robust losses) and, for
static poses, ``rejected_poses: {poses: [{pose, frame, samples, disagreement}], reason}``.

Files written before the header existed carry ``meta: {log, robot, command, created}`` instead, and
older ones a ``prediction`` list (cross-sensor MAE rows that ``diegocal predict`` used to add; it no
longer writes into the model it reads).

``terms`` (optional): extra terms of the observation model found by ``diegocal diagnose``
(:mod:`diegocal.stac.terms`), a list of ``{cause, channel, region, parameters, extra}``; ``predict``
honours them.

Simulated logs store the true values in ``/truth`` attribute ``params`` in this same schema.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial.transform import Rotation

from diegocal.errors import InputFileError
from diegocal.io.bundle import HEADER_KEYS, LAYOUT
from diegocal.robot import Robot
from diegocal.terms import Term, make_term, term_from_dict, write_correlated

#: The units of a pot's (gain, bias) by its kind (an encoder's gain is fixed at 1; its reading is
#: the joint's own coordinate, rad, or m on a prismatic joint).
POT_UNITS = {"rotary": ("V/rad", "V"), "linear": ("V/m", "V"), "tendon": ("V/m", "V"), "encoder": ("1", "rad")}

#: The unit of each sensor type's readings, and so of its residuals and noise σ: a pot's bias unit
#: (:data:`POT_UNITS`; an encoder reads rad, the others V), a marker's position m.
READING_UNITS = {**{kind: units[1] for kind, units in POT_UNITS.items()}, "markers": "m"}

#: What a calibration did with a pot's gain or bias (:meth:`Calibration.pot_roles`): estimated by the
#: fit; fixed by design (an encoder's gain is 1: it reads its joint's own coordinate plus a bias); a
#: gauge (a bias held at nominal because no marker can fix its joint's zero: ``gauges``); unobservable
#: (gain and bias nominal: no marker moves with the joint, or no channel: ``unobservable``); or
#: nominal for no recorded reason (a nominal calibration, or a method without standard errors).
POT_ROLES = ("estimated", "design", "gauge", "unobservable", "nominal")

#: Why calib.yaml's ``rejected`` frames were written off (robust losses; stac/robust.py).
REJECTED_REASON = (
    "their pots disagree, far beyond their noise (chi-square tail 1e-6), with the joint angles their "
    "markers need: the markers are not this frame's (another pose's mocap frame?); written off as occluded"
)

#: Why calib.yaml's ``rejected_poses`` were written off (static-pose logs; stac/poses.py).
REJECTED_POSES_REASON = (
    "the pose's markers disagree with its pots, at a calibration fitted without them, far beyond the noise "
    "of the other poses (chi-square tail 1e-6): another pose's mocap frame (a drifting clock?); its markers "
    "are written off as occluded"
)

#: Why calib.yaml lists a sensor type under ``sigma: unresolved`` (stac/robust.py floor_factor).
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
    gain, bias : (P,) pot gain [V/rad or V/m; 1 for an encoder] and bias [V; rad for an encoder]
    gain_se, bias_se : (P,) standard errors (NaN when not estimated)
    marker_names, marker_links : (M,)
    marker_xyz : (M, 3) marker positions in their link frames, m
    marker_xyz_se : (M, 3) standard errors, m; marker_xyz_cov : (2, 3M, 3M) the coordinates'
        covariance, m², reported (block sandwich) and model-based (in memory only: a function of
        them, a slip's move, needs it; None when not estimated)
    mocap_R : (3, 3) rotation from base link to mocap frame; mocap_T : (3,) translation, m
    sigma_pots, sigma_markers : noise standard deviations, §2.3.5: the pots' is the RMS of the
        per-type σ (V, but pooled with rad when the robot has encoders: read ``sigma_by_group``), m
    method : 'stac' | 'classical' | 'ekf' | 'nominal'
    sigma_by_group : noise level per sensor type (rotary, linear, tendon, encoder, markers), each in
        its type's unit (:data:`READING_UNITS`: V, rad for encoders, m)
    history : per-iteration records as dicts {iteration, cost, sigma_pots, sigma_markers, seconds}
    meta : {log, robot, command, created}, where a legacy calibration came from
    terms : extra terms of the observation model (:mod:`diegocal.stac.terms`), () for STAC's own
    unobservable : ({pot, joints, reason}, ...) pots kept at their nominal gain and bias
    gauges : ({joint, pot, kind, reason}, ...) joint zeros fixed by keeping a pot's bias nominal
    rejected : frame indices (0-based, in the fitted log) whose markers a robust fit wrote off
        (:func:`diegocal.stac.robust.gross_frames`)
    rejected_poses : ({pose, frame, samples, disagreement}, ...) static poses whose markers were
        written off as another pose's (:mod:`diegocal.stac.poses`): pose index, its first frame
        (0-based), its samples, its disagreement over the threshold (> 1)
    sigma_unresolved : ({group, reason}, ...) sensor types whose σ the data do not resolve (held
        at its detection limit, :func:`diegocal.stac.robust.floor_factor`)
    header : the bundle header (:func:`diegocal.io.bundle.header`), written first
    pot_units : ((gain unit, bias unit), ...) per pot (:data:`POT_UNITS`); () when not known
    correlations : ((label, label, ρ), ...) estimates that trade off (|ρ| ≥ 0.9), labels
        ``<pot>.gain``, ``<pot>.bias``, ``<marker>.x|y|z``: written next to each value
    stderr : how the standard errors were estimated ({method, blocks, block_s}; {} unknown)
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
    marker_xyz_cov: np.ndarray | None = field(default=None, repr=False, compare=False)
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
    rejected_poses: tuple = ()
    sigma_unresolved: tuple = ()
    header: dict = field(default_factory=dict)
    pot_units: tuple = ()
    correlations: tuple = ()
    stderr: dict = field(default_factory=dict)

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
            pot_units=tuple(POT_UNITS.get(p.kind, ("", "")) for p in pots),
        )

    @property
    def calibrated_pots(self) -> tuple[str, ...]:
        """Names of the pots whose gain or bias the fit estimated (a finite standard error), in
        ``pot_names`` order: not those listed as unobservable (no marker moves with their joints,
        or no channel in the log), nor any of a nominal calibration."""
        P = len(self.pot_names)
        gse = self.gain_se if self.gain_se is not None else np.full(P, np.nan)
        bse = self.bias_se if self.bias_se is not None else np.full(P, np.nan)
        held = {u.get("pot") for u in self.unobservable}
        fitted = np.isfinite(gse) | np.isfinite(bse)
        return tuple(n for n, ok in zip(self.pot_names, fitted, strict=True) if ok and n not in held)

    def pot_roles(self, kinds: dict | None = None) -> dict:
        """{pot: (gain role, bias role)}, each one of :data:`POT_ROLES`, in ``pot_names`` order.

        An encoder's gain is known from ``pot_units`` (gain unit "1") or, for files without units,
        from ``kinds`` ({pot: sensors.yaml kind}); gauges and unobservable pots from calib.yaml's
        ``gauges`` and ``unobservable`` lists; an estimate is a finite standard error.
        """
        P = len(self.pot_names)
        gse = self.gain_se if self.gain_se is not None else np.full(P, np.nan)
        bse = self.bias_se if self.bias_se is not None else np.full(P, np.nan)
        unobservable = {u.get("pot") for u in self.unobservable}
        gauges = {g.get("pot") for g in self.gauges}
        kinds = kinds or {}
        # a method that gives no standard errors at all (the EKF) still estimated what it did not hold
        unknown_se = self.method != "nominal" and not (np.isfinite(gse).any() or np.isfinite(bse).any())
        out = {}
        for i, n in enumerate(self.pot_names):
            unit = self.pot_units[i][0] if i < len(self.pot_units) else None
            design = unit == POT_UNITS["encoder"][0] or (unit is None and kinds.get(n) == "encoder")
            if n in unobservable:
                out[n] = ("design" if design else "unobservable", "unobservable")
                continue
            gain = "design" if design else "estimated" if np.isfinite(gse[i]) or unknown_se else "nominal"
            bias = "gauge" if n in gauges else "estimated" if np.isfinite(bse[i]) or unknown_se else "nominal"
            out[n] = (gain, bias)
        return out

    def baseline_terms(self) -> tuple[Term, ...]:
        """The kinematic baseline as terms: a ``pot_transfer`` per pot, a ``marker_position`` per
        marker, the ``mocap_frame`` (:mod:`diegocal.causes`), with values, standard errors, units."""
        P, M = len(self.pot_names), len(self.marker_names)
        gse = self.gain_se if self.gain_se is not None else np.full(P, np.nan)
        bse = self.bias_se if self.bias_se is not None else np.full(P, np.nan)
        xse = self.marker_xyz_se if self.marker_xyz_se is not None else np.full((M, 3), np.nan)
        out = []
        for i, n in enumerate(self.pot_names):
            t = make_term("pot_transfer", n, [self.gain[i], self.bias[i]], stderr=[gse[i], bse[i]])
            if self.pot_units:
                units = self.pot_units[i]
                t = replace(t, parameters=tuple(replace(p, unit=u) for p, u in zip(t.parameters, units, strict=True)))
            out.append(t)
        for i, n in enumerate(self.marker_names):
            out.append(
                make_term("marker_position", n, self.marker_xyz[i], extra={"link": self.marker_links[i]}, stderr=xse[i])
            )
        rotvec = Rotation.from_matrix(np.asarray(self.mocap_R, float)).as_rotvec()
        out.append(make_term("mocap_frame", "markers", np.concatenate([np.asarray(self.mocap_T, float), rotvec])))
        return tuple(out)

    def to_dict(self) -> dict:
        """The calib.yaml mapping (layout 2, module docstring)."""
        out = {
            **{k: v for k, v in self.header.items()},
            "layout": LAYOUT,
            "method": self.method,
            "baseline": [t.to_dict() for t in self.baseline_terms()],
            "sigma": {"pots": _f(self.sigma_pots), "markers": _f(self.sigma_markers)},
            "fit": {
                "cost": _f(self.fit.cost),
                "iterations": int(self.fit.iterations),
                "converged": bool(self.fit.converged),
                "seconds": _f(self.fit.seconds),
            },
        }
        if self.correlations:
            write_correlated(out["baseline"], self.correlations)
        if self.stderr:
            out["stderr"] = dict(self.stderr)
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
        if self.rejected_poses:
            out["rejected_poses"] = {"poses": [dict(r) for r in self.rejected_poses], "reason": REJECTED_POSES_REASON}
        if self.meta:
            out["meta"] = dict(self.meta)
        if self.terms:
            out["terms"] = [t.to_dict() for t in self.terms]
        return out

    @classmethod
    def from_dict(cls, data: dict, source: str = "calib.yaml") -> Calibration:
        """A calibration from its calib.yaml mapping, layout 2 or 1 (module docstring)."""
        try:
            parts = _baseline_v2(data, source) if "baseline" in data else _baseline_v1(data)
            sigma = data.get("sigma") or {}
            fit = data.get("fit") or {}
            return cls(
                **parts,
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
                rejected_poses=tuple(dict(r) for r in ((data.get("rejected_poses") or {}).get("poses") or ())),
                sigma_unresolved=tuple(dict(u) for u in (sigma.get("unresolved") or ())),
                header={k: data[k] for k in HEADER_KEYS if k in data},
                correlations=_read_correlations(data.get("baseline")),
                stderr=dict(data.get("stderr") or {}),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise InputFileError(f"{source}: not a valid calib.yaml ({type(exc).__name__}: {exc})") from None


def _baseline_v2(data: dict, source: str) -> dict:
    """Calibration fields from layout 2's ``baseline`` terms."""
    items = data.get("baseline")
    if not isinstance(items, list):
        raise InputFileError(f"{source}: 'baseline' must be a list of terms")
    terms = [term_from_dict(d, f"{source}: baseline", "kinematics") for d in items]
    pots = [t for t in terms if t.cause == "pot_transfer"]
    markers = [t for t in terms if t.cause == "marker_position"]
    frame = next((t for t in terms if t.cause == "mocap_frame"), None)
    x = frame.values if frame is not None else np.zeros(6)
    return {
        "pot_names": tuple(t.channel for t in pots),
        "gain": np.array([t.value("gain") for t in pots]),
        "bias": np.array([t.value("bias") for t in pots]),
        "gain_se": np.array([t.parameters[0].stderr for t in pots]),
        "bias_se": np.array([t.parameters[1].stderr for t in pots]),
        "pot_units": tuple((t.parameters[0].unit, t.parameters[1].unit) for t in pots),
        "marker_names": tuple(t.channel for t in markers),
        "marker_links": tuple(str(t.extra["link"]) for t in markers),
        "marker_xyz": np.array([t.values for t in markers], float).reshape(-1, 3),
        "marker_xyz_se": np.array([t.stderrs for t in markers], float).reshape(-1, 3),
        "mocap_R": Rotation.from_rotvec(x[3:]).as_matrix(),
        "mocap_T": x[:3].copy(),
    }


def _baseline_v1(data: dict) -> dict:
    """Calibration fields from layout 1's ``pots``, ``markers`` and ``mocap`` mappings."""
    pots = data.get("pots") or {}
    markers = data.get("markers") or {}
    mocap = data.get("mocap") or {}
    names, mnames = tuple(pots), tuple(markers)
    return {
        "pot_names": names,
        "gain": np.array([float(pots[n]["gain"]) for n in names]),
        "bias": np.array([float(pots[n]["bias"]) for n in names]),
        "gain_se": np.array([_nan(pots[n].get("gain_se")) for n in names]),
        "bias_se": np.array([_nan(pots[n].get("bias_se")) for n in names]),
        "marker_names": mnames,
        "marker_links": tuple(str(markers[n]["link"]) for n in mnames),
        "marker_xyz": np.array([markers[n]["xyz"] for n in mnames], dtype=float).reshape(-1, 3),
        "marker_xyz_se": np.array(
            [[_nan(v) for v in (markers[n].get("xyz_se") or [None] * 3)] for n in mnames], dtype=float
        ).reshape(-1, 3),
        "mocap_R": np.array(mocap.get("R", np.eye(3)), dtype=float).reshape(3, 3),
        "mocap_T": np.array(mocap.get("T", [0.0, 0.0, 0.0]), dtype=float).reshape(3),
    }


def _read_correlations(items) -> tuple:
    seen, out = set(), []
    for d in items or ():
        for name, p in ((d or {}).get("parameters") or {}).items():
            for other, rho in ((p.get("correlated") or {}) if isinstance(p, dict) else {}).items():
                a = f"{d['channel']}.{name}"
                if (other, a) not in seen:
                    seen.add((a, other))
                    out.append((a, str(other), float(rho)))
    return tuple(out)


def _terms(items) -> tuple:
    if not items:
        return ()
    return tuple(term_from_dict(d, "calib.yaml terms", "kinematics") for d in items)


def _f(v) -> float | None:
    v = float(v)
    return None if not np.isfinite(v) else v


def _nan(v) -> float:
    return float("nan") if v is None else float(v)
