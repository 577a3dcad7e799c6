"""Interleaved timing for the benchmarks that compare settings of one command in the same run.

Settings alternate round by round after one warm-up round (not counted), so a machine that slows
down mid-run slows every setting alike; medians are compared, as the README's benchmark rule asks.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable


def add_sampling_arguments(parser: argparse.ArgumentParser) -> None:
    """--model, --steps, --guidance, --repeats and --threads, at the world-model benchmark's sampler settings."""
    parser.add_argument("--model", default="shipped:multiview")
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--guidance", type=float, default=7.0)
    parser.add_argument("--repeats", type=int, default=3, help="clips per setting, alternating")
    parser.add_argument("--threads", type=int, default=2, help="torch threads (the caller sets them)")


def alternate(runs: dict[str, Callable[[int], object]], repeats: int) -> dict[str, list[float]]:
    """Seconds of each named run over ``repeats`` rounds; each call gets its round number (a seed)."""
    times: dict[str, list[float]] = {name: [] for name in runs}
    for r in range(repeats + 1):
        for name, run in runs.items():
            tic = time.perf_counter()
            run(r)
            if r:
                times[name].append(time.perf_counter() - tic)
    return times


def print_medians(times: dict[str, list[float]], base: str, label: str, extra: dict[str, dict] | None = None) -> None:
    """A row per setting: ``extra`` columns ({header: {setting: value}}), the median seconds and the
    ratio to setting ``base``'s median."""
    extra = extra or {}
    reference = statistics.median(times[base])
    print(f"{label:>14s} " + "".join(f"{h:>6s} " for h in extra) + f"{'median s/clip':>14s} {'ratio':>6s}")
    for name, seconds in times.items():
        median = statistics.median(seconds)
        cells = "".join(f"{column[name]:6d} " for column in extra.values())
        print(f"{name:>14s} {cells}{median:14.2f} {median / reference:6.2f}")
