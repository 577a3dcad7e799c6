"""CPU seconds per curation step, for the report and the throughput benchmark.

``time.process_time`` counts this process's CPU only, so other jobs on a loaded machine do not
inflate a step (they still slow it through shared caches). Steps nest: entering a step pauses
the one around it, so every CPU second is charged to exactly one step.
"""

from __future__ import annotations

import time

#: The steps of the per-log stage, in pipeline order (the report and benchmark print them so).
STEPS = ("index", "read", "decode", "resize", "shots", "filters", "encode", "layout", "write", "other")


class StepClock:
    """Accumulates CPU seconds per named step (``seconds``); use :meth:`step` as a context manager."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self._stack: list[str] = []
        self._since = time.process_time()

    def step(self, name: str) -> _Step:
        """``with clock.step(name):`` charges the block's CPU to ``name`` (a plain class, not a
        contextlib generator: ~4 steps per camera-frame, 3.3 instead of 5.2 us each)."""
        return _Step(self, name)

    def _charge(self) -> None:
        """Give the CPU time since the last change to the innermost open step (or to "other")."""
        now = time.process_time()
        name = self._stack[-1] if self._stack else "other"
        self.seconds[name] = self.seconds.get(name, 0.0) + now - self._since
        self._since = now

    def totals(self) -> dict[str, float]:
        """Seconds per step so far (rounded to the millisecond), in :data:`STEPS` order."""
        self._charge()
        return {k: round(self.seconds[k], 3) for k in STEPS if k in self.seconds}


class _Step:
    """The context manager of :meth:`StepClock.step`."""

    __slots__ = ("clock", "name")

    def __init__(self, clock: StepClock, name: str) -> None:
        self.clock, self.name = clock, name

    def __enter__(self) -> None:
        self.clock._charge()
        self.clock._stack.append(self.name)

    def __exit__(self, *exc) -> None:
        self.clock._charge()
        self.clock._stack.pop()
