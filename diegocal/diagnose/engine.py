"""The diagnosis engine: show what a model gets wrong, name the cause, extend, measure the gain.

Domain-free. A domain supplies an :class:`Adapter` (``diagnose/dynamics.py``,
``diagnose/kinematics.py``, ``diagnose/pneumatics.py``) that fits its model with any extra terms,
gives the residuals per channel, proposes candidate terms as (linearised) regressor columns, and
scores a model on held-out samples. The engine owns the statistics and the order of the steps.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from diegocal.evaluate import Score
from diegocal.terms import Term


@dataclass(frozen=True)
class Residuals:
    """A model's residuals (measured − predicted) on every sample of the log, per channel.

    Attributes
    ----------
    channels : channel -> (T,) or (T, d) residual in the channel's unit; NaN where not measured
    units : channel -> unit ("N·m", "V", "m", "kPa")
    variables : name -> (T,) state variables to show the residuals against ("q.joint3", "u", ...)
    channel_variables : channel -> names of ``variables`` worth showing it against, most relevant first
    """

    channels: dict
    units: dict
    variables: dict = field(default_factory=dict)
    channel_variables: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Candidate:
    """A term proposed for the model, linearised: residual ≈ Σ_channel columns @ θ.

    Attributes
    ----------
    term : the cause, channel, region and parameter names (values are not read)
    columns : residual channel -> (T, k) or (T, d, k): d(prediction)/d(θ) at θ = 0 on every sample
    family : variants of one family (the regions of one joint, the delays of one valve) share it;
        the engine keeps the variant with the best fit on the training samples, then tests it
    refit : residual channel -> (T, k0) or (T, d, k0): directions of the current model re-fitted
        together with the term (so that it does not merely take over a baseline term's part)
    """

    term: Term
    columns: dict
    family: str = ""
    refit: dict | None = None

    @property
    def n_params(self) -> int:
        return len(self.term.parameters)


@dataclass(frozen=True)
class Fault:
    """A per-reading data fault (marker outliers, swapped labels): not a regression.

    Attributes
    ----------
    term : the cause with ``extra`` naming what it found (frames, a swapped partner)
    readings : channel -> (T,) bool, the readings it explains
    exclude : True: those readings are left out of every score (an outlier predicts nothing);
        False: the term predicts them (a swap predicts the swapped readings)
    evidence : the detection's facts (threshold, readings, false-alarm rate)
    """

    term: Term
    readings: dict
    exclude: bool
    evidence: dict = field(default_factory=dict)


class Adapter(Protocol):
    """What a domain gives the engine (see the module docstring)."""

    domain: str
    unit_name: str

    def fit(self, terms: tuple[Term, ...], train: np.ndarray) -> Any: ...

    def residuals(self, fitted) -> Residuals: ...

    def candidates(self, fitted, residuals: Residuals, train: np.ndarray) -> list[Candidate]: ...

    def score(self, fitted, mask: np.ndarray, exclude: dict | None = None) -> Score: ...

    def terms(self, fitted) -> tuple[Term, ...]: ...

    def describe(self, fitted) -> str: ...

    def save(self, fitted, path, header: dict) -> Path: ...
