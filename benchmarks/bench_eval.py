"""Seconds per clip of the consistency benchmark against its goals: 5 s per 6-camera 17-frame clip
and 60 s for the 221-frame real dashcam clip, on 2 idle cores (issue 69).

Simulates one short nuscenes6 drive (highway-env, 320x192, 10 fps), curates it into 17-frame
clips with the packaged curate recipe ``test`` (or takes the clips of ``--clip-dir``, e.g. the
reference set), and scores each clip with the full protocol (TSE, CSE, pose, trajectory) three
times, interleaved: the protocol (``pose.features=shared``: TSE, CSE and structure from motion share
one clip's SIFT features and matches) on one thread and on two (``evaluate_item(threads=2)``: one
clip's features, matches and F fits spread over both cores; COLMAP's mapping stays on one), and with
COLMAP's own extraction and matching (``colmap``, the protocol before issue 14) on one. Prints
per-metric seconds per clip, the medians, their ratios and the ratio to the 5 s goal, pose success
and ATE, and whether the one- and two-thread figures are identical (they must be). ``--dashcam``
also times ../shared/data's 221-frame 960x540 dashcam clip (front camera, pose + TSE) against 60 s,
wall and CPU: the protocol on two threads and on one, and COLMAP's 50 iterations per global bundle
adjustment, interleaved, and prints how far apart the camera paths are (seconds by part: TSE,
pose's database and mapping). The machine is shared: the load average is printed; compare ratios
taken in the same run.

    python benchmarks/bench_eval.py              # 2 clips
    python benchmarks/bench_eval.py --clips 6 --dashcam
    python benchmarks/bench_eval.py --clip-dir CLIPDIR   # e.g. the reference set: tests/conftest.py::sim_clips()
    taskset -c 0,1 python benchmarks/bench_eval.py   # pin to 2 cores
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("SDL_VIDEODRIVER", "offscreen")
REPO = Path(__file__).resolve().parents[1]
DASHCAM = REPO / ".." / "shared" / "data" / "video" / "dashcam_highway" / "solidWhiteRight.mp4"
CLIP_GOAL_S, DASHCAM_GOAL_S = 5.0, 60.0


def make_clips(out: Path, clips: int) -> Path:
    from drivewm.curate import curate, load_curate_config
    from drivewm.sim import SimConfig, simulate

    log = simulate(
        SimConfig(source="highway", scenario="highway", duration_s=1.7 * clips + 2.0, fps=10.0, seed=7),
        out / "drive.mcap",
        progress=False,
    )
    cfg = load_curate_config("test")
    curate([log], out / "clips", cfg, executor="local", workers=1, progress=False)
    return out / "clips"


def timed(item, cfg, threads: int):
    """Wall seconds, CPU seconds of this process (all its threads), and the ClipResult (metrics,
    artifacts) of one clip scored on ``threads`` threads."""
    from drivewm.eval.suite import evaluate_item

    t0, c0 = time.perf_counter(), time.process_time()
    result = evaluate_item(item, cfg, threads)
    return time.perf_counter() - t0, time.process_time() - c0, result


def figures(metrics: dict) -> dict:
    """The metrics without their timings: what must not depend on the thread count."""
    return {k: v for k, v in metrics.items() if k != "seconds"}


def bench_clips(n: int, clip_dir: Path | None = None) -> None:
    """Score ``n`` new simulated clips, or every clip of ``clip_dir``, with both feature paths, interleaved."""
    from drivewm.eval.config import EvalConfig, PoseConfig
    from drivewm.eval.inputs import load_items

    with tempfile.TemporaryDirectory() as tmp:
        items = load_items(clip_dir or make_clips(Path(tmp), n))
        for item in items:
            item.videos()  # decode once, outside the timing
        protocol = EvalConfig(metrics=["tse", "cse", "pose", "traj"])
        runs = {
            "2 threads": (protocol, 2),
            "1 thread": (protocol, 1),
            "colmap": (EvalConfig(metrics=["tse", "cse", "pose", "traj"], pose=PoseConfig(features="colmap")), 1),
        }
        walls: dict[str, list[float]] = {k: [] for k in runs}
        cpus: dict[str, list[float]] = {k: [] for k in runs}
        success: dict[str, list[float]] = {k: [] for k in runs}
        ates: dict[str, list[float]] = {k: [] for k in runs}
        same = []
        for item in items:
            got = {}
            for name, (cfg, threads) in runs.items():  # interleaved: all see the same load
                wall, cpu, result = timed(item, cfg, threads)
                m = got[name] = result.metrics
                walls[name].append(wall)
                cpus[name].append(cpu)
                success[name].append(m["pose_success"])
                ates[name].append(m["ate"])
                parts = ", ".join(f"{k} {v:.1f}" for k, v in m["seconds"].items())
                print(f"  {item.key:24s} {name:9s} wall {wall:6.1f} s, cpu {cpu:6.1f} s  ({parts})")
            same.append(
                json.dumps(figures(got["1 thread"]), default=str) == json.dumps(figures(got["2 threads"]), default=str)
            )
    print(f"clips: {len(items)} (6 cameras x 17 frames, 320x192), load average {os.getloadavg()[0]:.1f}")
    for name in runs:
        wall, cpu = float(np.median(walls[name])), float(np.median(cpus[name]))
        print(
            f"  {name:9s} median wall {wall:6.1f} s/clip = {wall / CLIP_GOAL_S:.2f}x the {CLIP_GOAL_S:.0f} s goal, "
            f"cpu {cpu:6.1f} s; pose success {np.mean(success[name]):.2f}, ATE mean {np.nanmean(ates[name]):.4f} "
            f"max {np.nanmax(ates[name]):.4f} m"
        )
    one, two = float(np.median(walls["1 thread"])), float(np.median(walls["2 threads"]))
    print(
        f"  one clip on 2 cores: 2 threads {one / two:.2f}x faster than 1 (wall medians); 2 clips in parallel on one "
        f"thread each: {float(np.median(cpus['1 thread'])) / 2 / CLIP_GOAL_S:.2f}x the goal per clip (cpu / 2); "
        f"figures identical on 1 and 2 threads: {all(same)}"
    )
    ratio = float(np.median(cpus["colmap"])) / float(np.median(cpus["1 thread"]))
    print(f"  speed-up shared / colmap features (cpu medians, 1 thread): {ratio:.2f}x")


def bench_dashcam() -> None:
    """The 221-frame dashcam clip (TSE and pose, one process, one core) with the protocol and with
    COLMAP's 50 Ceres iterations per global bundle adjustment (the protocol before), interleaved;
    the seconds against the 60 s goal, and how far apart the two camera paths are."""
    from drivewm.eval.config import EvalConfig, PoseConfig
    from drivewm.eval.inputs import load_items
    from drivewm.eval.trajectory_errors import ate

    item = load_items(DASHCAM, "front1", fit="stretch")[0]
    item.videos()
    frames = len(next(iter(item.videos().values())))
    protocol = EvalConfig(metrics=["tse", "pose"])
    runs = {
        "protocol, 2 threads": (protocol, 2),
        "protocol, 1 thread": (protocol, 1),
        "ba_50_iterations, 2 threads": (
            EvalConfig(metrics=["tse", "pose"], pose=PoseConfig(ba_global_max_iterations=50)),
            2,
        ),
    }
    paths = {}
    for name, (cfg, threads) in runs.items():
        wall, cpu, result = timed(item, cfg, threads)
        m, paths[name] = result.metrics, result.artifacts["sfm"].T_world_from_cam["CAM_FRONT"]
        parts = ", ".join(f"{k} {v:.1f}" for k, v in m["seconds"].items())
        print(
            f"dashcam {name:27s}: {frames} frames 960x540, wall {wall:.1f} s ({parts}) = {wall / DASHCAM_GOAL_S:.2f}x "
            f"the {DASHCAM_GOAL_S:.0f} s goal, cpu {cpu:.1f} s; "
            f"registered {m['registered_fraction']:.2f}, TSE {m['tse']:.4f}, load {os.getloadavg()[0]:.1f}"
        )
    same = np.array_equal(paths["protocol, 1 thread"], paths["protocol, 2 threads"], equal_nan=True)
    print(f"  camera paths on 1 and 2 threads identical: {same}")
    est, ref = paths["protocol, 2 threads"], paths["ba_50_iterations, 2 threads"]
    if np.isfinite(est).all() and np.isfinite(ref).all():
        err, _ = ate(est, ref)
        length = float(np.sum(np.linalg.norm(np.diff(ref[:, :3, 3], axis=0), axis=1)))
        print(f"  camera paths after a similarity alignment: {100 * err / length:.3f}% of the path length apart")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--clips", type=int, default=2, help="simulated 17-frame clips to time")
    parser.add_argument("--clip-dir", type=Path, help="score these clips instead (e.g. the reference set's)")
    parser.add_argument("--dashcam", action="store_true", help="also time the 221-frame real dashcam clip")
    args = parser.parse_args()
    cores = len(os.sched_getaffinity(0))
    print(f"{cores} cores available to this process ({os.cpu_count()} on the machine)")
    before = cpu_ticks()
    bench_clips(args.clips, args.clip_dir)
    if args.dashcam:
        bench_dashcam()
    print(machine_share(before, cpu_ticks()))


def cpu_ticks() -> list[int] | None:
    """The machine's CPU ticks by kind (/proc/stat: user nice system idle iowait irq softirq steal), None off Linux."""
    try:
        return [int(x) for x in Path("/proc/stat").read_text().split("\n")[0].split()[1:9]]
    except OSError:
        return None


def machine_share(before: list[int] | None, after: list[int] | None) -> str:
    """How busy the whole machine was during the run and how much the hypervisor took (steal): a
    load average does not show another tenant, and steal stretches every wall time."""
    if before is None or after is None:
        return "machine CPU shares: not available"
    d = [b - a for a, b in zip(before, after)]
    total = sum(d) or 1
    return (
        f"machine CPU during the run: busy {100 * (total - d[3] - d[4]) / total:.0f}%, steal {100 * d[7] / total:.1f}%"
    )


if __name__ == "__main__":
    main()
