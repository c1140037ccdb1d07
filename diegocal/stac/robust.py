"""Robust losses for the motion-capture term of STAC, and the markers' noise level under them.

Motion capture fails in two gross ways that the Gaussian likelihood of eq. 2.21 cannot absorb:
ghost markers and reflections (a reading centimetres off for a few samples), and swapped labels
(two markers exchange names for a fraction of a second); the simulator injects both
(``marker_outliers``, ``swapped_labels``).

Why the previous Huber option failed (loss on pots and markers alike, σ the RMS residual), and
why Huber alone is not enough:

* with a robust pot term, moving a joint so that its markers fit the swapped labels costs only
  k σ_p per pot: the q-phase takes that explanation (for a leaf link, turning the leaf joint
  does it), the pots of those frames are discounted, and the pots' σ collapses (one pot per
  joint can then be fitted exactly). Measured on diego (1,000 frames, the hand marker's label
  swapped with the wrist's in 7 % of the frames, ghost readings in 1 %): both pot σ went to 0
  and gains ended 4 % off; the Gaussian fit, 16 % off;
* σ re-estimated as the RMS residual (§2.3.5) grows with the outliers, so the corner k σ moves
  out until most of them are inside it (σ_x 4-5 x the noise on the finger below), and the pots'
  σ grows with the frames whose joints followed a swapped label, which lets more joints follow;
* Huber's influence is bounded, not zero: each wrong reading still pulls by k σ, a bias of
  about (fraction x k σ) that does not shrink with the log's length. On the finger (a label swap
  with the nearest marker in 4.5 % of the frames, ghosts in 2 % of each marker's samples) Huber
  with the changes below ends 3.3 standard errors from the fit to the same log without the
  corruption at 500 frames and 4.7 at 2,000; Tukey's biweight 0.8 and 0.6.

Hence: the loss acts on the markers only (the pots stay Gaussian, so a frame's joint angles stay
with its pots while a wrong marker is discounted); every σ comes from clipped residuals
(:func:`group_sigma`), which wrong readings can drag only a bounded amount; and Tukey's
biweight, which gives wrong readings zero weight, is offered after a Huber stage, as an
MM-estimator: it is not convex (started far from the answer it can discard good readings), and
σ stays at the Huber stage's robust estimate, because a bounded marker loss with σ re-estimated
makes the likelihood unbounded: fitting every pot exactly (σ_p → 0) and writing the markers off
at a constant cost wins (a collapse seen on the test robots).

One gross error the marker loss cannot see: a frame filed with markers that are not its own (a
static pose given another pose's mocap frame) when the markers alone fix every joint of the frame
(a rigid cluster on the end effector of a 6-joint arm). Its joint angles then follow those markers
(the marker term is fitted exactly) and the disagreement lands on its pots, which inflates the
pots' σ past the point where the clipped scale recovers (10 % of such frames is its breakdown
point: c² x 10 % ≈ κ). :func:`gross_frames` finds those frames after a robust fit, from a
high-breakdown scale of the pot residuals (their median), and STAC writes their markers off
(treated as occluded) and fits again: pot residuals that far out (a χ² tail of 1e-6) are not
noise, and the markers, not the pots, are the suspects (the pots stay Gaussian, as above). Measured on a UR5
with 30 static poses, 1 to 3 of them filed with another pose's markers: σ of the encoders ended
at 0.1-0.6 rad (truth 0.005) and biases 0.1-0.2 rad off before; the wrong poses found exactly and
biases within their standard errors after (tests/stac/test_static_poses.py).

ρ acts on z = ‖r‖ / σ, the norm of a marker's 3-D residual. Tukey's constant c = 6 keeps 96.6 %
efficiency for Gaussian 3-D residuals (Monte Carlo; c = 4.685 is the 95 % point for 1-D ones).
"""

from __future__ import annotations

import numpy as np
from scipy.special import chdtr, chdtrc, chdtri  # chi-square cdf, sf, isf: no scipy.stats import

LOSSES = ("linear", "huber", "tukey")
#: residuals beyond this many σ count as this many in the robust noise level (:func:`group_sigma`)
SCALE_CLIP = 3.0
#: losses that reject gross errors outright; non-convex, so they start from a Huber fit
REDESCENDING = ("tukey",)
TUKEY_C = 6.0


def rho(z: np.ndarray, loss: str, k: float) -> np.ndarray:
    """Loss of standardised residuals z (any shape): z²/2, Huber's (corner k) or Tukey's biweight
    (c = TUKEY_C: c²/6 (1 − (1 − (z/c)²)³) inside ±c, c²/6 outside)."""
    if loss == "huber":
        a = np.abs(z)
        return np.where(a <= k, 0.5 * z * z, k * a - 0.5 * k * k)
    if loss == "tukey":
        u = np.minimum((z / TUKEY_C) ** 2, 1.0)
        return TUKEY_C**2 / 6.0 * (1.0 - (1.0 - u) ** 3)
    return 0.5 * z * z


def weight(z: np.ndarray, loss: str, k: float) -> np.ndarray:
    """IRLS weight ρ'(z)/z: 1, min(1, k/|z|) (Huber) or (1 − (z/c)²)² inside ±c, else 0 (Tukey)."""
    if loss == "huber":
        return np.minimum(1.0, k / np.maximum(np.abs(z), 1e-300))
    if loss == "tukey":
        return np.maximum(1.0 - (z / TUKEY_C) ** 2, 0.0) ** 2
    return np.ones_like(z)


def _kappa(nu: int, c: float) -> float:
    """E[min(X, c²)] / ν for X ~ χ²_ν: the share of a Gaussian variance that survives clipping
    the squared residual at c² (σ = 1); E[X 1(X ≤ a)] = ν F_ν+2(a)."""
    a = c * c
    return float((nu * chdtr(nu + 2, a) + a * chdtrc(nu, a)) / nu)


def group_sigma(obs, params, st, used: dict | None, sigma: dict) -> dict:
    """Robust dynamic variance adjustment (§2.3.5): σ per sensor type with clipped residuals.

    Huber's "proposal 2" scale, one fixed-point step from the current ``sigma``:
    σ_g² = Σ min(r², (c σ_g)²) / (κ (N_g − used_g)), c = SCALE_CLIP, κ = E[min(χ²_ν, c²)] / ν so
    that Gaussian residuals give σ back (ν = 1 per pot reading; ν = 3 per marker, r = ‖r‖ its
    3-D residual, σ per axis). A wrong reading adds at most c² σ², where it adds r² to an RMS: a
    few % of swapped or ghost readings inflate σ by a bounded ~10-20 %, not without limit. The
    q-phase's degrees of freedom ``used`` enter as in :func:`diegocal.stac.qphase.group_sigma`
    (a median would not do: readings the q-phase fits exactly, a joint seen by its pot alone,
    pull it to zero, and σ collapses), and so does its floor at the detection limit
    (:func:`floor_factor`). ``obs``: Observation; ``params``: Params; ``st``: State at
    the current q. Returns {group: σ} in V or m.
    """
    used = used or {}
    out = {}
    rp = params.gain * st.s + params.bias - obs.pots
    for g in obs.groups:
        if g == "markers":
            xb = (st.Rl @ params.xyz[:, :, None])[..., 0] + st.pl
            sq = np.sum((xb @ params.R.T + params.T - obs.markers) ** 2, axis=-1)[obs.valid]
            nu = 3
        else:
            sq, nu = rp[:, obs.kinds == g].ravel() ** 2, 1
        n = nu * sq.size
        dof = max(n - used.get(g, 0.0), MIN_REDUNDANCY * n)
        clipped = np.minimum(sq, (SCALE_CLIP * sigma[g]) ** 2).sum()
        out[g] = float(np.sqrt(clipped / (_kappa(nu, SCALE_CLIP) * dof) * floor_factor(n, dof)))
    return out


#: A frame's pots are gross when their squared standardised residuals sum past this tail
#: probability of χ²_P (P pots): 1e-6, so a Gaussian log of 25,000 frames flags none by chance.
GROSS_TAIL = 1e-6


def gross_frames(obs, params, st) -> np.ndarray:
    """(T,) bool: frames whose pots disagree with their tracked joint angles far beyond noise
    (see the module docstring).

    Each pot's residual is standardised by a high-breakdown scale, 1.4826 · median |r| over the
    frames (the MAD about zero, per pot: the q-phase absorbs a different share of each pot's
    noise); a frame is gross when the sum of its squared standardised residuals exceeds the
    1 − GROSS_TAIL quantile of χ²_P. Pots held at nominal (fitted exactly) are left out.
    ``obs``: Observation; ``params``: Params; ``st``: State.
    """
    use = ~obs.fixed_gain
    if not use.any():
        return np.zeros(obs.n_frames, dtype=bool)
    r = (params.gain * st.s + params.bias - obs.pots)[:, use]
    scale = 1.4826 * np.median(np.abs(r), axis=0)
    z = r / np.maximum(scale, 1e-12)
    return np.sum(z * z, axis=1) > chdtri(int(use.sum()), GROSS_TAIL)


#: r_g is kept above this share of N_g only to avoid dividing by zero (the floor below acts first)
MIN_REDUNDANCY = 1e-9


def floor_factor(n: float, dof: float) -> float:
    """max(1, √(2N) / r): the factor that lifts σ² = RSS / r to the group's detection limit.

    Why (Förstner's variance components, and where they break). With the q-phase's share of a
    group's readings, h = used / N, RSS / r is the estimate σ² = E[e_del²] − g² v: the mean square
    of the group's deleted residuals (its readings against q from the other sensors alone,
    e_del = e / (1 − h)) less the part of it the other sensors' own uncertainty explains (g² v).
    That difference has the standard error √(2/N) E[e_del²] (a mean of N squares), so σ² is told
    apart from zero only while σ² > √(2/N) E[e_del²], i.e. while r > √(2N). Below that, a group
    whose every reading fixes its joint (one rotary pot per joint) is not resolved by the data:
    its Förstner iterate drifts to σ = 0 whenever the other sensors' σ is pessimistic about that
    joint (pooled with a sensor that has model error, say), and at σ = 0 the likelihood of eq. 2.5
    is unbounded (the q-phase pins the joints to the pots). There σ² is held at one standard error,
    √(2/N) E[e_del²] = RSS √(2N) / r², as a boundary-avoiding prior holds a variance whose
    likelihood peaks at zero one standard error off the boundary (Chung, Rabe-Hesketh, Dorie,
    Gelman & Liu 2013, Psychometrika 78: 685-709); negative or zero variance components of
    Helmert/Förstner estimation are the same problem (Koch 1999, Parameter Estimation and
    Hypothesis Testing in Linear Models, §3.6; Teunissen & Amiri-Simkooei 2008, J. Geod. 82: 65-82).
    ``n``: readings N_g (scalars: 3 per marker); ``dof``: their redundancy r_g.
    """
    return max(1.0, float(np.sqrt(2.0 * n)) / dof)
