"""Seconds per 6-camera clip for each eval metric on the CPU, and the speed-up from parallel workers.

Simulates one short nuscenes6 drive (highway-env, 320x192, 10 fps), curates it into 17-frame clips
with drivewm/recipes/curate/test.yaml, then runs the full protocol with 1 worker and with 2 workers on the
same clips. Prints per-metric seconds per clip, the real-time factor (seconds of compute per second
of 6-camera video) and the 2-vs-1-worker speed-up measured in the same run.

    python benchmarks/bench_eval.py            # 2 clips (~ a few minutes on 2 busy cores)
    python benchmarks/bench_eval.py --full     # 6 clips
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

os.environ.setdefault("SDL_VIDEODRIVER", "offscreen")


def make_clips(out: Path, clips: int) -> Path:
    from drivewm.curate import curate, load_curate_config
    from drivewm.sim import SimConfig, simulate

    log = simulate(
        SimConfig(source="highway", scenario="highway", duration_s=1.7 * clips + 2.0, fps=10.0, seed=7),
        out / "drive.mcap",
    )
    curate(
        [log],
        out / "clips",
        load_curate_config("test"),
        executor="local",
        workers=1,
    )
    return out / "clips"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--full", action="store_true", help="6 clips instead of 2")
    args = parser.parse_args()
    from drivewm.eval.config import EvalConfig
    from drivewm.eval.suite import evaluate

    with tempfile.TemporaryDirectory() as tmp:
        clip_dir = make_clips(Path(tmp), 6 if args.full else 2)
        walls = {}
        for workers in (1, 2):
            t0 = time.perf_counter()
            metrics = evaluate(clip_dir, cfg=EvalConfig(), workers=workers, progress=False)
            walls[workers] = time.perf_counter() - t0
            if workers == 1:
                per_metric = metrics["seconds_per_clip"]
                n, clip_s = metrics["num_clips"], 1.7
    print(f"clips: {n} (6 cameras x 17 frames, 320x192)")
    for name, secs in per_metric.items():
        print(f"  {name:10s} {secs:7.2f} s/clip   real-time factor {secs / clip_s:6.1f}x")
    print(f"  {'total':10s} {sum(per_metric.values()):7.2f} s/clip")
    ideal = n / -(-n // 2)  # n clips in ceil(n / 2) rounds of 2 workers
    print(
        f"wall: 1 worker {walls[1]:.1f} s, 2 workers {walls[2]:.1f} s -> speed-up {walls[1] / walls[2]:.2f}x "
        f"(ideal {ideal:.2f}x for {n} clips on 2 free cores; {os.cpu_count()} cores here, load "
        f"{os.getloadavg()[0]:.1f})"
    )


if __name__ == "__main__":
    main()
