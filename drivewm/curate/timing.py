"""CPU seconds per curation step, for the report and the throughput benchmark.

``time.process_time`` counts this process's CPU only, so other jobs on a loaded machine do not
inflate a step (they still slow it through shared caches). Steps nest: entering a step pauses
the one around it, so every CPU second is charged to exactly one step.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator

#: The steps of the per-log stage, in pipeline order (the report and benchmark print them so).
STEPS = ("index", "read", "decode", "resize", "shots", "filters", "encode", "write", "other")


class StepClock:
    """Accumulates CPU seconds per named step (``seconds``); use :meth:`step` as a context manager."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self._stack: list[str] = []
        self._since = time.process_time()

    @contextlib.contextmanager
    def step(self, name: str) -> Iterator[None]:
        self._charge()
        self._stack.append(name)
        try:
            yield
        finally:
            self._charge()
            self._stack.pop()

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
