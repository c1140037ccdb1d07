"""Effect requests shared by the simulators: ``--effect NAME[:channel][=SIZE]`` parsing and validation.

An effect is a named departure of the simulated robot from its nominal model (DESIGN.md,
"Diagnosis output", vocabulary). Each simulator injects the effects of its own domain and
records what it injected in ``/truth`` as a list of dicts ``{cause, channel, region, values}``
(see :func:`effect_record`).
"""

from __future__ import annotations

from dataclasses import dataclass

from diegocal.causes import DOMAINS, VOCABULARY  # noqa: F401  (the simulators' names for them)
from diegocal.errors import OptionError, UnknownNameError
from diegocal.io.files import to_plain


class EffectError(OptionError):
    """An ``--effect`` request is malformed, unknown, or belongs to another domain."""


class SimOptionError(OptionError):
    """A simulator option is out of range (negative duration, occlusion fraction >= 1, ...)."""


@dataclass(frozen=True)
class EffectRequest:
    """One requested effect: a cause id from :data:`VOCABULARY` and an optional channel.

    Attributes
    ----------
    name : str, the cause id (``position_friction``)
    channel : str or None, the joint / sensor / marker / chamber it acts on (``r_knee``);
        None lets the simulator choose one (seeded).
    size : float or None, the effect's magnitude in the unit its simulator documents (a torque in
        N·m, a reading in V, a distance in m, a delay in s, a pressure in kPa); None: the
        simulator's default.
    """

    name: str
    channel: str | None = None
    size: float | None = None

    def __str__(self) -> str:
        text = self.name if self.channel is None else f"{self.name}:{self.channel}"
        return text if self.size is None else f"{text}={self.size:g}"


def parse_effect(text: str) -> EffectRequest:
    """Parse ``"NAME"``, ``"NAME:channel"``, ``"NAME=SIZE"`` or ``"NAME:channel=SIZE"``.

    Only the syntax is checked here; :func:`check_effects` checks names against a domain.
    """
    if not isinstance(text, str):
        raise EffectError(f"effect must be a string like 'name:channel', got {text!r}")
    raw, eq, size_text = text.strip().partition("=")
    name, sep, channel = raw.partition(":")
    name, channel = name.strip(), channel.strip()
    if not name:
        raise EffectError(f"effect {text!r}: expected NAME, NAME:CHANNEL or NAME:CHANNEL=SIZE")
    if sep and not channel:
        raise EffectError(f"effect {text!r}: empty channel after ':'")
    size = None
    if eq:
        try:
            size = float(size_text)
        except ValueError:
            raise EffectError(f"effect {text!r}: size {size_text.strip()!r} is not a number") from None
        if not size > 0 or size == float("inf"):
            raise EffectError(f"effect {text!r}: size must be a positive number, got {size_text.strip()}")
    return EffectRequest(name=name, channel=channel or None, size=size)


def parse_effects(texts) -> tuple[EffectRequest, ...]:
    """Parse a sequence of ``--effect`` values (None or empty -> ``()``)."""
    return tuple(parse_effect(t) for t in (texts or ()))


def check_effects(requests, domain: str) -> tuple[EffectRequest, ...]:
    """Validate requests for one simulator's domain; returns them as a tuple.

    Raises :class:`EffectError` for an unknown name ("effect 'x' is not a kinematics effect;
    known: ...") or a name from another domain, and for the same effect requested twice on the
    same channel. Requests given as strings are parsed first.
    """
    if domain not in DOMAINS:
        raise UnknownNameError(f"unknown effect domain {domain!r}; known: {', '.join(DOMAINS)}")
    known = sorted(k for k, d in VOCABULARY.items() if d == domain)
    out, seen = [], set()
    for req in requests or ():
        if isinstance(req, str):
            req = parse_effect(req)
        if VOCABULARY.get(req.name) != domain:
            other = VOCABULARY.get(req.name)
            hint = f" (it is a {other} effect)" if other else ""
            raise EffectError(
                f"effect {req.name!r} is not a {domain} effect{hint}; known: {', '.join(known)}"
            )
        if (req.name, req.channel) in seen:
            raise EffectError(f"effect '{req}' requested twice")
        seen.add((req.name, req.channel))
        out.append(req)
    return tuple(out)


def check_channel(request: EffectRequest, available, what: str) -> str:
    """The request's channel if it is in ``available``; else :class:`UnknownNameError`.

    ``what`` names the kind of channel ("joint", "pot", "marker") for the message.
    """
    available = tuple(available)
    if request.channel not in available:
        shown = ", ".join(available[:12]) + (", ..." if len(available) > 12 else "")
        raise UnknownNameError(
            f"effect '{request}': {request.channel!r} is not a {what} of this robot; "
            f"known: {shown or 'none'}"
        )
    return request.channel


def effect_record(cause: str, channel: str | None, values: dict,
                  region: dict | None = None) -> dict:
    """One ``/truth`` effects entry: ``{cause, channel, region, values}`` (DESIGN.md).

    numpy values become plain floats and lists, so the record in memory equals the one read
    back from a log file.
    """
    return {"cause": cause, "channel": channel, "region": to_plain(region),
            "values": to_plain(dict(values))}
