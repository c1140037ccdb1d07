"""A toy domain for testing the diagnosis engine: y_c(t) = a_c x_c(t) + effects + AR(1) noise.

Two channels, each with a state variable x_c (slow sines plus a random walk); the baseline model
is y = a x + b (a, b fitted); the vocabulary has ``square`` [x²], ``poly`` [x², x³] (the same and
more: the one-SE rule must prefer ``square``) and ``bump`` [the indicator of a window of x] (a
family over windows). The bump is injected with its own smooth shape, so that term is never
checked against itself.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from diegocal.diagnose.types import Candidate, Residuals
from diegocal.evaluate import score
from diegocal.terms import Parameter, Region, Term

CHANNELS = ("c0", "c1")


def make_data(seed: int, T: int = 4000, effects=(), noise: float = 0.1, rho: float = 0.7):
    """x (T, 2), y (T, 2) with AR(1) noise of std ``noise`` and ``effects`` [(kind, channel, size)]."""
    rng = np.random.default_rng(seed)
    t = np.arange(T) * 0.01
    x = np.stack([np.sin(2 * np.pi * f * t + rng.uniform(0, 6.3)) for f in rng.uniform(0.05, 0.3, 2)], axis=1)
    x += 0.2 * np.cumsum(rng.normal(0, 0.02, (T, 2)), axis=0)
    a = np.array([1.0, -0.5])
    y = a * x
    e = rng.normal(0, noise * np.sqrt(1 - rho**2), (T, 2))
    for k in range(1, T):
        e[k] += rho * e[k - 1]
    y = y + e
    for kind, ch, size in effects:
        c = CHANNELS.index(ch)
        if kind == "bump":  # smooth bump around x = 0.5
            y[:, c] += size / (1 + np.exp(-(x[:, c] - 0.4) / 0.02)) / (1 + np.exp((x[:, c] - 0.7) / 0.02))
        elif kind == "quadratic":
            y[:, c] += size * x[:, c] ** 2
    return t, x, y


@dataclass
class Fitted:
    terms: tuple
    a: np.ndarray
    b: np.ndarray
    coef: dict  # term label -> values


class ToyAdapter:
    domain = "toy"
    unit_name = ""

    def __init__(self, t, x, y):
        self.t, self.x, self.y = t, x, y

    def _columns(self, term: Term) -> np.ndarray:
        c = CHANNELS.index(term.channel)
        x = self.x[:, c]
        if term.cause == "square":
            return x[:, None] ** 2
        if term.cause == "poly":
            return np.stack([x**2, x**3], axis=1)
        return term.region.contains(x).astype(float)[:, None]

    def fit(self, terms, train):
        a, b = np.zeros(2), np.zeros(2)
        coef = {}
        for c, ch in enumerate(CHANNELS):
            mine = [t for t in terms if t.channel == ch]
            A = np.column_stack([self.x[:, c], np.ones(len(self.t))] + [self._columns(t) for t in mine])
            sol, *_ = np.linalg.lstsq(A[train], self.y[train, c], rcond=None)
            a[c], b[c] = sol[:2]
            k = 2
            for t in mine:
                n = len(t.parameters)
                coef[t.label] = (t, sol[k : k + n])
                k += n
        return Fitted(tuple(terms), a, b, coef)

    def predict(self, fitted):
        p = self.x * fitted.a + fitted.b
        for t, v in fitted.coef.values():
            p[:, CHANNELS.index(t.channel)] += self._columns(t) @ v
        return p

    def residuals(self, fitted):
        r = self.y - self.predict(fitted)
        variables = {"time": self.t}
        for c, ch in enumerate(CHANNELS):
            variables[f"x.{ch}"] = self.x[:, c]
        return Residuals(
            {ch: r[:, c] for c, ch in enumerate(CHANNELS)},
            {ch: "u" for ch in CHANNELS},
            variables,
            {ch: (f"x.{ch}",) for ch in CHANNELS},
        )

    def candidates(self, fitted, res, train):
        out = []
        for c, ch in enumerate(CHANNELS):
            x = self.x[:, c]
            refit = {ch: np.stack([x, np.ones_like(x)], axis=1)}
            have = {t.cause for t in fitted.terms if t.channel == ch}
            if not have & {"square", "poly"}:
                term = Term("square", ch, (Parameter("k2"),))
                out.append(Candidate(term, {ch: self._columns(term)}, refit=refit))
                term = Term("poly", ch, (Parameter("k2"), Parameter("k3")))
                out.append(Candidate(term, {ch: self._columns(term)}, refit=refit))
            if "bump" not in have:
                q = np.quantile(x[train], np.linspace(0, 1, 21))
                for i in range(20):
                    for j in range(i + 1, min(i + 9, 21)):
                        term = Term("bump", ch, (Parameter("h"),), Region(f"x.{ch}", q[i], q[j]))
                        out.append(Candidate(term, {ch: self._columns(term)}, family=f"bump:{ch}", refit=refit))
        return out

    def score(self, fitted, mask, exclude=None):
        return score(self.y, self.predict(fitted), CHANNELS, mask=mask, unit="u")

    def terms(self, fitted):
        return tuple(t.with_values(v) for t, v in fitted.coef.values())

    def describe(self, fitted):
        return "+".join(["a·x+b"] + [t.label for t in fitted.terms])

    def save(self, fitted, path, header) -> Path:
        return Path(path)
