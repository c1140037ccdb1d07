"""Time left of a loop of known length: the one estimate every long command's progress shows
(issue #33: progress with an estimate of time left on every command that runs for long).

The library never prints: a loop that takes long (candidate terms tested by the diagnosis, the
chambers of ``pneumatic-fit --all``, a diagnosis's units) keeps an :class:`Eta` and, when it is
:meth:`Eta.due`, passes :meth:`Eta.text` to the progress callable it was given; the command line
prints it. The estimate is the mean time per item so far times the items left: the items of these
loops are alike (chambers of one robot, candidate terms of one log), so it settles after a few.
"""

from __future__ import annotations

import time
from collections.abc import Callable

#: Seconds between two progress lines of one loop (and before its first).
EVERY = 5.0


def duration(seconds: float) -> str:
    """A duration in words a user reads at a glance: "8 s", "3 min 20 s", "1 h 05 min"."""
    s = int(round(seconds))
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {s % 3600 // 60:02d} min"


class Eta:
    """Progress of a loop over ``total`` items started now: elapsed time, items done, time left.

    ``clock`` (seconds, monotonic) is ``time.monotonic`` unless a test gives its own;
    ``every``: seconds between two reports (:meth:`due`).
    """

    def __init__(self, total: int, every: float = EVERY, clock: Callable[[], float] = time.monotonic):
        self.total = int(total)
        self.every = every
        self.clock = clock
        self.start = self.last = clock()
        self.reported = False

    def elapsed(self) -> float:
        return self.clock() - self.start

    def left(self, done: int) -> float | None:
        """Seconds left after ``done`` items: the mean time per item so far times the items left
        (None before the first item)."""
        if done <= 0:
            return None
        return self.elapsed() / done * max(self.total - done, 0)

    def due(self, done: int) -> bool:
        """Whether to report now: ``every`` seconds after the start or the last report, and at
        the last item of a loop that was reported before (a short loop says nothing)."""
        now = self.clock()
        if now - self.last >= self.every or (done >= self.total and self.reported):
            self.last, self.reported = now, True
            return True
        return False

    def text(self, done: int) -> str:
        """Progress in words, "12/76, 1 min 05 s so far, about 5 min 47 s left" (no estimate
        before the first item, none after the last)."""
        left = self.left(done)
        tail = "" if left is None or done >= self.total else f", about {duration(left)} left"
        return f"{done}/{self.total}, {duration(self.elapsed())} so far{tail}"


def ticker(progress: Callable[[str], None] | None, total: int, what: str) -> Callable[[], None]:
    """A function to call after each of ``total`` steps of a loop: tells ``progress`` (None: no
    one) "what: done/total, time so far, time left" when :meth:`Eta.due`."""
    eta, done = Eta(total), [0]

    def tick() -> None:
        done[0] += 1
        if progress is not None and eta.due(done[0]):
            progress(f"{what}: {eta.text(done[0])}")

    return tick
