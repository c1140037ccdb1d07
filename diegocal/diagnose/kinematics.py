"""The kinematics adapter of the diagnosis engine: STAC's pots and markers (thesis ch. 2).

Baseline: STAC (thesis §2.2-2.3) on the training blocks' frames, then the q-phase (eq. 2.21) on
every frame with θ fixed, so that q is tracked everywhere. Channels: each pot (V) and each marker
((T, 3), m); residual = reading − prediction at the tracked q. A model with extra terms is the
baseline fitted to the log mapped into its terms (:func:`diegocal.stac.terms.apply_terms`).

Candidates (:mod:`diegocal.stac.terms`), linearised at the current fit: the column
∂(prediction)/∂θ_term over every pot and marker row of a frame, projected out of that frame's q
directions and out of the calibration STAC fits for the whole log
(:mod:`diegocal.diagnose.kinematics_lin`), so that no term is "explained" by moving q or by
re-fitting what the baseline already fits: a link offset by the markers' positions, the mocap
frame and the pots' gains (a longer knuckle is a larger lever about the abduction axis, which
the abduction pot's gain absorbs in part); a pot term by the gains and biases of the pots that
read its joints. A clock shift is a family over shifts (:data:`TIME_SHIFTS`), each variant the
predicted markers' change over its shift: a shift of many samples is far from its linearisation
at zero. A marker slip re-fits its marker's position (``refit``); its change time is a family:
in each run of training frames the time a change-point scan fits best, and the middle, first
and last frame of each gap between runs (:func:`slip_samples`). Its region is open, ``time`` from the change on: a
marker that moved stays moved, in this log and in any later one on the same clock.
Data faults (``faults``): ``swapped_labels`` (two markers whose readings fit each other's
prediction over runs of frames; where one of them is not seen, the other's reading alone)
and ``marker_outliers`` (readings far off their neighbours' trend, by a threshold with a
family-wise false-alarm rate, save those a pot's spike carried: :mod:`.kinematics_outliers`;
on a static-pose log, whose neighbours are other poses, the poses whose markers are not their
own: :func:`.geometry.foreign_poses`, and the fits leave the writing-off to that fault instead
of doing it themselves).

Held-out score: RMSE per channel of reading − prediction on the held-out frames, q tracked from
every sensor with θ fixed. The extended model is a calib.yaml (kind ``calibration``) whose
``terms`` ``predict`` honours.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path

import numpy as np
from scipy.stats import chi2

from diegocal.diagnose import geometry
from diegocal.diagnose.kinematics_clock import clock_fault, far_clock
from diegocal.diagnose.kinematics_curves import curve_candidates, pot_block
from diegocal.diagnose.kinematics_families import FamilyRanks
from diegocal.diagnose.kinematics_lin import Linearised, step_errors
from diegocal.diagnose.kinematics_outliers import outlier_flags, pot_carried, retracked
from diegocal.diagnose.kinematics_refine import REFINED, plausible_start, refined
from diegocal.diagnose.kinematics_slip import FromSample, SlipScan, slip_value
from diegocal.diagnose.kinematics_sweep import Columns, Sweep
from diegocal.diagnose.spill import on_disk
from diegocal.diagnose.types import Candidate, Fault, Residuals
from diegocal.evaluate import Score, score
from diegocal.io import Log, save_yaml
from diegocal.lstsq import TallLstsq
from diegocal.stac.calibration import READING_UNITS, Calibration
from diegocal.stac.model import known_channels
from diegocal.stac.predict import OTHERS, predict
from diegocal.stac.result import StacOptions, WarmStart
from diegocal.stac.stac import calibrate
from diegocal.stac.static import static_poses
from diegocal.stac.terms import POT_CAUSES, SLIP, Applied, apply_terms, pot_columns, pot_extra, relabelled, shift_clock
from diegocal.terms import Region, Term, make_term

#: Dead-band widths tried for a backlash (a family), in multiples of BAND_SIGMAS pot σ.
BAND_SCALES = (0.33, 0.6, 1.0, 1.7, 2.8, 5.0)
#: Clock shifts tried for a time offset (a family, both signs), s: a shift of several samples
#: moves the markers by far more than their linearisation at zero predicts (a PID-driven joint
#: turns through a radian in a quarter second), so each variant is the change of the predicted
#: markers over its own shift.
TIME_SHIFTS = (0.01, 0.02, 0.035, 0.06, 0.1, 0.15, 0.22, 0.33, 0.5)


@dataclass
class KinFit:
    """A fitted kinematic model: extra terms, the calibration (in the mapped terms of ``applied``),
    tracked q (T, n), predictions pots (T, P) and markers (T, M', 3) in the mapped terms."""

    terms: tuple
    cal: Calibration
    applied: Applied
    q: np.ndarray
    pots: np.ndarray
    markers: np.ndarray
    train: np.ndarray = field(repr=False)
    deleted: tuple | None = field(default=None, repr=False)  # (pots, markers) residuals of --from others, on disk
    unconverged: tuple = ()  # what in this fit stopped at a cap before its tolerance, in words


class KinematicsAdapter:
    """The engine's adapter for a robot's pots and markers (module docstring)."""

    domain = "kinematics"
    unit_name = ""
    #: The engine's channel weights and written-off readings (set by it): only the variant of each
    #: family that its selection would test is written (:class:`FamilyRanks`); None: every variant.
    selection_weights = None
    selection_exclude = None
    progress = None  # callable(str), set by the engine: how far a long log's sweeps are

    def __init__(self, log: Log, robot, options: StacOptions | None = None):
        self.log, self.robot = known_channels(log.without_truth(), robot), robot  # others ignored, said
        self.options = options or StacOptions()
        st = self.log.stream("pots")
        self.pot_names = tuple(st.names)
        self.raw_pots = np.asarray(st.data, float)
        self.marker_names = tuple(self.log.stream("markers").names)
        self.time = np.asarray(self.log.time, float)
        self._baseline: KinFit | None = None
        self._sweep: Sweep | None = None  # the round's: its blocks' linearisations, read again by spill_candidates
        self.joint_of_pot = {p.name: p.joint for p in robot.sensors.pots if p.kind in ("rotary", "encoder")}
        self.poses = static_poses(self.log)  # (T,) int on a static-pose log: link geometry is a candidate
        if self.poses is not None:  # foreign poses are a fault the diagnosis writes off, not the fits
            self.options = replace(self.options, check_poses=False)

    # ------------------------------------------------------------------ fit
    def fit(self, terms, train) -> KinFit:
        train = np.asarray(train, bool)
        self.release()  # the round is over
        terms = tuple(self._own(t, train) for t in terms)
        base = self._baseline if self._baseline is not None and np.array_equal(self._baseline.train, train) else None
        base = None if far_clock(terms, TIME_SHIFTS[-1]) else base  # the baseline's markers fit the other clock
        fitted = self.fit_once(terms, train, base)
        if not terms:
            self._baseline = fitted
        if any(t.cause in REFINED for t in terms):
            fitted = refined(self, fitted, train, TIME_SHIFTS[-1])
        return fitted

    @staticmethod
    def unconverged(fitted: KinFit) -> tuple:
        return fitted.unconverged

    def _own(self, term: Term, train) -> Term:
        """A term as this adapter builds it (engine copies keep ``extra``; YAML ones too)."""
        if term.cause in POT_CAUSES and not term.extra:
            j = self.pot_names.index(term.channel)
            return replace(term, extra=pot_extra(term.cause, self.raw_pots[train, j], 0.005))
        if term.cause == "time_offset" and "span" in term.extra:  # a family variant's column only
            return replace(term, extra={k: v for k, v in term.extra.items() if k != "span"})
        return plausible_start(term) if term.cause == "link_offset" else term

    def fit_once(self, terms, train, previous=None, options=None, warm: bool = False, track=None) -> KinFit:
        """STAC on the training frames of the log mapped into ``terms``, then q tracked on every
        frame (from ``previous``'s q: the pot terms act on its model readings).

        An extended model's STAC starts its markers where ``previous`` put them (``marker_seed``
        'nominal' on a robot carrying those positions; a slipped marker's second one at the first's
        plus the slip): from the link origins it can end in a degenerate optimum (a pot type's σ
        collapsed to 0, tendons 3 x their noise) once a marker is split. ``options``: STAC's, default
        the adapter's. ``warm``: STAC starts at ``previous``'s calibration and q (the same terms, a
        step apart: two iterations instead of twenty on diego). ``track``: the frames q is tracked
        on (:meth:`_track`; None: all)."""
        robot, options = self.robot, options or self.options
        if previous is not None:
            robot, options = _seeded(robot, previous.cal), replace(options, marker_seed="nominal")
        chain = tuple(t for t in terms if geometry.is_chain(t))
        terms = tuple(t for t in terms if not geometry.is_chain(t))
        model_pots = None if previous is None else previous.pots
        applied = apply_terms(terms, self.log, robot, model_pots)
        idx = np.flatnonzero(train)
        sub = applied.log.take(idx)
        if chain:  # stac --geometry on the training poses, its geometry then composed into the robot
            cal, chain = geometry.fit_chain(sub, applied.robot, options, self.poses[idx])
            applied = apply_terms(terms + geometry.per_joint(chain), self.log, robot, model_pots)
        else:
            start = WarmStart(previous.cal, previous.q[idx]) if warm and previous is not None else None
            cal = calibrate(sub, applied.robot, options, start).calibration
        terms = tuple(slip_value(t, cal, self.robot) for t in terms) + ((chain,) if chain else ())
        q, pots, markers = self._track(applied, cal, previous, track)
        late = () if cal.fit.converged else (f"STAC stopped after {cal.fit.iterations} iteration(s), unconverged",)
        return KinFit(terms, cal, applied, q, pots, markers, train.copy(), unconverged=late)

    def _track(self, applied: Applied, cal: Calibration, previous: KinFit | None, frames=None) -> tuple:
        """q (T, n), pots (T, P) and markers (T, M', 3) of the model ``applied`` with ``cal``,
        tracked from ``previous``'s q on the frames ``frames`` (T,) bool (None: every frame; the
        others keep ``previous``'s, which must be of the same mapped terms)."""
        both = ("pots", "markers")
        if frames is None or previous is None:
            q0 = None if previous is None else previous.q
            pred = predict(applied.log, applied.robot, cal, both, both, self.options, q_init=q0)
            return pred.q, pred.pots, pred.markers
        idx = np.flatnonzero(frames)
        pred = predict(applied.log.take(idx), applied.robot, cal, both, both, self.options, q_init=previous.q[idx])
        q, pots, markers = previous.q.copy(), previous.pots.copy(), previous.markers.copy()
        q[idx], pots[idx], markers[idx] = pred.q, pred.pots, pred.markers
        return q, pots, markers

    def refine_step(self, fitted: KinFit) -> tuple:
        """One Gauss-Newton step on every continuous term at once (their projected columns,
        weighted least squares on the training frames), its normal equations a block of frames at a
        time (:meth:`Sweep.design`; the least squares by :class:`~diegocal.lstsq.TallLstsq`, each
        frame's share of AᵀWA and AᵀWr kept for the standard errors: (T, k, k), k the terms'
        parameters)."""
        sweep = Sweep(fitted, self, train_only=True)
        cols, blocks, at = [], [], 0
        for i, t in enumerate(fitted.terms):
            c = self._term_columns(sweep, fitted, t)
            if c is None:
                continue
            k = int(np.size(t.values))
            blocks.append((i, at, k))
            at += k
            cols.append(c)
        if not cols:
            return fitted.terms
        tall = TallLstsq(at)
        AWA, AWr = np.zeros((sweep.T, at, at)), np.zeros((sweep.T, at))

        def normal(lin, A):  # A (B, R, k) on a block
            r = lin.residual_rows()
            rows = lin.train[:, None] & np.isfinite(r) & np.isfinite(A).all(-1) & (lin.w > 0)
            w = np.sqrt(lin.w)[rows]
            tall.add(A[rows] * w[:, None], r[rows] * w)
            ww, Ar = np.where(rows, lin.w, 0.0), np.where(rows[..., None], A, 0.0)
            AWA[lin.frames] = np.einsum("trk,tr,trl->tkl", Ar, ww, Ar)
            AWr[lin.frames] = np.einsum("trk,tr->tk", Ar, ww * np.where(rows, r, 0.0))

        sweep.design(cols, normal)
        coef, _ = tall.solve()
        se = step_errors(AWA.sum(axis=0), AWr - AWA @ coef)  # scores: Aᵀ W (r − A coef) per frame
        out = list(fitted.terms)
        for i, a0, k in blocks:
            t = out[i]
            out[i] = t.with_values(t.values + coef[a0 : a0 + k], se[a0 : a0 + k])
        return tuple(out)

    # ------------------------------------------------------------------ residuals
    def merged(self, applied: Applied, x: np.ndarray) -> np.ndarray:
        """Mapped markers (T, M', ...) -> the log's markers (T, M, ...), slips merged back."""
        names = list(applied.log.stream("markers").names)
        out = x[:, [names.index(n) for n in self.marker_names]].copy()
        for name, (orig, k) in applied.slips.items():
            out[k:, self.marker_names.index(orig)] = x[k:, names.index(name)]
        return out

    def marker_arrays(self, fitted: KinFit):
        """(readings, predictions), each (T, M, 3) on the log's markers: a prediction on every
        frame, seen or not (a reading is NaN where the cameras lost it)."""
        a = fitted.applied
        return self.merged(a, np.asarray(a.log.stream("markers").data, float)), self.merged(a, fitted.markers)

    def residuals(self, fitted: KinFit) -> Residuals:
        rp = np.asarray(fitted.applied.log.stream("pots").data, float) - fitted.pots
        xm, pred = self.marker_arrays(fitted)
        rm = xm - pred
        channels = {n: rp[:, i] for i, n in enumerate(self.pot_names)}
        channels.update({n: rm[:, i] for i, n in enumerate(self.marker_names)})
        units = {p.name: READING_UNITS[p.kind] for p in self.robot.sensors.pots if p.name in self.pot_names}
        units.update({n: "m" for n in self.marker_names})
        variables = {"time": self.time}
        variables.update({f"p.{n}": self.raw_pots[:, i] for i, n in enumerate(self.pot_names)})
        joints = self.robot.joint_names
        variables.update({f"q.{j}": fitted.q[:, i] for i, j in enumerate(joints)})
        chv = {}
        for n in self.pot_names:
            j = self.joint_of_pot.get(n)
            chv[n] = (f"p.{n}",) + ((f"q.{j}",) if j else ())
        for m in self.robot.sensors.markers:
            if m.name in self.marker_names:
                chv[m.name] = ("time",)
        return Residuals(channels, units, variables, chv)

    # ------------------------------------------------------------------ candidates
    def _term_columns(self, sweep: Sweep, fitted: KinFit, term: Term) -> Columns | None:
        """How a :class:`Sweep` makes a term's columns on the mapped rows, projected out of every
        frame's q and of the calibration's span (:meth:`Linearised.beyond_calibration`; a pot term's:
        of its pots' gains and biases); None for a term without continuous columns."""
        if term.cause in POT_CAUSES:
            j = self.pot_names.index(term.channel)
            f = pot_columns(term, self.raw_pots[:, j], fitted.pots[:, j])  # (T, k): a dead band runs along the log
            return Columns(partial(pot_block, j=j, f=sweep.on_disk(f)), span=j, projected=True)  # read per block
        if term.cause == "link_offset":
            return Columns(partial(Linearised.link_offset_basis, joint=term.channel))
        if term.cause == "time_offset":
            return Columns(partial(_clock_block, markers=fitted.markers, time=self.time, span=term.extra.get("span")))
        return None

    def candidates(self, fitted: KinFit, residuals: Residuals, train) -> list[Candidate]:
        """The round's candidates (module docstring), their columns made in one :class:`Sweep`."""
        train = np.asarray(train, bool)
        sweep = self._sweep = Sweep(fitted, self)
        have = {(t.cause, t.channel) for t in fitted.terms}
        sigma_p = sweep.sigma_p
        made = []  # (term, family, Columns) in the order offered, or a candidate made whole

        def offer(term, family=""):  # a term the calibration takes up entirely is no candidate
            made.append((term, family, self._term_columns(sweep, fitted, term)))

        for j, name in enumerate(self.pot_names):
            for cause in POT_CAUSES:
                if (cause, name) in have:
                    continue
                extra = pot_extra(cause, self.raw_pots[train, j], float(sigma_p[j]))
                bands = BAND_SCALES if cause == "backlash" else (1.0,)
                for b in bands:  # backlash: a family over dead-band widths
                    ex = dict(extra, width=extra["width"] * b) if cause == "backlash" else extra
                    term = make_term(cause, name, extra=ex)
                    fam = f"backlash:{name}" if cause == "backlash" else ""
                    offer(term, fam)
        # static poses: the chain's geometry, which holds every joint's offset, instead of each offset
        geometric = any(geometry.is_chain(t) for t in fitted.terms)
        chain = geometry.candidate(self, fitted, train) if self.poses is not None and not geometric else None
        if chain is not None:
            made.append(chain)
        for joint in sweep.observed_joints():
            if ("link_offset", joint) not in have and not geometric and chain is None:
                offer(make_term("link_offset", joint))
        if ("time_offset", "markers") not in have:
            for span in (0.0, *TIME_SHIFTS, *(-t for t in TIME_SHIFTS)):
                term = make_term("time_offset", "markers", extra={"span": span} if span else None)
                offer(term, "time_offset:markers")
        slips = [n for n in self.marker_names if ("marker_slip", n) not in have]
        cols = [m[2] for m in made if isinstance(m, tuple)]
        first = len(cols)
        cols += [Columns(partial(Linearised.marker_basis, m=sweep.mapped_index(n)), span=None) for n in slips]
        scan = SlipScan(train, slips, first)
        families = None
        if self.selection_weights is not None:
            names = [m[1] for m in made if isinstance(m, tuple)] + [""] * len(slips)
            families = FamilyRanks(sweep, names, residuals, self.selection_weights, self.selection_exclude, train)
        chans = iter(sweep.channels(cols, see=scan.add, families=families))
        out = []
        for m in made:
            if not isinstance(m, tuple):
                out.append(m)
                continue
            c = next(chans)
            if c is not None:
                out.append(Candidate(m[0], c, family=m[1]))
        for i, name in enumerate(slips):
            out += self._slip_family(name, next(chans) or {}, scan.samples(i, train))
        return out

    def spill_candidates(self, fitted: KinFit, train, term: Term, channels) -> list[Candidate]:
        """For a pot term, a link offset or a marker's slip, the flexible models of the pots near it
        and among ``channels`` (:mod:`~diegocal.diagnose.kinematics_curves`): does a pot explain more?"""
        if term.cause not in (*POT_CAUSES, "link_offset", "marker_slip"):
            return []
        sweep = self._sweep if self._sweep is not None and self._sweep.fitted is fitted else Sweep(fitted, self)
        return curve_candidates(sweep, fitted, np.asarray(train, bool), term, channels)

    def release(self) -> None:
        """Let the round's sweep go (its blocks' file): the engine's rounds are over."""
        self._sweep = None

    def _slip_family(self, name: str, refit: dict, samples: list[int]) -> list[Candidate]:
        """A marker's slip candidates: a family over change times (:func:`slip_samples`: the best
        in each run of training frames by a change-point scan of the marker's projected position
        columns, and the first, middle and last frame of each gap between runs: the training
        frames cannot place a slip inside a gap, so those tie and the validation frames choose),
        each its re-fit columns ``refit`` from its change on."""
        out = []
        for k in samples:
            cols_k = {c: FromSample(v, k) for c, v in refit.items()}
            region = Region("time", float(self.time[k]), float("inf"))  # moved for good: open
            term = make_term("marker_slip", name, region=region)
            out.append(Candidate(term, cols_k, family=f"marker_slip:{name}", refit=refit))
        return out

    # ------------------------------------------------------------------ faults
    def faults(self, fitted: KinFit, residuals: Residuals) -> list[Fault]:
        """A clock seconds off (:func:`clock_fault`), swapped labels, marker outliers, on the baseline's residuals."""
        xm, pred = self.marker_arrays(fitted)
        rm = xm - pred
        T, M = rm.shape[:2]
        n_tests = max(T * M, 1)
        sig = float(fitted.cal.sigma_markers)
        # a reading is off when its residual's squared norm passes chi²_3 at alpha / readings
        thr2 = chi2.isf(0.01 / n_tests, 3) * sig**2
        own = np.einsum("tmi,tmi->tm", rm, rm)
        out = [f for f in (clock_fault(self, fitted, TIME_SHIFTS[-1]),) if f is not None]  # moves every marker
        swapped = np.zeros((T, M), bool)
        seen = np.isfinite(own)
        off = seen & (own > thr2)
        for m in range(M):
            for k in range(m + 1, M):
                # each reading of the pair that is seen is off its own marker: a swap needs one
                bad = (off[:, m] | ~seen[:, m]) & (off[:, k] | ~seen[:, k]) & (off[:, m] | off[:, k])
                if bad.sum() < 3:
                    continue
                with np.errstate(invalid="ignore"):
                    dm = np.sum((xm[:, m] - pred[:, k]) ** 2, -1)
                    dk = np.sum((xm[:, k] - pred[:, m]) ** 2, -1)
                # ... and on the other's prediction (a label moved onto a marker the cameras lost)
                swap = bad & ((dm < thr2) | ~seen[:, m]) & ((dk < thr2) | ~seen[:, k])
                if swap.sum() >= 3:
                    frames = np.flatnonzero(swap)
                    a, b = self.marker_names[m], self.marker_names[k]
                    term = make_term("swapped_labels", a, extra={"partner": b, "frames": frames.tolist()})
                    mask = np.zeros(T, bool)
                    mask[frames] = True
                    ev = {"frames": int(swap.sum()), "partner": b, "threshold_m": float(np.sqrt(thr2))}
                    out.append(Fault(term, {a: mask, b: mask}, exclude=False, evidence=ev))
                    swapped[frames, m] = swapped[frames, k] = True
        if self.poses is not None:  # a static-pose log: its poses judged, not a trend between them
            return out + [f for f in (geometry.foreign_poses(self, fitted, swapped),) if f is not None]
        flag, z, scale = outlier_flags(rm, n_tests, swapped)
        flag, pots = pot_carried(self, fitted.applied, fitted.cal, (fitted.q, fitted.pots), flag, scale, z)
        if pots:  # their readings raised the pots' σ: the markers' residuals judged at a q that weighs them less
            bad = np.zeros(T, bool)
            bad[[k for f in pots.values() for k in f]] = True
            cal, tracked, rm = retracked(self, fitted, bad)
            flag, z, scale = outlier_flags(rm, n_tests, swapped)
            flag, pots = pot_carried(self, fitted.applied, cal, tracked, flag, scale, z)
        say = self.progress or (lambda _: None)
        for name, frames in pots.items():  # no pot fault in the vocabulary: said, left in
            say(f"{name}: {len(frames)} reading(s) far off the q the markers fit: no marker outliers there")
        if flag.sum() >= 1:
            frames = {self.marker_names[m]: np.flatnonzero(flag[:, m]).tolist() for m in range(M) if flag[:, m].any()}
            ch = next(iter(frames)) if len(frames) == 1 else "markers"
            term = make_term("marker_outliers", ch, extra={"frames": frames})
            readings = {n: flag[:, self.marker_names.index(n)] for n in frames}
            ev = {"readings": int(flag.sum()), "threshold_sigma": z}
            out.append(Fault(term, readings, exclude=True, evidence=ev))
        return out

    # ------------------------------------------------------------------ scores and output
    def score(self, fitted: KinFit, mask, exclude: dict | None = None) -> Score:
        """RMSE per channel on ``mask`` of each reading against its prediction by the frame's other
        sensors, with the model as saved: ``diegocal predict MODEL LOG --from others`` (q tracked
        from every sensor, then each reading left out, :mod:`diegocal.stac.loo`). A reading's own
        residual would reward a model for following it: a rotary pot that largely fixes its
        joint's q has a small residual whatever its transfer curve, and a term that corrects it
        moves q back onto the other sensors, so its own residual grows while every other sensor's
        shrinks."""
        rp, rm = self.deleted(fitted)  # read back afresh: written into below
        for c, ex in (exclude or {}).items():
            ex = np.asarray(ex, bool)
            if c in self.pot_names:
                rp[ex, self.pot_names.index(c)] = np.nan
            elif c in self.marker_names:
                rm[ex, self.marker_names.index(c)] = np.nan
        zero_p = np.zeros_like(rp)
        sp = score(np.where(np.isfinite(rp), rp, np.nan), zero_p, self.pot_names, unit="V", mask=mask)
        sm = score(rm, np.zeros_like(rm), self.marker_names, unit="m", mask=mask)
        cov = None
        return Score(
            sp.channels + sm.channels,
            np.concatenate([sp.rmse, sm.rmse]),
            np.concatenate([sp.nmse, sm.nmse]),
            np.concatenate([sp.mae, sm.mae]),
            cov,
            np.concatenate([sp.n_samples, sm.n_samples]),
            "V (pots), m (markers)",
        )

    def deleted(self, fitted: KinFit) -> tuple:
        """(pots (T, P) V, markers (T, M, 3) m): each reading minus its prediction by the frame's
        other sensors with the model as saved (:meth:`score`), computed once per fit (kept in a
        temporary file, :func:`~diegocal.diagnose.spill.on_disk`; each call reads it afresh). Its q is
        tracked from the fit's own (the same model and sensors: the same minimum to the tracking's
        tolerance) rather than from the pots' inversion, which takes many more steps."""
        if fitted.deleted is None:
            cal, both = self.calibration(fitted), ("pots", "markers")
            pred = predict(self.log, self.robot, cal, (OTHERS,), both, self.options, q_init=fitted.q)
            pots = pred.pots[:, [pred.pot_names.index(n) for n in self.pot_names]]
            markers = pred.markers[:, [pred.marker_names.index(n) for n in self.marker_names]]
            readings = relabelled(self.log.stream("markers").data, self.marker_names, fitted.terms)  # labels as read
            fitted.deleted = on_disk(self.raw_pots - pots, readings - markers)  # not held: 0.9 kB a frame per fit
        return tuple(np.asarray(x) for x in fitted.deleted)

    def terms(self, fitted: KinFit):
        return tuple(fitted.terms)

    def describe(self, fitted: KinFit) -> str:
        return "+".join(["stac (eq. 2.11-2.20)", *[t.cause for t in fitted.terms]])

    def calibration(self, fitted: KinFit) -> Calibration:
        """The extended calibration in the log's own markers (slip markers folded into terms)."""
        cal = fitted.cal
        keep = [i for i, n in enumerate(cal.marker_names) if not n.endswith(SLIP)]
        se = cal.marker_xyz_se[keep] if cal.marker_xyz_se is not None else None
        return replace(
            cal,
            marker_names=tuple(cal.marker_names[i] for i in keep),
            marker_links=tuple(cal.marker_links[i] for i in keep),
            marker_xyz=cal.marker_xyz[keep],
            marker_xyz_se=se,
            marker_xyz_cov=None,  # of the split markers
            terms=geometry.expand(fitted.terms),
        )

    def save(self, fitted: KinFit, path, header: dict) -> Path:
        path = Path(path)
        data = self.calibration(fitted).to_dict()
        save_yaml({**header, "kind": "calibration", **data}, path)
        return path


def _seeded(robot, cal: Calibration):
    """``robot`` with its markers' nominal positions at a calibration's (those it names); the rest
    of the robot (locked and continuous joints, source) as it is."""
    xyz = dict(zip(cal.marker_names, cal.marker_xyz, strict=True))
    markers = tuple(replace(m, xyz=np.array(xyz.get(m.name, m.xyz), float)) for m in robot.sensors.markers)
    return robot.with_model(robot.model, replace(robot.sensors, markers=markers))


def _clock_block(lin, markers: np.ndarray, time: np.ndarray, span) -> np.ndarray:
    """A clock shift's column on a block: the predicted markers' (T, M', 3) change over the shift
    ``span`` (s) per second of it, or their rate (no span), on the block's frames, from the frames
    around it that it reads (the same numbers as on the whole log)."""
    sl, T = lin.frames, time.size
    if span:  # shift_clock reads the two frames around time + span
        lo = max(min(sl.start, int(np.searchsorted(time, time[sl.start] + span)) - 2), 0)
        hi = min(max(sl.stop, int(np.searchsorted(time, time[sl.stop - 1] + span)) + 2), T)
        xd = (shift_clock(markers[lo:hi], time[lo:hi], -span)[sl.start - lo : sl.stop - lo] - markers[sl]) / span
    else:
        lo, hi = max(sl.start - 1, 0), min(sl.stop + 1, T)
        xd = np.gradient(markers[lo:hi], time[lo:hi], axis=0)[sl.start - lo : sl.stop - lo]
    v = np.zeros((lin.T, lin.R, 1))
    v[:, lin.P :, 0] = xd.reshape(lin.T, -1)
    return np.nan_to_num(v)


def adapters(log, robot, options) -> list[KinematicsAdapter]:
    """One adapter: the robot's pots and markers together (they share q); ``options.jobs`` threads
    share its per-frame work (one unit: no processes to spread)."""
    return [KinematicsAdapter(log, robot, StacOptions(jobs=max(1, options.jobs)))]
