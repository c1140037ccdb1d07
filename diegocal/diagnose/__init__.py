"""Diagnosis: show what a model gets wrong, name the cause, extend the model, measure the gain.

Public API::

    from diegocal.diagnose import diagnose, DiagnoseOptions
    result = diagnose(log, robot, DiagnoseOptions(domain="dynamics"))   # a Diagnosis
    result.findings          # most important first; () when nothing is significant
    result.to_dict()         # diagnosis.yaml (DESIGN.md, "Diagnosis output")
    result.save_extended(path)   # the extended model, a bundle `predict` accepts

The engine (:mod:`.engine`, the choice of candidates in :mod:`.selection`, statistics in :mod:`.stats`,
the Show step in :mod:`.show`, a finding's evidence curves in :mod:`.evidence`) is domain-free; each
domain gives it an adapter: :mod:`.dynamics`, :mod:`.kinematics`, :mod:`.pneumatics` (their function
``adapters(log, robot, options) -> list[Adapter]``).
"""

from __future__ import annotations

import importlib
import numbers
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from diegocal.diagnose.engine import (
    Adapter,
    Candidate,
    EngineOptions,
    Fault,
    Finding,
    Residuals,
    UnitDiagnosis,
    run_unit,
)
from diegocal.diagnose.output import diagnosis_dict
from diegocal.domains import DOMAIN_NAMES as DOMAINS
from diegocal.domains import domain as domain_record
from diegocal.errors import DiegocalError, FitError, MissingStreamError, OptionError
from diegocal.evaluate import Blocks, split_blocks
from diegocal.io import save_yaml
from diegocal.io.bundle import header
from diegocal.parallel import one_blas_thread
from diegocal.progress import Eta

#: Samples a block needs at least: fewer leave each block's error and its standard error to a handful
BLOCK_SAMPLES = 5
#: (option, lowest, highest) of :class:`DiagnoseOptions`, as the command line bounds them
BOUNDS = (("alpha", 1e-6, 0.5), ("min_gain", 0.0, 0.99), ("max_rounds", 1, 1000), ("n_blocks", 5, 10_000),
          ("jobs", 1, 1024))


@dataclass(frozen=True)
class DiagnoseOptions:
    """Options of :func:`diagnose`, parsed once.

    domain : "kinematics" | "dynamics" | "pneumatics"
    alpha, min_gain, max_rounds : see :class:`~diegocal.diagnose.engine.EngineOptions`
    n_blocks : contiguous blocks the log is cut into (roles train / validation / held out, interleaved)
    friction : dynamics: the baseline's friction terms (subset of viscous, coulomb)
    inertia : dynamics: "identified" (the baseline fits the rigid body's base parameters) or
        "nominal" (the URDF's inertias are the model; only friction is fitted, so an unmodelled
        payload is a model error that can be named)
    chambers : pneumatics: the chambers to diagnose (() = all)
    jobs : independent units (chambers) diagnosed in parallel processes; a log of one unit uses
        them as threads within it (its adapter's work and its candidates' fits)
    seed : seeds anything random (none of the defaults is)
    progress : optional callable(str)
    """

    domain: str = "dynamics"
    alpha: float = 0.01
    min_gain: float = 0.05
    max_rounds: int = 6
    n_blocks: int = 10
    friction: tuple = ("viscous", "coulomb")
    inertia: str = "identified"
    chambers: tuple = ()
    jobs: int = 1
    seed: int = 0
    progress: object = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        """The command line's bounds hold for a library caller too: one OptionError line (a log cut
        into 2 blocks has no held-out block, and its diagnosis would read as a clean bill)."""
        for name, low, high in BOUNDS:
            value = getattr(self, name)
            if not isinstance(value, numbers.Real) or not low <= value <= high:
                raise OptionError(f"diagnose option {name} = {value!r}: expected a number from {low:g} to {high:g}")

    def engine(self, n_units: int = 1) -> EngineOptions:
        return EngineOptions(
            alpha=self.alpha,
            min_gain=self.min_gain,
            max_rounds=self.max_rounds,
            n_units=n_units,
            progress=self.progress,
            jobs=self.jobs if n_units == 1 else 1,
        )


@dataclass(frozen=True)
class Diagnosis:
    """The diagnosis of one log in one domain: every unit's result, and how the log was cut."""

    domain: str
    units: tuple[UnitDiagnosis, ...]
    blocks: Blocks
    time: np.ndarray
    options: DiagnoseOptions
    adapters: tuple = field(repr=False, default=())
    robot: object = field(repr=False, default=None)

    @property
    def findings(self) -> tuple[Finding, ...]:
        """Every unit's findings, most important first: by the fraction of its channel's held-out
        error it removed (:meth:`~diegocal.diagnose.types.Finding.gain`); findings without a
        held-out gain (structure left unexplained, with nothing to absorb it) last, by validation
        gain."""
        items = []
        for u in self.units:
            for f in u.findings:
                red = (f.gain() or {}).get("reduction")
                held = red is not None and np.isfinite(red)
                items.append((0 if held else 1, -(red if held else 0.0), -f.evidence.get("validation_gain", 0.0), f))
        return tuple(item[-1] for item in sorted(items, key=lambda item: item[:3]))

    def save_extended(self, path, header: dict) -> Path:
        """Write the extended model (a bundle of the domain's kind) to ``path``."""
        if len(self.units) == 1:
            return self.adapters[0].save(self.units[0].fitted, path, header)
        module = importlib.import_module(f"diegocal.diagnose.{self.domain}")
        return module.save_units(self.adapters, [u.fitted for u in self.units], path, header)

    def to_dict(self, extended_model: str | None = None) -> dict:
        return diagnosis_dict(self, extended_model)

    def save(self, path, log=None, command: str = "diegocal (Python)", extended: Path | None = None) -> Path:
        """Write diagnosis.yaml at ``path`` and the extended model beside it (``extended``; default
        the domain's suffix, ``run.extended.sgp``), both with their bundle headers (``log``: the
        path of the log it diagnosed). Returns the extended model's path."""
        path = Path(path)
        if extended is None:
            stem = path.name.removesuffix(".yaml").removesuffix(".diagnosis")
            extended = path.with_name(stem + domain_record(self.domain).extended_suffix)
        try:
            self.save_extended(extended, header(domain_record(self.domain).kind, self.robot, log, command))
        except OSError as exc:
            raise DiegocalError(f"{extended}: cannot write the extended model ({exc.strerror or exc})") from None
        save_yaml({**header("diagnosis", self.robot, log, command), **self.to_dict(extended.name)}, path)
        return Path(extended)


def domains_of(log) -> tuple[str, ...]:
    """The domains a log's streams allow (DESIGN.md: markers + pots, q + tau, pressure + valve)."""
    return tuple(d for d in DOMAINS if all(log.has(s) for s in domain_record(d).streams))


def check_domain(log, domain: str) -> None:
    if domain not in DOMAINS:
        raise DiegocalError(f"unknown domain {domain!r}; expected one of {', '.join(DOMAINS)}")
    missing = [s for s in domain_record(domain).streams if not log.has(s)]
    if missing:
        have = ", ".join(sorted(log.streams)) or "none"
        raise MissingStreamError(
            f"diagnose --domain {domain} needs the stream(s) {', '.join(missing)}; the log has: {have}"
        )


def diagnose(log, robot, options: DiagnoseOptions | None = None) -> Diagnosis:
    """Diagnose ``log`` in ``options.domain`` (never reads ``log.truth``).

    BLAS runs on one thread: the diagnosis is many small least-squares problems, where threads
    only contend (a 60-s UR5 log: 6.6 s against 17.8 s with the default threads on 2 cores);
    ``options.jobs`` spreads independent units over processes instead, or, with one unit, its
    work over threads.
    """
    with one_blas_thread():
        return _diagnose(log, robot, options or DiagnoseOptions())


def _diagnose(log, robot, options: DiagnoseOptions) -> Diagnosis:
    check_domain(log, options.domain)
    log = log.without_truth()
    if log.n_samples < BLOCK_SAMPLES * options.n_blocks:
        raise FitError(
            f"too few samples to diagnose: {log.n_samples} for {options.n_blocks} blocks (train, validation, held "
            f"out), {BLOCK_SAMPLES} a block at least"
        )
    blocks = split_blocks(log.n_samples, options.n_blocks)
    # the domain's adapter module, imported when its domain is diagnosed (each loads its model family)
    module = importlib.import_module(f"diegocal.diagnose.{options.domain}")
    adapters = tuple(module.adapters(log, robot, options))
    if not adapters:
        raise DiegocalError(f"nothing to diagnose in the {options.domain} domain of this log")
    engine = options.engine(n_units=len(adapters))
    eta = Eta(len(adapters), every=0.0)  # every unit is reported, with the time left

    def done(units: list, unit, name: str) -> None:
        units.append(unit)
        if options.progress is not None and len(adapters) > 1 and eta.due(len(units)):
            options.progress(f"diagnosed {name}: {eta.text(len(units))}")

    units: list = []
    if options.jobs > 1 and len(adapters) > 1:
        quiet = replace(engine, progress=None)
        with ProcessPoolExecutor(max_workers=options.jobs) as pool:
            futures = [pool.submit(run_unit, a, blocks, quiet) for a in adapters]
            for a, fut in zip(adapters, futures, strict=True):
                done(units, fut.result(), a.unit_name)
    else:
        for a in adapters:
            done(units, run_unit(a, blocks, engine), a.unit_name)
    return Diagnosis(options.domain, tuple(units), blocks, log.time, options, adapters, robot)


__all__ = [
    "DOMAINS",
    "Adapter",
    "Candidate",
    "DiagnoseOptions",
    "Diagnosis",
    "EngineOptions",
    "Fault",
    "Finding",
    "Residuals",
    "UnitDiagnosis",
    "check_domain",
    "diagnose",
    "domains_of",
    "run_unit",
]
