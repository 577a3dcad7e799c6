"""What the manifest check of the shipped weights costs (drivewm.model_folders.verify_shipped), against the
``drivewm generate`` call it guards.

Each round times, interleaved: one ``generate`` (in this process, the shipped multi-view model and its
tokenizer); the check of those two folders cold (nothing remembered: every file hashed, as the first load on a
machine); and warm (the cache file of an earlier process: a ``stat`` per file). Medians over rounds; the limit
is a cold check under 5% of a generate call. ``--steps`` below generate's default only makes the call cheaper,
so the ratio it gives is an upper bound.

    python benchmarks/bench_shipped_check.py                # 3 rounds, generate's defaults
    python benchmarks/bench_shipped_check.py --steps 4 --rounds 2
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

import torch

from drivewm import cli, model_folders

FOLDERS = ("multiview", "tokenizer")  # what generate loads by default
LIMIT = 0.05


def check(cache_dir: Path, cold: bool) -> None:
    """The check of every folder generate loads, in a fresh process's state (``cold``: no cache file either)."""
    model_folders._VERIFIED.clear()
    if cold:
        model_folders.verified_cache_path().unlink(missing_ok=True)
    for kind in FOLDERS:
        model_folders.verify_shipped(model_folders.shipped_model(kind))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--steps", type=int, default=None, help="generate's --steps (default: its own)")
    parser.add_argument("--threads", type=int, default=2, help="torch threads")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    times: dict[str, list[float]] = {"generate": [], "check cold": [], "check warm": []}
    with tempfile.TemporaryDirectory() as tmp:
        os.environ["DRIVEWM_CACHE_DIR"] = str(Path(tmp) / "cache")
        steps = [] if args.steps is None else ["--steps", str(args.steps)]
        runs = {
            "generate": lambda r: cli.main(
                ["generate", "--prompt", "a highway at dusk", "--seed", str(r), *steps, "--out", f"{tmp}/gen{r}"]
            ),
            "check cold": lambda r: check(Path(tmp), cold=True),
            "check warm": lambda r: check(Path(tmp), cold=False),
        }
        for r in range(args.rounds):
            for name, run in runs.items():
                tic = time.perf_counter()
                run(r)
                times[name].append(time.perf_counter() - tic)
    base = statistics.median(times["generate"])
    print(f"median seconds over {args.rounds} interleaved rounds (ratio to one generate call; limit {LIMIT:.0%}):")
    for name, seconds in times.items():
        median = statistics.median(seconds)
        print(f"  {name:12s} {median:10.4f} s  {median / base:8.4%}")
    cold = statistics.median(times["check cold"]) / base
    print(f"cold check {'within' if cold < LIMIT else 'OVER'} the limit: {cold:.4%} < {LIMIT:.0%}")


if __name__ == "__main__":
    main()
