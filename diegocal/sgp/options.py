"""The options of :func:`diegocal.sgp.fit_dynamics` and their defaults (thesis ch. 3).

:class:`SGPOptions` is parsed once (STYLE.md: no option dicts); :data:`DEFAULT_GUARD` is the SGP
guard's setting for every robot, :func:`default_guard` its form for a regressor without viscous
friction.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import numpy as np

from diegocal.errors import OptionError
from diegocal.sgp.guard_options import Guard
from diegocal.sgp.inducing import MAX_POINTS, SPARSE_TOLERANCE
from diegocal.sgp.regressor import check_friction

KINDS = ("sgp", "pr", "gp", "prgp")
INERTIA = ("identified", "nominal")
INFERENCE = ("auto", "exact", "sparse")
INPUT_STREAMS = ("q", "qd", "qdd")

#: The guard's defaults (SGPOptions(guard=True)), one setting for every robot and experiment
#: (evidence: bench/bench_sgp_experiments.py, bench/bench_real_identification.py), except that a
#: regressor without viscous friction also gets the "extended" candidate (:func:`default_guard`):
#:
#: - the GP sees the state (q, qd) only: the rigid-body model is exactly linear in qdd, so a GP
#:   that also saw qdd could take the inertial terms away from W (GUARD_GP_INPUTS);
#: - length-scales at most MAX_LENGTHSCALE training stds: far from the data the GP reverts to 0
#:   and W alone predicts, instead of extrapolating a trend or half-reverting (the failure of the
#:   reaction wheel's pole-up and the 3-link arm's vertical figure-eight);
#: - σ_z at most twice the parametric fit's residual std: Z models deviations, not the physics
#:   (without it ML-II let σ_z grow to 120 N·m on a TX40 joint);
#: - a blocked cross-validation (five contiguous blocks in time order) chooses, output by output,
#:   between these hyperparameters, the same with the inputs whose length-scale sits at the cap
#:   released (the GP constant along them: ARD found them irrelevant, so a drifting wheel angle
#:   must not make the GP revert), and the parametric model alone (PR's σ_w and σ_v): on real,
#:   low-pass filtered torques ML-II otherwise shrinks σ_v until the GP interpolates the run and
#:   extrapolates badly (TX40, reverse split: SGP 20 N·m RMSE against PR's 3.7 before the
#:   validation). A GP is kept only if it beats PR by more than one standard error of the
#:   blocked CV (the one-standard-error rule) and by 2 % of PR's CV error (guard.MIN_GP_GAIN): a
#:   GP that buys nothing lets W drift (3-link arm at 1000 samples, vertical joint 1: one seed of
#:   five at 6.8 against PR's 0.15 without the rule; issue #14's arm at 20,000 samples, joint 2:
#:   0.25 % worse than PR over 5 seeds with the first rule alone, bench/bench_sgp_sizes.py);
#: - two stages (Guard.two_stage: PR, then a capped GP on its residual) replace that choice where
#:   they beat it by more than one standard error: the issue #14 arm's joint 3, 0.0085 -> 0.0065
#:   (bench/bench_sgp_case.py); given the ties instead, they lost the reaction wheel's pole-up
#:   pole axis (0.086, PR's, against 0.018) by keeping PR's friction-biased W;
#: - Guard.region: the two stages' GP may be cut at an onset in its joint's angle (a friction
#:   confined to part of the range), a cut judged on folds of every sample outside each block
#:   against PR on the same folds (issue #14's arm: joint 3 0.0053 -> 0.0018 at 4,000 samples;
#:   see Guard.region; `sgp-fit --no-region` turns it off); where such a cut loses to the
#:   joint GP, Guard.joint_region offers the joint GP cut at the same onset (issue #14's arm at
#:   600 samples: joint 3 0.030 -> 0.00054, ±2σ coverage 0.81 -> 0.97; `--no-joint-region`);
#: - a candidate that wins is confirmed by a nested cross-validation, each fold's hyperparameters
#:   re-learnt without the block it predicts (two stages always; the joint GPs where the
#:   cross-validation has at most 500 samples): learnt on all samples, the GP had seen the block
#:   it was scored on (real TX40, reverse split: joint 4 31 % worse than PR before, tied after);
#: - no extra start: the SGP's three starts are SGPOptions.restarts, shared by every kind.
#: W keeps §3.3.4's ML-II σ_w (a zero-mean prior learnt from the data, as for PR): a flat prior
#: left the weakly excited parameters of a single figure-eight free to drift.
MAX_LENGTHSCALE = 3.0
DEFAULT_GUARD = Guard(
    max_lengthscale=MAX_LENGTHSCALE,
    max_amplitude=2.0,
    validation_fraction=0.2,
    restarts=0,
    release_capped=True,
    two_stage=True,
    region=True,
    joint_region=True,
)
GUARD_GP_INPUTS = ("q", "qd")


def default_guard(friction: tuple) -> Guard:
    """DEFAULT_GUARD, with ``extend_capped`` when the regressor has no viscous friction column:
    then nothing in W is linear in qd, and only the SE kernel's linear limit carries a viscous
    friction beyond the training velocities (:class:`~diegocal.sgp.guard.Guard`)."""
    return DEFAULT_GUARD if "viscous" in friction else replace(DEFAULT_GUARD, extend_capped=True)


@dataclass(frozen=True)
class SGPOptions:
    """Options of :func:`fit_dynamics`, parsed once (STYLE.md: no option dicts).

    Attributes
    ----------
    kind : "sgp" | "pr" | "gp" | "prgp"
    friction : subset of ("viscous", "coulomb"); () = rigid body only
    inference : "auto" (exact up to ``exact_max`` samples, else sparse) | "exact" | "sparse"
    exact_max : int, the auto threshold in samples per joint
    n_inducing : int, the most inducing inputs per joint for sparse inference (greedy conditional
        variance until they miss at most ``sparse_tolerance`` σ_v² of prior variance per sample,
        :mod:`diegocal.sgp.inducing`; why 1,000: ``inducing.MAX_POINTS``)
    sparse_tolerance : float, see ``n_inducing``
    restarts : int, extra hyperparameter starts (the first: short length-scales; the second:
        σ_z and σ_v at the parametric residual; then random): the same starts for every kind
        with a GP, so that GP and PRGP are optimised as hard as the SGP (with one extra start,
        PRGP's GP stopped in the white-noise optimum, ℓ at its floor, on the 3-link arm at
        4,000 samples: PRGP equal to PR, 0.0107 on joint 3 against 0.0041 with it); with the
        guard's cross-validation, where the hyperparameter subset (min(N, hyper_max) samples)
        holds more than 500, the starts are screened on 250 of them and the best is refined
        (SemiParametricGP._screen)
    seed : int
    jobs : int, hyperparameter starts optimised in parallel threads
    guard : bool, turn the SGP guard on (``guard_options``, GP on ``gp_inputs``); SGP only
    guard_options : Guard or None, None = DEFAULT_GUARD
    gp_inputs : streams the GP sees; None = (q, qd, qdd), or (q, qd) when the guard is on
    hyper_max : int, hyperparameters are learnt on at most this many samples (random subset)
    fit_sigma_w : bool, learn σ_w (True) or keep §3.3.4's large prior
    maxiter : int, L-BFGS-B iterations per start
    min_noise : float, floor of σ_v relative to std(tau_j) (raise it for real, noisy torques)
    inertia : "identified" (W holds the base parameters, eq. 3.30) | "nominal" (the rigid body
        is fixed at the URDF's inertias, :func:`nominal_torque`; W holds friction and extra
        terms only: a model that can show an unmodelled payload)
    gp_joints : the joints that get a GP (None: every joint with a torque); the others are PR
        within the same model (W shared)
    """

    kind: str = "sgp"
    friction: tuple = ("viscous", "coulomb")
    inference: str = "auto"
    exact_max: int = 3000
    n_inducing: int = MAX_POINTS
    sparse_tolerance: float = SPARSE_TOLERANCE
    restarts: int = 2
    seed: int = 0
    jobs: int = 1
    guard: bool = True
    guard_options: Guard | None = None
    gp_inputs: tuple | None = None
    hyper_max: int = 1000
    fit_sigma_w: bool = True
    maxiter: int = 200
    min_noise: float = 1e-4
    inertia: str = "identified"
    gp_joints: tuple | None = None

    def __post_init__(self):
        """One OptionError line for a value no fit can take (a library caller's too: the command line
        bounds its own)."""
        if self.inertia not in INERTIA:
            raise OptionError(f"unknown inertia {self.inertia!r}; expected one of {', '.join(INERTIA)}")
        if self.kind not in KINDS:
            raise OptionError(f"unknown model kind {self.kind!r}; expected one of {', '.join(KINDS)}")
        if self.inference not in INFERENCE:
            raise OptionError(f"unknown inference {self.inference!r}; expected one of {', '.join(INFERENCE)}")
        try:
            object.__setattr__(self, "friction", check_friction(self.friction))
        except ValueError as exc:
            raise OptionError(str(exc)) from None
        if self.gp_inputs is not None:
            bad = [s for s in self.gp_inputs if s not in INPUT_STREAMS]
            if bad or not self.gp_inputs:
                raise OptionError(f"gp_inputs must be a non-empty subset of {INPUT_STREAMS}, got {self.gp_inputs}")
        for name, low in (("n_inducing", 1), ("restarts", 0), ("jobs", 1), ("hyper_max", 2), ("maxiter", 1),
                          ("exact_max", 1)):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or value < low:
                raise OptionError(f"SGP option {name} = {value!r}: expected a whole number of at least {low}")

    @property
    def guard_active(self) -> bool:
        return self.guard and self.kind == "sgp"

    def resolved_gp_inputs(self) -> tuple:
        if self.gp_inputs is not None:
            return tuple(self.gp_inputs)
        return GUARD_GP_INPUTS if self.guard_active else INPUT_STREAMS

    def to_dict(self) -> dict:
        g = self.guard_options
        return {
            "kind": self.kind,
            "friction": list(self.friction),
            "inference": self.inference,
            "exact_max": self.exact_max,
            "n_inducing": self.n_inducing,
            "sparse_tolerance": self.sparse_tolerance,
            "restarts": self.restarts,
            "seed": self.seed,
            "jobs": self.jobs,
            "guard": self.guard,
            "guard_options": None if g is None else asdict(g),
            "gp_inputs": None if self.gp_inputs is None else list(self.gp_inputs),
            "hyper_max": self.hyper_max,
            "fit_sigma_w": self.fit_sigma_w,
            "maxiter": self.maxiter,
            "min_noise": self.min_noise,
            # only when not the default: the summaries of default fits stay as they were
            **({"inertia": self.inertia} if self.inertia != "identified" else {}),
            **({"gp_joints": list(self.gp_joints)} if self.gp_joints is not None else {}),
        }

    @classmethod
    def from_dict(cls, d: dict) -> SGPOptions:
        d = dict(d)
        g = d.get("guard_options")
        if g is not None:
            g = dict(g)
            if g.get("lengthscale_prior") is not None:
                g["lengthscale_prior"] = tuple(g["lengthscale_prior"])
            d["guard_options"] = Guard(**g)
        d["friction"] = tuple(d.get("friction", ()))
        for key in ("gp_inputs", "gp_joints"):
            if d.get(key) is not None:
                d[key] = tuple(d[key])
        return cls(**d)


def with_kind(options: SGPOptions, kind: str) -> SGPOptions:
    """The same options for another model kind (for method comparisons)."""
    return replace(options, kind=kind)
