"""The STAC observation model over a log: data, parameters θ and batched evaluation (thesis §2.3).

:class:`Observation` binds a log's ``pots`` (T, P) and ``markers`` (T, M, 3) streams to the
robot's sensors, checks names and observability once, and evaluates for a batch of frames
the quantities both phases need: the pot transmission s(q) (eq. 2.18-2.20, with ∂s/∂q for
eq. 2.22) and the pose of every marker's link (eq. 2.11, with the point Jacobian of eq. 2.23).

The q-phase does not need the dense Jacobians: :meth:`Observation.linearise` returns the joint
poses (the markers' Gauss-Newton sums are formed from them, see
:meth:`diegocal.robot.batch.BatchKinematics.points_normal`) and ∂s/∂q of the linear pots only;
rotary, encoder and tendon pots have the constant ∂s/∂q = A. :class:`Sparsity` records which
joints each reading depends on, once per log.
"""

from __future__ import annotations

import copy
import difflib
import logging
from dataclasses import dataclass, replace

import numpy as np
from scipy.sparse.csgraph import connected_components

from diegocal.errors import UnknownNameError
from diegocal.io import Log
from diegocal.robot import PointSet, Robot, anchor_points
from diegocal.robot.batch import BatchKinematics
from diegocal.stac.calibration import Calibration
from diegocal.stac.observability import NO_CHANNEL, Observability
from diegocal.stac.scale import check_marker_scale, check_pot_scale

LOG = logging.getLogger(__name__)

#: sensor groups that share one noise level σ (§2.3.5): each pot kind, and the markers
MARKERS = "markers"
#: A State keeps its linearisation (:class:`State`; the joint twists and ∂s/∂q of the linear pots
#: are 2.3 of diego's 4.9 kB per frame) on at most this many frames. Above it (issue #33: a long
#: log's STAC) it holds s and the link poses only, and each step linearises its frames again: the
#: same numbers (the kinematics of a frame does not depend on its batch) for two more passes of
#: the forward kinematics per iteration.
KEEP_FRAMES = 30_000


@dataclass(frozen=True)
class Params:
    """θ = [gain, bias, R, T0, d_1:M] (thesis eq. 2.10) for the sensors present in the log.

    gain, bias : (P,) V/rad (V/m) and V; xyz : (M, 3) marker positions in link frames, m;
    R : (3, 3) base -> mocap rotation; T : (3,) translation, m.
    """

    gain: np.ndarray
    bias: np.ndarray
    xyz: np.ndarray
    R: np.ndarray
    T: np.ndarray


@dataclass(frozen=True)
class Linearisation:
    """The observation model at a batch q (B, n) for Gauss-Newton: s (B, P), Rl (B, M, 3, 3),
    pl (B, M, 3) as in :class:`State`, the joint twists ``xi`` (6, B, n)
    (:meth:`diegocal.robot.batch.BatchKinematics.twist_rows`: all the markers' sums need of the
    joint poses) and ∂s/∂q of the linear pots ``ds_lin`` (B, L, c) on the joints
    ``Sparsity.lin_cols`` (c,) (eq. 2.19-2.20; zero on the other joints)."""

    s: np.ndarray
    Rl: np.ndarray
    pl: np.ndarray
    xi: np.ndarray
    ds_lin: np.ndarray


@dataclass(frozen=True)
class Sparsity:
    """Which entries of the per-frame q-phase normal matrix JᵀWJ (n, n) can be non-zero.

    pot_flat : per pot kind with a constant ∂s/∂q (rotary, encoder, tendon): (pot indices (k,),
        flat indices U into the n x n matrix, vec(A_p A_pᵀ)[U] (k, |U|))
    lin_cols : (c,) joints that move the linear pots' anchors relative to each other
    blocks : index arrays of the joints in each independent block (connected components of the
        pattern): the normal matrix is block diagonal, each block is solved on its own
    pot_local, lin_local : where the pots' entries (per kind, then the linear pots' lin_cols x
        lin_cols) lie in the blocks: per block, (which of the entries, their flat indices in it)
    """

    pot_flat: dict
    lin_cols: np.ndarray
    blocks: tuple
    pot_local: dict
    lin_local: tuple


@dataclass(frozen=True)
class State:
    """The p-phase's input at fixed q: s (T, P), marker link poses Rl (T, M, 3, 3), pl (T, M, 3).

    The q-phase also keeps the rest of its :class:`Linearisation` at that q, the joint twists
    ``xi`` (6, T, n) and ``ds_lin`` (T, L, c) (None where not kept): the joint step and the next
    q-step linearise at the same q, so one forward kinematics per q serves them all.
    """

    s: np.ndarray
    Rl: np.ndarray
    pl: np.ndarray
    xi: np.ndarray | None = None
    ds_lin: np.ndarray | None = None

    def linearisation(self, sl: slice) -> Linearisation | None:
        """The Linearisation of frames ``sl`` when it is kept, else None."""
        if self.xi is None:
            return None
        return Linearisation(self.s[sl], self.Rl[sl], self.pl[sl], self.xi[:, sl], self.ds_lin[sl])

    def take(self, frames: np.ndarray) -> State:
        """The frames ``frames`` (an index array), linearisation included: a copy."""
        xi = None if self.xi is None else self.xi[:, frames]
        ds_lin = None if self.ds_lin is None else self.ds_lin[frames]
        return State(self.s[frames], self.Rl[frames], self.pl[frames], xi, ds_lin)

    def put(self, frames: np.ndarray, other: State) -> None:
        """Frames ``frames`` (an index array) set to ``other``'s (a State of those frames), in place."""
        self.s[frames], self.Rl[frames], self.pl[frames] = other.s, other.Rl, other.pl
        if self.xi is not None:
            self.xi[:, frames], self.ds_lin[frames] = other.xi, other.ds_lin


class Observation(Observability):
    """A log's pot and marker data bound to a robot (what it determines: :class:`Observability`).

    Parameters
    ----------
    log : Log with ``pots`` (T, P) in V and/or ``markers`` (T, M, 3) in m (NaN = occluded)
    robot : Robot
    need : which streams are required ('pots', 'markers'); a missing one raises MissingStreamError
    needed_by : command name for error messages
    """

    def __init__(self, log: Log, robot: Robot, need=("pots", "markers"), needed_by: str = "stac"):
        self.robot = robot
        self.kin = BatchKinematics(robot)
        specs = {p.name: (i, p) for i, p in enumerate(robot.sensors.pots)}
        mspecs = {m.name: (i, m) for i, m in enumerate(robot.sensors.markers)}
        T = log.n_samples
        self.ignored: dict = {}  # log channels sensors.yaml does not name, per stream (not used)
        if "pots" in need or log.has("pots"):
            st = _known(log.stream("pots", needed_by=needed_by), specs, "pots", self.ignored)
            self.pot_index = np.array([specs[n][0] for n in st.names], dtype=int)
            self.pots = st.data
        else:
            self.pot_index, self.pots = np.zeros(0, dtype=int), np.zeros((T, 0))
        if "markers" in need or log.has("markers"):
            st = _known(log.stream("markers", needed_by=needed_by), mspecs, "markers", self.ignored)
            self.marker_index = np.array([mspecs[n][0] for n in st.names], dtype=int)
            self.markers = st.data
        else:
            self.marker_index, self.markers = np.zeros(0, dtype=int), np.zeros((T, 0, 3))
        if self.ignored:
            LOG.warning(ignored_line(self.ignored, robot))
        #: markers of sensors.yaml the log's 'markers' stream lacks: kept at their nominal positions
        self.absent_markers: tuple = ()
        if log.has("markers"):
            logged = set(log.streams["markers"].names)
            self.absent_markers = tuple(n for n in robot.sensors.marker_names if n not in logged)
        if self.absent_markers:
            LOG.warning(absent_line(self.absent_markers, log.streams["markers"].names, robot, needed_by))
        if len(self.marker_index):
            check_marker_scale(self.markers, robot, [robot.sensors.markers[i] for i in self.marker_index])
        self.valid = np.isfinite(self.markers).all(axis=-1)  # (T, M)
        self.pot_specs = [robot.sensors.pots[i] for i in self.pot_index]
        self.marker_specs = [robot.sensors.markers[i] for i in self.marker_index]
        self.pot_names = tuple(p.name for p in self.pot_specs)
        self.marker_names = tuple(m.name for m in self.marker_specs)
        self.marker_links = tuple(m.link for m in self.marker_specs)
        self.kinds = np.array([p.kind for p in self.pot_specs], dtype=object)
        self.groups = tuple(dict.fromkeys(list(self.kinds))) + ((MARKERS,) if len(self.marker_index) else ())
        self.A = _linear_map(robot, self.pot_specs)  # (P, n): s = A q for rotary/encoder/tendon
        if len(self.pot_index):
            check_pot_scale(self.pots, robot, self.pot_specs, self.A)
        self.linear = np.flatnonzero(self.kinds == "linear")
        full = anchor_points(robot)
        lin_all = [i for i, p in enumerate(robot.sensors.pots) if p.kind == "linear"]
        rows = [2 * lin_all.index(self.pot_index[i]) + k for i in self.linear for k in (0, 1)]
        self.anchors = PointSet(tuple(full.links[r] for r in rows), full.xyz[rows].reshape(-1, 3))
        self.n_frames = T
        # q is projected onto the joint limits widened by a margin: a joint's zero is only known up
        # to its pot's bias error (and exactly so for gauge joints, see _gauge_biases), so the
        # tracked angles may legitimately sit past the nominal URDF limit by that much; a joint
        # continuous in the URDF has no limit (its ±π are the model's, not the robot's)
        lo, hi = robot.lower.copy(), robot.upper.copy()
        endless = np.array([n in getattr(robot, "continuous", ()) for n in robot.joint_names], dtype=bool)
        bad = ~np.isfinite(lo) | ~np.isfinite(hi) | endless
        lo[bad], hi[bad] = -np.inf, np.inf
        margin = np.where(bad, 0.0, 0.25 * (hi - lo) + np.where(self.kin.prismatic, 0.0, 0.3))
        self.lower, self.upper = lo - margin, hi + margin
        self.fixed_bias = np.zeros(len(self.pot_index), dtype=bool)
        self.fixed_gain = np.zeros(len(self.pot_index), dtype=bool)  # unobservable: gain and bias nominal
        self.unobservable: tuple = ()  # ({pot, joints, reason}, ...) set by check_observable
        self.gauges: tuple = ()  # ({joint, pot, kind, reason}, ...) set by check_observable
        self.rejected = np.zeros(0, dtype=int)  # frames whose markers a robust fit wrote off
        self.rejected_poses: tuple = ()  # static poses whose markers were written off (poses.py)
        self.sparsity = self._sparsity()

    def _sparsity(self) -> Sparsity:
        n = self.robot.n_joints
        pattern = np.eye(n, dtype=bool)
        pot_flat = {}
        for kind in dict.fromkeys(self.kinds[self.kinds != "linear"]):
            idx = np.flatnonzero(self.kinds == kind)
            outer = np.einsum("pj,pk->pjk", self.A[idx], self.A[idx]).reshape(len(idx), n * n)
            U = np.flatnonzero(np.any(outer != 0, axis=0))
            pot_flat[kind] = (idx, U, outer[:, U])
            pattern.ravel()[U] = True
        lin_cols = np.zeros(0, dtype=int)
        if len(self.linear):
            joint, _, _ = self.kin.link_info(self.anchors.links)
            moves = self.kin._anc[joint[0::2]] != self.kin._anc[joint[1::2]]  # (L, n)
            lin_cols = np.flatnonzero(moves.any(axis=0))
            for row in moves:
                pattern |= np.outer(row, row)
        if self.n_markers:
            st = self.kin._points_structure(self.marker_links)
            pattern |= st.pattern
        _, label = connected_components(pattern, directed=False)
        blocks = tuple(np.flatnonzero(label == c) for c in np.unique(label))
        pot_local = {kind: _local(U, blocks, n) for kind, (_, U, _) in pot_flat.items()}
        lin_local = _local((lin_cols[:, None] * n + lin_cols).ravel(), blocks, n)
        return Sparsity(pot_flat, lin_cols, blocks, pot_local, lin_local)

    @property
    def n_pots(self) -> int:
        return len(self.pot_index)

    @property
    def n_markers(self) -> int:
        return len(self.marker_index)

    def subset(self, frames: slice | np.ndarray) -> Observation:
        """The same sensors and robot on a subset of the frames (a slice, or an index array: a
        copy), sharing everything but the data."""
        sub = copy.copy(self)
        sub.pots, sub.markers, sub.valid = self.pots[frames], self.markers[frames], self.valid[frames]
        sub.n_frames = sub.pots.shape[0]
        return sub

    def without_markers(self, frames: np.ndarray) -> Observation:
        """The same observation with every marker of ``frames`` (T,) bool written off (as if
        occluded), recorded in ``rejected`` (frame indices, cumulative)."""
        out = copy.copy(self)
        out.markers = np.where(frames[:, None, None], np.nan, self.markers)
        out.valid = self.valid & ~frames[:, None]
        out.rejected = np.union1d(self.rejected, np.flatnonzero(frames)).astype(int)
        return out

    def without_poses(self, frames: np.ndarray) -> Observation:
        """The same observation with every marker of ``frames`` (T,) bool written off (as if
        occluded), not recorded in ``rejected``: the frames of static poses filed with another
        pose's markers (:mod:`diegocal.stac.poses`), listed as poses instead."""
        out = copy.copy(self)
        out.markers = np.where(frames[:, None, None], np.nan, self.markers)
        out.valid = self.valid & ~frames[:, None]
        return out

    def with_rejected_poses(self, records: tuple) -> Observation:
        """The same observation listing ``records`` ({pose, frame, samples, disagreement}, ...)
        as the static poses whose markers were written off."""
        out = copy.copy(self)
        out.rejected_poses = tuple(records)
        return out

    # ------------------------------------------------------------------ evaluation
    def evaluate(self, q: np.ndarray, xyz: np.ndarray | None = None):
        """Transmission and marker link poses for a batch q (B, n).

        Returns (s (B, P), ds (B, P, n) or None, Rl (B, M, 3, 3), pl (B, M, 3),
        Jx (B, M, 3, n) or None); the Jacobians are computed when ``xyz`` (M, 3), the marker
        positions they are taken at, is given.
        """
        poses = self.kin.joint_poses(q)
        s = q @ self.A.T
        ds = None if xyz is None else np.broadcast_to(self.A, (q.shape[0], *self.A.shape)).copy()
        if len(self.linear):
            if xyz is None:
                x = self.kin.points(poses, self.anchors)
            else:
                x, J = self.kin.points_jacobian(poses, self.anchors)
            d = x[:, 1::2] - x[:, 0::2]
            length = np.linalg.norm(d, axis=-1)
            s[:, self.linear] = length  # eq. 2.19-2.20
            if xyz is not None:
                ds[:, self.linear] = np.einsum("bkc,bkcn->bkn", d / length[..., None], J[:, 1::2] - J[:, 0::2])
        Rl, pl = self.kin.link_poses(poses, self.marker_links)
        Jx = None
        if xyz is not None and self.n_markers:
            _, Jx = self.kin.points_jacobian(poses, PointSet(self.marker_links, xyz))
        return s, ds, Rl, pl, Jx

    def linearise(self, q: np.ndarray) -> Linearisation:
        """s, marker link poses and joint poses at q (B, n), with ∂s/∂q of the linear pots
        (eq. 2.19-2.20: the unit vector between the anchors times their relative Jacobian)."""
        poses = self.kin.joint_poses(q)
        xi = self.kin.twist_rows(poses)
        s = q @ self.A.T
        cols = self.sparsity.lin_cols
        ds_lin = np.zeros((q.shape[0], len(self.linear), len(cols)))
        if len(self.linear):
            x = self.kin.points(poses, self.anchors)
            d = x[:, 1::2] - x[:, 0::2]
            length = np.linalg.norm(d, axis=-1)
            s[:, self.linear] = length  # eq. 2.19-2.20
            u = d / length[..., None]
            f = np.stack([-u, u], axis=2).reshape(x.shape)  # ∂|d|/∂q = uᵀ (J_1 − J_0)
            proj = self.kin.points_project(None, x, self.anchors.links, f, cols, xi=xi)
            ds_lin = proj[:, 0::2] + proj[:, 1::2]
        Rl, pl = self.kin.link_poses(poses, self.marker_links)
        return Linearisation(s, Rl, pl, xi, ds_lin)

    def poses_at(self, q: np.ndarray) -> Linearisation:
        """s and the marker link poses at q (B, n) as :meth:`evaluate` gives them, without the
        rest of the linearisation (``xi``, ``ds_lin`` None)."""
        s, _, Rl, pl, _ = self.evaluate(q)
        return Linearisation(s, Rl, pl, None, None)

    def state(self, q: np.ndarray, batch: int = 2000, keep: bool = False) -> State:
        """s(q) and link poses for every frame, in batches, each written into the State's arrays
        (no list of parts to concatenate); with ``keep`` also the rest of the linearisation
        (twists, ∂s/∂q of the linear pots: :class:`State`) for the q-phase, on at most
        :data:`KEEP_FRAMES` frames (above, the steps linearise again where they need it)."""
        T, out = q.shape[0], None
        keep = keep and T <= KEEP_FRAMES
        for i in range(0, T, batch):
            sl = slice(i, i + batch)
            lin = self.linearise(q[sl]) if keep else self.poses_at(q[sl])
            if out is None:
                arrays = (np.empty((T, *getattr(lin, k).shape[1:])) for k in ("s", "Rl", "pl"))
                kept = (np.empty((6, T, lin.xi.shape[2])), np.empty((T, *lin.ds_lin.shape[1:]))) if keep else ()
                out = State(*arrays, *kept)
            out.s[sl], out.Rl[sl], out.pl[sl] = lin.s, lin.Rl, lin.pl
            if keep:
                out.xi[:, sl], out.ds_lin[sl] = lin.xi, lin.ds_lin
        return out

    # ------------------------------------------------------------------ parameters
    def nominal(self, marker_seed: str = "origin") -> Params:
        """Seed θ: sensors.yaml gains/biases; markers at link origins (§2.7.1) or nominal; R = I."""
        xyz = np.array([m.xyz for m in self.marker_specs], float).reshape(-1, 3)
        if marker_seed == "origin":
            xyz = np.zeros_like(xyz)
        return Params(
            np.array([p.gain for p in self.pot_specs], float),
            np.array([p.bias for p in self.pot_specs], float),
            xyz,
            np.eye(3),
            np.zeros(3),
        )

    def to_calibration(self, params: Params, se: dict, sigma: dict, method: str, fit=None) -> Calibration:
        """A full-robot Calibration: sensors absent from the log keep nominal values (SE NaN)."""
        nom = Calibration.nominal(self.robot)
        gain, bias, xyz = nom.gain.copy(), nom.bias.copy(), nom.marker_xyz.copy()
        gse, bse = np.full(len(gain), np.nan), np.full(len(gain), np.nan)
        xse, xcov = np.full(xyz.shape, np.nan), np.full((2, xyz.size, xyz.size), np.nan)
        gain[self.pot_index], bias[self.pot_index], xyz[self.marker_index] = (
            params.gain,
            params.bias,
            params.xyz,
        )
        if se:
            gse[self.pot_index], bse[self.pot_index], xse[self.marker_index] = (
                se["gain"],
                se["bias"],
                se["xyz"],
            )
            if "xyz_cov" in se:
                at = (3 * np.asarray(self.marker_index)[:, None] + np.arange(3)).ravel()
                xcov[np.ix_((0, 1), at, at)] = se["xyz_cov"]
        pots_sigma = [sigma[k] for k in self.groups if k != MARKERS]
        cal = replace(
            nom,
            gain=gain,
            bias=bias,
            marker_xyz=xyz,
            gain_se=gse,
            bias_se=bse,
            marker_xyz_se=xse,
            marker_xyz_cov=xcov,
            mocap_R=params.R,
            mocap_T=params.T,
            method=method,
            sigma_pots=float(np.sqrt(np.mean(np.square(pots_sigma)))) if pots_sigma else float("nan"),
            sigma_markers=float(sigma.get(MARKERS, np.nan)),
            sigma_by_group={k: float(v) for k, v in sigma.items()},
            unobservable=self.unobservable,
            gauges=self.gauges,
            rejected=tuple(int(f) for f in self.rejected),
            rejected_poses=tuple(dict(r) for r in self.rejected_poses),
        )
        return cal if fit is None else replace(cal, fit=fit)

    def params_from(self, cal: Calibration) -> Params:
        """θ for this log's sensors from a calibration (pots/markers looked up by name)."""
        pi = {n: i for i, n in enumerate(cal.pot_names)}
        mi = {n: i for i, n in enumerate(cal.marker_names)}
        for names, index, what in ((self.pot_names, pi, "pot"), (self.marker_names, mi, "marker")):
            missing = [n for n in names if n not in index]
            if missing:
                raise UnknownNameError(f"calibration has no {what} {missing[0]!r} (the log has it)")
        return Params(
            np.array([cal.gain[pi[n]] for n in self.pot_names]),
            np.array([cal.bias[pi[n]] for n in self.pot_names]),
            np.array([cal.marker_xyz[mi[n]] for n in self.marker_names]).reshape(-1, 3),
            np.asarray(cal.mocap_R, float),
            np.asarray(cal.mocap_T, float),
        )


def _local(U: np.ndarray, blocks: tuple, n: int) -> tuple:
    """Flat indices U into an n x n matrix split over its diagonal blocks: per block, (the
    positions in U of its entries, their flat indices in the block); an entry outside every
    block is none of them (the pattern puts every non-zero entry in one)."""
    out = []
    for ix in blocks:
        pos = np.full(n, -1)
        pos[ix] = np.arange(len(ix))
        r, c = pos[U // n], pos[U % n]
        sel = np.flatnonzero((r >= 0) & (c >= 0))
        out.append((sel, r[sel] * len(ix) + c[sel]))
    return tuple(out)


def _known(stream, specs, what: str, ignored: dict):
    """The stream's channels sensors.yaml names (in log order); the others go to ``ignored``."""
    unknown = [n for n in stream.names if n not in specs]
    if not unknown:
        return stream
    ignored[what] = unknown
    return stream.select([n for n in stream.names if n in specs])


def known_channels(log: Log, robot: Robot) -> Log:
    """``log`` with only the pots and markers sensors.yaml names, the others said in one warning
    line (:func:`ignored_line`): what an Observation of it would bind."""
    ignored: dict = {}
    for what, specs in (("pots", robot.sensors.pot_names), ("markers", robot.sensors.marker_names)):
        if log.has(what):
            log = log.with_streams(**{what: _known(log.stream(what), set(specs), what, ignored)})
    if ignored:
        LOG.warning(ignored_line(ignored, robot))
    return log


def ignored_line(ignored: dict, robot) -> str:
    """One line naming the log channels that sensors.yaml does not name (with close matches)."""
    parts = []
    for what, names in ignored.items():
        specs = robot.sensors.pot_names if what == "pots" else robot.sensors.marker_names
        shown = ", ".join(n + _close(n, specs) for n in names[:6]) + (", ..." if len(names) > 6 else "")
        parts.append(f"{len(names)} log {what} ({shown})")
    return f"ignored {' and '.join(parts)}: not in {robot.name}'s sensors.yaml"


def absent_line(absent, channels, robot, needed_by: str = "stac") -> str:
    """One warning line: the markers of sensors.yaml the log lacks (close matches in ``channels``); a fit
    keeps them nominal, a prediction (``needed_by``) its calibration's, unscored."""
    shown = ", ".join(n + _close(n, channels) for n in absent[:6]) + (", ..." if len(absent) > 6 else "")
    if needed_by == "predict":
        return f"{len(absent)} marker(s) of {robot.name}'s sensors.yaml not in this log: {shown}; not scored"
    return (
        f"{len(absent)} marker(s) of {robot.name}'s sensors.yaml not calibrated: {shown} ({NO_CHANNEL}); "
        "their positions keep their nominal values (standard error null)"
    )


def _close(name: str, choices) -> str:
    match = difflib.get_close_matches(name, list(choices), n=1, cutoff=0.75)
    return f" — did you mean {match[0]!r}?" if match else ""


def _linear_map(robot: Robot, specs) -> np.ndarray:
    A = np.zeros((len(specs), robot.n_joints))
    for i, p in enumerate(specs):
        if p.kind in ("rotary", "encoder"):
            A[i, robot.joint_index(p.joint)] = 1.0
        elif p.kind == "tendon":
            for joint, arm in p.moment_arms.items():
                A[i, robot.joint_index(joint)] = arm
    return A
