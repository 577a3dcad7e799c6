"""Seconds per clip of the consistency benchmark with its guards (drivewm.eval.guards) against the
speed limits: 5 s per 6-camera 17-frame 320x192 clip and 60 s for the 221-frame real dashcam clip,
on 2 cores.

Scores the simulated clips of ``--clip-dir`` (default: the test suite's cached clips,
tests/conftest.py::sim_clips(), built on first use) with the full protocol (TSE, CSE, pose,
trajectory) on 2 threads, ``--repeats`` times each, interleaved with the dashcam clip (TSE and
pose, 2 threads) when ``--dashcam`` is given, and prints the wall medians, their ratio to the
limits, the parts (``seconds``: features, TSE with its motion and direction guards, CSE, pose with
its flow plausibility check ``pose_flow``) and the guards' verdicts. The machine is shared: the load
average and the machine's busy share are printed beside every figure.

    python benchmarks/bench_eval_guards.py --clips 2
    taskset -c 0,1 python benchmarks/bench_eval_guards.py --dashcam   # pin to 2 cores
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np
from bench_eval import DASHCAM, cpu_ticks, machine_share

REPO = Path(__file__).resolve().parents[1]
CLIP_LIMIT_S, DASHCAM_LIMIT_S = 5.0, 60.0


def sim_items(clip_dir: Path | None, clips: int) -> list:
    from drivewm.clips.shards import spread
    from drivewm.eval.inputs import load_items

    if clip_dir is None:
        sys.path.insert(0, str(REPO / "tests"))
        from conftest import sim_clips  # the cached test clips (DRIVEWM_TEST_CACHE)

        clip_dir = sim_clips()
    items = spread(load_items(clip_dir), clips)
    for item in items:
        item.videos()  # decode once, outside the timing
    return items


def timed(item, cfg) -> tuple[float, dict]:
    from drivewm.eval.suite import evaluate_item

    t0 = time.perf_counter()
    metrics = evaluate_item(item, cfg, threads=2).metrics
    return time.perf_counter() - t0, metrics


def verdict(m: dict) -> str:
    keys = ("guard_motion", "guard_time", "guard_views", "pose_plausible")
    return ", ".join(f"{k} {m.get(k)}" for k in keys) + (f", voided by {m['voided_by']}" if "voided_by" in m else "")


def main() -> None:
    from drivewm.eval.config import EvalConfig
    from drivewm.eval.inputs import load_items

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--clips", type=int, default=2, help="simulated clips to time")
    parser.add_argument("--clip-dir", type=Path, help="score these clips (default: the test suite's cached clips)")
    parser.add_argument("--repeats", type=int, default=2, help="timings per clip, interleaved")
    parser.add_argument("--dashcam", action="store_true", help="also time the 221-frame real dashcam clip")
    parser.add_argument("--dashcam-path", type=Path, default=DASHCAM, help="where that clip is (../shared/data)")
    args = parser.parse_args()
    print(f"{len(os.sched_getaffinity(0))} cores available to this process ({os.cpu_count()} on the machine)")
    jobs = [
        (item.key, item, EvalConfig(metrics=["tse", "cse", "pose", "traj"]))
        for item in sim_items(args.clip_dir, args.clips)
    ]
    if args.dashcam:
        dash = load_items(args.dashcam_path, "front1", fit="stretch")[0]
        dash.videos()
        jobs.append(("dashcam", dash, EvalConfig(metrics=["tse", "pose"])))
    walls: dict[str, list[float]] = {key: [] for key, _, _ in jobs}
    before = cpu_ticks()
    for _ in range(args.repeats):
        for key, item, cfg in jobs:  # interleaved: every clip sees the same load
            wall, m = timed(item, cfg)
            walls[key].append(wall)
            parts = ", ".join(f"{k} {v:.1f}" for k, v in m["seconds"].items())
            print(f"  {key:24s} wall {wall:6.1f} s ({parts}); {verdict(m)}; load {os.getloadavg()[0]:.1f}", flush=True)
    sim = float(np.median([np.median(w) for k, w in walls.items() if k != "dashcam"]))
    print(f"sim clips: median wall {sim:.1f} s/clip = {sim / CLIP_LIMIT_S:.2f}x the {CLIP_LIMIT_S:.0f} s limit")
    if args.dashcam:
        d = float(np.median(walls["dashcam"]))
        print(
            f"dashcam 221 frames: median wall {d:.1f} s = {d / DASHCAM_LIMIT_S:.2f}x the {DASHCAM_LIMIT_S:.0f} s limit"
        )
    print(machine_share(before, cpu_ticks()))


if __name__ == "__main__":
    main()
