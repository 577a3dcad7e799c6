"""Seconds per clip of the consistency benchmark with its guards against the speed limits: 5 s per
6-camera 17-frame 320x192 clip and 60 s for the 221-frame real dashcam clip, on 2 cores (issue 69).

Scores the simulated clips of ``--clip-dir`` (default: the test suite's cached clips,
tests/conftest.py::sim_clips(), built on first use; ``--clips`` of them, spread) with the full
protocol (TSE, CSE, pose, trajectory) on 2 threads (``evaluate_item(threads=2)``: one clip's
features, matches and F fits over both cores, COLMAP's one-thread mapping beside TSE and CSE),
``--repeats`` times each, interleaved, after one untimed warm-up clip (lazy imports). Prints each
timing with its parts (``seconds``: features, TSE with its motion and direction guards, CSE, pose's
database and mapping, the pose plausibility check) and the guards' verdicts, then the median wall
per clip against the limit. ``--peers`` adds, interleaved, the protocol on one thread and with
COLMAP's own extraction and matching (``colmap``, the protocol before issue 14): wall and CPU
medians, pose success and ATE per run, the speed-up of 2 threads over 1, whether the one- and
two-thread figures are identical (they must be) and the CPU ratio colmap / shared features.

``--dashcam`` also times ../shared/data's 221-frame 960x540 dashcam clip (front camera, TSE and
pose, 2 threads; with ``--peers`` also one thread and COLMAP's 50 iterations per global bundle
adjustment, and how far apart those camera paths are). The machine is shared: the load average is
printed beside every timing and the machine's busy share at the end; compare figures of one run.

    python benchmarks/bench_eval.py --clips 3 --repeats 2 --dashcam   # the limits
    python benchmarks/bench_eval.py --clips 2 --peers                 # 1 thread and colmap beside
    taskset -c 0,1 python benchmarks/bench_eval.py --dashcam          # pin to 2 cores
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("SDL_VIDEODRIVER", "offscreen")
REPO = Path(__file__).resolve().parents[1]
DASHCAM = REPO / ".." / "shared" / "data" / "video" / "dashcam_highway" / "solidWhiteRight.mp4"
CLIP_LIMIT_S, DASHCAM_LIMIT_S = 5.0, 60.0
PROTOCOL = "2 threads"


def sim_items(clip_dir: Path | None, clips: int) -> list:
    """``clips`` clips of ``clip_dir`` (default: the test suite's cached ones), spread, decoded."""
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


def timed(item, cfg, threads: int):
    """Wall seconds, CPU seconds of this process (all its threads) and the ClipResult of one clip."""
    from drivewm.eval.suite import evaluate_item

    t0, c0 = time.perf_counter(), time.process_time()
    result = evaluate_item(item, cfg, threads)
    return time.perf_counter() - t0, time.process_time() - c0, result


def figures(metrics: dict) -> str:
    """The metrics without their timings: what must not depend on the thread count."""
    return json.dumps({k: v for k, v in metrics.items() if k != "seconds"}, default=str, sort_keys=True)


def verdict(m: dict) -> str:
    keys = ("guard_motion", "guard_time", "guard_views", "pose_plausible")
    return ", ".join(f"{k} {m.get(k)}" for k in keys) + (f", voided by {m['voided_by']}" if "voided_by" in m else "")


def clip_runs(peers: bool) -> dict:
    """Run name -> (EvalConfig, threads): the protocol on 2 threads; with ``peers`` 1 thread and colmap."""
    from drivewm.eval.config import EvalConfig, PoseConfig

    metrics = ["tse", "cse", "pose", "traj"]
    runs = {PROTOCOL: (EvalConfig(metrics=metrics), 2)}
    if peers:
        runs["1 thread"] = (EvalConfig(metrics=metrics), 1)
        runs["colmap"] = (EvalConfig(metrics=metrics, pose=PoseConfig(features="colmap")), 1)
    return runs


def bench_clips(items: list, repeats: int, peers: bool) -> None:
    """Every run of :func:`clip_runs` on every clip, ``repeats`` times, interleaved (all see the same load)."""
    runs = clip_runs(peers)
    warm, _, _ = timed(items[0], runs[PROTOCOL][0], 2)  # the eval's lazy imports (torch) are no clip's time
    print(f"  warm-up (first clip, once per process: imports), not counted: wall {warm:.1f} s", flush=True)
    walls, cpus, got = ({r: {} for r in runs} for _ in range(3))
    for _ in range(repeats):
        for item in items:
            for name, (cfg, threads) in runs.items():
                wall, cpu, result = timed(item, cfg, threads)
                m = result.metrics
                walls[name].setdefault(item.key, []).append(wall)
                cpus[name].setdefault(item.key, []).append(cpu)
                got[name][item.key] = m
                parts = ", ".join(f"{k} {v:.1f}" for k, v in m["seconds"].items())
                print(
                    f"  {item.key:24s} {name:9s} wall {wall:6.1f} s, cpu {cpu:6.1f} s ({parts}); {verdict(m)}; "
                    f"load {os.getloadavg()[0]:.1f}",
                    flush=True,
                )
    print(f"clips: {len(items)} (6 cameras x 17 frames, 320x192), {repeats} timings each")
    medians = {name: _median_of_medians(walls[name]) for name in runs}
    for name in runs:
        ms = got[name].values()
        print(
            f"  {name:9s} median wall {medians[name]:6.2f} s/clip = {medians[name] / CLIP_LIMIT_S:.2f}x the "
            f"{CLIP_LIMIT_S:.0f} s limit, cpu {_median_of_medians(cpus[name]):6.2f} s; pose success "
            f"{np.mean([m['pose_success'] for m in ms]):.2f}, ATE mean {np.nanmean([m['ate'] for m in ms]):.4f} "
            f"max {np.nanmax([m['ate'] for m in ms]):.4f} m"
        )
    if peers:
        _peer_ratios(walls, cpus, got)


def _median_of_medians(by_clip: dict[str, list[float]]) -> float:
    """The median over clips of each clip's median timing."""
    return float(np.median([np.median(v) for v in by_clip.values()]))


def _peer_ratios(walls: dict, cpus: dict, got: dict) -> None:
    one, two = _median_of_medians(walls["1 thread"]), _median_of_medians(walls[PROTOCOL])
    same = all(figures(got["1 thread"][k]) == figures(got[PROTOCOL][k]) for k in got[PROTOCOL])
    cpu_one = _median_of_medians(cpus["1 thread"])
    print(
        f"  one clip on 2 cores: 2 threads {one / two:.2f}x faster than 1 (wall medians); 2 clips in parallel on one "
        f"thread each: {cpu_one / 2 / CLIP_LIMIT_S:.2f}x the limit per clip (cpu / 2); figures identical on 1 and "
        f"2 threads: {same}"
    )
    ratio = _median_of_medians(cpus["colmap"]) / cpu_one
    print(f"  speed-up shared / colmap features (cpu medians, 1 thread): {ratio:.2f}x")


def bench_dashcam(path: Path, repeats: int, peers: bool) -> None:
    """The 221-frame dashcam clip (TSE and pose) on 2 threads, ``repeats`` times; with ``peers``
    interleaved with one thread and COLMAP's 50 Ceres iterations per global bundle adjustment, and
    how far apart those camera paths are."""
    from drivewm.eval.config import EvalConfig, PoseConfig
    from drivewm.eval.inputs import load_items

    item = load_items(path, "front1", fit="stretch")[0]
    frames = len(next(iter(item.videos().values())))
    runs = {PROTOCOL: (EvalConfig(metrics=["tse", "pose"]), 2)}
    if peers:
        runs["1 thread"] = (EvalConfig(metrics=["tse", "pose"]), 1)
        runs["ba 50 iterations"] = (
            EvalConfig(metrics=["tse", "pose"], pose=PoseConfig(ba_global_max_iterations=50)),
            2,
        )
    walls, paths = {name: [] for name in runs}, {}
    for _ in range(repeats):
        for name, (cfg, threads) in runs.items():
            wall, cpu, result = timed(item, cfg, threads)
            m, paths[name] = result.metrics, result.artifacts["sfm"].T_world_from_cam["CAM_FRONT"]
            walls[name].append(wall)
            parts = ", ".join(f"{k} {v:.1f}" for k, v in m["seconds"].items())
            print(
                f"  dashcam {name:16s}: {frames} frames 960x540, wall {wall:.1f} s, cpu {cpu:.1f} s ({parts}); "
                f"registered {m['registered_fraction']:.2f}, TSE {m['tse']:.4f}; {verdict(m)}; "
                f"load {os.getloadavg()[0]:.1f}",
                flush=True,
            )
    for name, w in walls.items():
        d = float(np.median(w))
        print(
            f"dashcam {name:16s}: median wall {d:.1f} s = {d / DASHCAM_LIMIT_S:.2f}x the {DASHCAM_LIMIT_S:.0f} s limit"
        )
    if peers:
        _path_agreement(paths)


def _path_agreement(paths: dict) -> None:
    from drivewm.eval.trajectory_errors import ate

    same = np.array_equal(paths["1 thread"], paths[PROTOCOL], equal_nan=True)
    print(f"  camera paths on 1 and 2 threads identical: {same}")
    est, ref = paths[PROTOCOL], paths["ba 50 iterations"]
    if np.isfinite(est).all() and np.isfinite(ref).all():
        err, _ = ate(est, ref)
        length = float(np.sum(np.linalg.norm(np.diff(ref[:, :3, 3], axis=0), axis=1)))
        print(f"  camera paths after a similarity alignment: {100 * err / length:.3f}% of the path length apart")


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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--clips", type=int, default=2, help="simulated clips to time")
    parser.add_argument("--clip-dir", type=Path, help="score these clips (default: the test suite's cached clips)")
    parser.add_argument("--repeats", type=int, default=2, help="timings per clip and run, interleaved")
    parser.add_argument("--peers", action="store_true", help="also one thread and the colmap / 50-iteration peers")
    parser.add_argument("--dashcam", action="store_true", help="also time the 221-frame real dashcam clip")
    parser.add_argument("--dashcam-path", type=Path, default=DASHCAM, help="where that clip is (../shared/data)")
    args = parser.parse_args()
    print(f"{len(os.sched_getaffinity(0))} cores available to this process ({os.cpu_count()} on the machine)")
    before = cpu_ticks()
    bench_clips(sim_items(args.clip_dir, args.clips), args.repeats, args.peers)
    if args.dashcam:
        bench_dashcam(args.dashcam_path, args.repeats, args.peers)
    print(machine_share(before, cpu_ticks()))


if __name__ == "__main__":
    main()
