"""The three domains diegocal models, one record each: the one place that says which streams,
commands, files and words belong to a domain (plain data: the command line's ``--help`` reads it).

================  ==================  ==================  =====================
                  kinematics          dynamics            pneumatics
================  ==================  ==================  =====================
thesis            ch. 2 (STAC)        ch. 3 (SGP)         ch. 4 (valve-chamber)
fit command       ``stac``            ``sgp-fit``         ``pneumatic-fit``
model file        ``.calib.yaml``     ``.sgp/``           ``.pneumatic.yaml``
diagnosable from  pots + markers      q + tau             pressure + valve
================  ==================  ==================  =====================

Older words for a domain (a bundle ``kind: calibration``, ``calib``, ``stac``; ``pneumatic``;
``sgp``) are accepted wherever a domain is named and mean the same domain (:func:`domain`).
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass

from diegocal.errors import UnknownNameError


@dataclass(frozen=True)
class Domain:
    """One domain (see the module docstring).

    name : the domain's one word
    fit_command : the command that fits its model
    model_suffix : the file name ending of a fitted model beside its log (``run.calib.yaml``)
    model_is_directory : the model is a directory (the dynamics bundle)
    streams : the streams a log needs to be diagnosed in this domain
    fit_needs : the streams its fit command needs
    predict_needs : the streams a log needs for ``predict`` with its model
    kind : the ``kind`` its fitted models' bundles carry: its name (files of layout 1 wrote
        ``calibration`` and ``pneumatic``, read as aliases)
    aliases : older words for it (bundle kinds of file layout 1, command-line words)
    """

    name: str
    fit_command: str
    model_suffix: str
    model_is_directory: bool
    streams: tuple[str, ...]
    fit_needs: tuple[str, ...]
    predict_needs: tuple[str, ...]
    kind: str
    aliases: tuple[str, ...] = ()

    @property
    def extended_suffix(self) -> str:
        """The ending of a diagnosis's extended model beside its diagnosis.yaml."""
        return ".extended" + self.model_suffix


KINEMATICS = Domain(
    "kinematics", "stac", ".calib.yaml", False, ("pots", "markers"), ("pots", "markers"), ("pots", "markers"),
    "kinematics", ("calibration", "calib", "stac"),
)
DYNAMICS = Domain("dynamics", "sgp-fit", ".sgp", True, ("q", "tau"), ("q", "tau"), ("q",), "dynamics", ("sgp",))
PNEUMATICS = Domain(
    "pneumatics", "pneumatic-fit", ".pneumatic.yaml", False, ("pressure", "valve"), ("pressure", "valve", "pots"),
    ("pressure", "valve", "pots"), "pneumatics", ("pneumatic",),
)

#: Domain name -> record, in the order diagnose runs them.
DOMAINS: dict[str, Domain] = {d.name: d for d in (KINEMATICS, DYNAMICS, PNEUMATICS)}
DOMAIN_NAMES: tuple[str, ...] = tuple(DOMAINS)
_WORDS = {w: d for d in DOMAINS.values() for w in (d.name, *d.aliases)}


def domain(word: str) -> Domain:
    """The domain a word names (its name or an older word for it); one clear error otherwise."""
    try:
        return _WORDS[word]
    except (KeyError, TypeError):
        close = difflib.get_close_matches(str(word), list(_WORDS), n=1)
        hint = f" (did you mean {close[0]}?)" if close else ""
        raise UnknownNameError(f"unknown domain {word!r}{hint}; expected one of {', '.join(DOMAINS)}") from None


def of_command(command: str) -> Domain | None:
    """The domain whose model ``command`` fits (None for commands that fit none)."""
    return next((d for d in DOMAINS.values() if d.fit_command == command), None)
