"""What ``diagnose`` may add to a dynamics model (:func:`diegocal.sgp.terms.proposals`), in a module
of its own so that the behaviours kept apart (:mod:`diegocal.sgp.backlash`) make theirs too."""

from __future__ import annotations

from dataclasses import dataclass

from diegocal.terms import Term


@dataclass(frozen=True)
class Proposal:
    """A term ``diagnose`` may add; ``columns`` (joint -> (T, k)) when they are not the term's own
    (a lag's exact change per second of lag); ``family`` groups the variants of one term."""

    term: Term
    family: str = ""
    columns: dict | None = None
