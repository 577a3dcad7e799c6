"""Curation throughput against raw decoding, where the time goes, output quality, 1 vs 2 workers,
and (``--hour``) an hour-long 6-camera log in bounded memory.

Everything is measured in this run on the same input, in interleaved rounds (medians):

- raw decode: drivewm's image stream of every log (MCAP + protobuf) and one JPEG decode per
  image (``ImageFrame.decode``): the least any curation must do;
- raw decode straight to RGB (``cv2.IMREAD_COLOR_RGB``, no BGR -> RGB copy): the same pixels a
  little cheaper, as curation decodes them, printed beside the baseline (which stays as it was);
- ``drivewm curate`` with the packaged ``default`` and ``fleet`` recipes (drivewm/recipes/curate/) on
  one local worker and the fleet recipe on two, at the logs' size and at 160x96 (the team's clip
  size: ``--set resolution=[160,96] crf=12 h264_yuv_converter=swscale``, JPEGs decoded at 1/2 scale in
  the DCT domain);
- per step CPU seconds per camera-frame (the stage's own StepClock: index, read, decode, resize,
  shots, filters, encode, write, other) and "outside": the run's CPU outside the per-log stage
  (contact sheet, manifest, report: a fixed cost per run);
- ``--scaling-seconds S``: 1 vs 2 workers on the logs looped to S seconds, timed twice: in this process
  (one worker then has the stage's imports already; two pay a fresh fork server's every run) and as
  fresh ``drivewm curate`` processes beside a fresh raw-decode process, where start-up costs every run alike
  (reading compiled bytecode, as a pip install leaves it);
- PSNR of the encoded clips against the log's frames at each camera's exposure times (decoded in
  full, INTER_AREA-resized to the clip's size), with the H.264 settings that produced them, and of
  the 1/2-scale JPEG decode against full decode + INTER_AREA.

On a machine shared with other jobs, wall-clock ratios move with the load; CPU seconds per
camera-frame (this process and its workers) move much less, so both are printed, and beside each run
the cores other processes kept busy while it ran (/proc/stat less this process tree; 0 when idle).

    python benchmarks/bench_curate.py                 # 4 simulated nuscenes6 drives of 20 s
    python benchmarks/bench_curate.py --hour          # + a 1 h, 6-camera log (looped frames)
    python benchmarks/bench_curate.py --drives 2 --duration 15 --rounds 2 --skip-throughput --scaling-seconds 600
    python benchmarks/bench_curate.py --logs DIR      # your own MCAP logs instead of simulating
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("SDL_VIDEODRIVER", "offscreen")
REPO = Path(__file__).resolve().parents[1]
RECIPES = ("default", "fleet")  # packaged curate recipes (drivewm/recipes/curate/)
#: the runs at the team's clip size: the fleet recipe at 160x96 (swscale: OpenCV's centred chroma costs ~3 dB there)
SMALL = ["resolution=[160,96]", "crf=12", "h264_yuv_converter=swscale"]
SCENARIOS = ["highway", "roundabout", "merge", "intersection"]


def simulate_logs(out: Path, drives: int, duration_s: float) -> list[Path]:
    """``drives`` nuscenes6 highway-env drives (kept in ``out`` for reruns)."""
    from drivewm.sim import SimConfig, simulate

    paths = []
    for i in range(drives):
        path = out / f"drive{i}_{duration_s:g}s.mcap"
        if not path.is_file():
            cfg = SimConfig(source="highway", scenario=SCENARIOS[i % 4], duration_s=duration_s, seed=i)
            simulate(cfg, path, progress=False)
        paths.append(path)
    return paths


class Meter:
    """Wall seconds and CPU seconds of this process plus its finished children (pool workers), and ``others``:
    the cores other processes on the machine kept busy meanwhile (1.0 = one core; 0 on an idle machine)."""

    def __enter__(self) -> Meter:
        self.wall, self.cpu, self.busy = time.perf_counter(), self._cpu(), self._machine_busy()
        return self

    def __exit__(self, *exc) -> None:
        self.wall, self.cpu = time.perf_counter() - self.wall, self._cpu() - self.cpu
        self.others = max(0.0, self._machine_busy() - self.busy - self.cpu) / self.wall

    @staticmethod
    def _cpu() -> float:
        kids = resource.getrusage(resource.RUSAGE_CHILDREN)
        return time.process_time() + kids.ru_utime + kids.ru_stime

    @staticmethod
    def _machine_busy() -> float:
        """CPU seconds all processes have used since boot (/proc/stat: all but idle and iowait)."""
        with open("/proc/stat") as f:
            ticks = [int(v) for v in f.readline().split()[1:]]
        return (sum(ticks) - ticks[3] - ticks[4]) / os.sysconf("SC_CLK_TCK")


def raw_decode(logs: list[Path]) -> int:
    """Stream every image of every log and decode it once; returns the camera-frame count."""
    from drivewm.logs.reader import LogStream

    frames = 0
    for path in logs:
        for _, (_, frame) in LogStream(path).stream(("image",)):
            frame.decode()
            frames += 1
    return frames


def raw_decode_rgb(logs: list[Path]) -> int:
    """As :func:`raw_decode`, decoding straight to RGB (the pixels of ``ImageFrame.decode``)."""
    import cv2

    from drivewm.logs.reader import LogStream

    frames = 0
    for path in logs:
        for _, (_, frame) in LogStream(path).stream(("image",)):
            cv2.imdecode(np.frombuffer(frame.data, np.uint8), cv2.IMREAD_COLOR_RGB)
            frames += 1
    return frames


def reduced_decode(logs: list[Path], size: tuple[int, int], rounds: int) -> None:
    """CPU ms per image and PSNR of JPEGs decoded at a reduced DCT scale to ``size`` against full decode +
    INTER_AREA (drivewm.curate.images), interleaved rounds over the first log's images."""
    import cv2

    from drivewm.curate.images import decode_rgb, fit, jpeg_scale
    from drivewm.logs.reader import read_log

    log = read_log(logs[0])
    frames = [f for fs in log.images.values() for f in fs]
    cam = log.rig.cameras[0]
    scale = jpeg_scale((cam.width, cam.height), size)
    full = lambda f: cv2.resize(f.decode(), size, interpolation=cv2.INTER_AREA)  # noqa: E731
    reduced = lambda f: fit(decode_rgb(f, size, scale), size)  # noqa: E731
    ms = {"full": [], "reduced": []}
    for _ in range(rounds):
        for name, fn in (("full", full), ("reduced", reduced)):
            c0 = time.process_time()
            for f in frames:
                fn(f)
            ms[name].append(1e3 * (time.process_time() - c0) / len(frames))
    mse = [np.mean((reduced(f).astype(np.float64) - full(f)) ** 2) for f in frames[::7]]
    print(
        f"\nJPEG {cam.width}x{cam.height} -> {size[0]}x{size[1]}: full decode + INTER_AREA "
        f"{np.median(ms['full']):.3f} CPU ms per image, 1/{scale} DCT-scaled decode (+ INTER_AREA) "
        f"{np.median(ms['reduced']):.3f} ms ({np.median(ms['full']) / np.median(ms['reduced']):.2f}x); "
        f"PSNR of the reduced against the full {10 * np.log10(255.0**2 / np.mean(mse)):.2f} dB"
    )


def curate_run(logs: list[Path], out: Path, recipe: str, workers: int, overrides: list[str] = ()) -> dict:
    from drivewm.curate import curate, load_curate_config

    shutil.rmtree(out, ignore_errors=True)
    cfg = load_curate_config(recipe, list(overrides))
    report = curate(logs, out, cfg, executor="local", workers=workers, progress=False)
    if workers > 1:
        stop_fork_server()
    return report


def stop_fork_server() -> None:
    """Stop this process's pool fork server (drivewm.workers), as the end of a ``drivewm curate`` process
    does: each pool run then pays the server's imports once, as a CLI run does, and the CPU of the server
    and of its workers (which it reaps) reaches this process's RUSAGE_CHILDREN only once it is reaped."""
    import multiprocessing.forkserver

    multiprocessing.forkserver._forkserver._stop()  # CPython's own stop (used by its tests); no public one


def step_ms(report: dict, frames: int) -> dict[str, float]:
    """CPU ms per camera-frame by step, summed over the report's logs."""
    from drivewm.curate.timing import STEPS

    total = {k: 0.0 for k in STEPS}
    for log in report["logs"].values():
        for k, v in log.get("cpu_s", {}).items():
            total[k] += v
    return {k: 1e3 * v / frames for k, v in total.items() if v}


def clip_psnr(out: Path, logs: list[Path], max_clips: int = 6) -> tuple[float, float, float]:
    """(mean PSNR dB, min PSNR dB, mean kB per camera video) of up to ``max_clips`` clips against
    the log frames at each camera's exposure times (decoded in full, INTER_AREA-resized to the clip's size)."""
    import cv2

    from drivewm.clips import iter_clips
    from drivewm.logs.reader import read_log

    by_name = {p.name: read_log(p) for p in logs}
    psnrs, sizes = [], []
    for clip in list(iter_clips(out))[:max_clips]:
        log = by_name[Path(clip.meta.source_log).name]
        for cam in clip.meta.cameras:
            frames = {f.timestamp_ns: f for f in log.images[cam]}
            size = tuple(clip.video(cam).shape[2:0:-1])  # (W, H)
            source = np.stack(
                [
                    cv2.resize(frames[t].decode(), size, interpolation=cv2.INTER_AREA)
                    for t in clip.meta.camera_times_ns(cam)
                ]
            )
            mse = np.mean((clip.video(cam).astype(np.float64) - source) ** 2, axis=(1, 2, 3))
            psnrs += list(10 * np.log10(255.0**2 / np.maximum(mse, 1e-12)))
            sizes.append(len(clip.mp4[cam]) / 1e3)
    return float(np.mean(psnrs)), float(np.min(psnrs)), float(np.mean(sizes))


def throughput(logs: list[Path], work: Path, rounds: int, max_workers: int = 2) -> None:
    import cv2

    cv2.setNumThreads(1)  # one core per worker, as the pool's workers run
    runs = {
        "raw decode": None,
        "raw decode, RGB": None,
        "default, 1 worker": ("default", 1, []),
        "fleet, 1 worker": ("fleet", 1, []),
        "fleet, 2 workers": ("fleet", 2, []),
        "fleet 160x96, 1 worker": ("fleet", 1, SMALL),
        "fleet 160x96, 2 workers": ("fleet", 2, SMALL),
    }
    runs = {k: spec for k, spec in runs.items() if spec is None or spec[1] <= max_workers}
    wall = {k: [] for k in runs}
    cpu = {k: [] for k in runs}
    others = {k: [] for k in runs}
    steps: dict[str, list[dict]] = {k: [] for k, spec in runs.items() if spec is not None and spec[1] == 1}
    stage_cpu = {k: [] for k in runs if runs[k] is not None}  # StepClock ms per camera-frame, without start-up
    frames, reports = 0, {}
    for r in range(rounds):
        for name, spec in runs.items():
            with Meter() as m:
                if spec is None:
                    frames = (raw_decode_rgb if name.endswith("RGB") else raw_decode)(logs)
                else:
                    reports[name] = curate_run(logs, _out(work, name), *spec)
            wall[name].append(m.wall)
            cpu[name].append(m.cpu)
            others[name].append(m.others)
            if spec is not None:
                stage = step_ms(reports[name], frames)
                stage_cpu[name].append(sum(stage.values()))
                if spec[1] == 1:  # in-process: the run's CPU outside the per-log stage is the rest
                    steps[name].append({**stage, "outside": 1e3 * m.cpu / frames - sum(stage.values())})
        print(f"  round {r + 1}/{rounds}: " + ", ".join(f"{k} {wall[k][-1]:.1f} s" for k in runs), flush=True)
    med = {k: float(np.median(v)) for k, v in wall.items()}
    med_cpu = {k: float(np.median(v)) for k, v in cpu.items()}
    kept = {k: reports[k]["kept"] for k in reports}
    print(f"\ninput: {len(logs)} logs, {frames} camera-frames; clips kept {kept}")
    print(
        f"{'':24s} {'cam-frames/s':>12s} {'x raw (wall)':>12s} {'CPU ms/frame':>13s} {'x raw (CPU)':>12s} "
        f"{'other jobs (cores)':>19s}"
    )
    for k in runs:
        print(
            f"{k:24s} {frames / med[k]:12.1f} {med['raw decode'] / med[k]:12.2f} "
            f"{1e3 * med_cpu[k] / frames:13.3f} {med_cpu['raw decode'] / med_cpu[k]:12.2f} {_spread(others[k]):>19s}"
        )
    steady = {k: float(np.median(v)) for k, v in stage_cpu.items()}
    pairs = (("fleet, 1 worker", "fleet, 2 workers"), ("fleet 160x96, 1 worker", "fleet 160x96, 2 workers"))
    for one, two in (pair for pair in pairs if pair[1] in runs):
        print(
            f"1 -> 2 workers ({one.split(',')[0]}): {med[one] / med[two]:.2f}x wall, "
            f"{med_cpu[one] / med_cpu[two]:.2f}x CPU per frame, on {os.cpu_count()} CPUs (load average now "
            f"{os.getloadavg()[0]:.1f}); stage CPU ms per camera-frame per worker (StepClock, no process start-up): "
            f"{steady[one]:.3f} with 1 worker, {steady[two]:.3f} with 2"
        )
    stage, smoother = worker_startup_cpu_s()
    print(
        f"a pool's fork server imports the stage ({stage:.2f} CPU s) and filterpy ({smoother:.2f} s) once per run, "
        f"i.e. {1e3 * (stage + smoother) / frames:.3f} ms per camera-frame of this input, whatever the workers "
        f"(spawned, each of 2 workers paid it: {1e3 * 2 * (stage + smoother) / frames:.3f} ms); 1 worker runs "
        "in-process"
    )
    print("\nwhere the CPU goes, ms per camera-frame (medians over rounds, stage StepClock; outside: rest of the run):")
    names = sorted({k for rows in steps.values() for row in rows for k in row}, key=_step_order)
    print(f"{'run':24s} " + " ".join(f"{k:>8s}" for k in names) + f" {'total':>8s}")
    for run, rows in steps.items():
        vals = [float(np.median([row.get(k, 0.0) for row in rows])) for k in names]
        print(f"{run:24s} " + " ".join(f"{v:8.3f}" for v in vals) + f" {sum(vals):8.3f}")
    print(f"raw decode total {1e3 * med_cpu['raw decode'] / frames:.3f} ms per camera-frame (read + decode)")
    print("\nH.264 output (yuv420p, no B-frames, tune zerolatency) against the source frames:")
    from drivewm.curate import load_curate_config

    for run, (recipe, _, overrides) in ((k, v) for k, v in runs.items() if v is not None and v[1] == 1):
        cfg = load_curate_config(recipe, overrides)
        mean, low, kb = clip_psnr(_out(work, run), logs)
        threads = cfg.h264_threads or "x264 auto"
        size = "x".join(map(str, cfg.resolution)) if cfg.resolution else "log size"
        print(
            f"  {run:24s} {size}, preset {cfg.h264_preset}, crf {cfg.crf}, threads {threads}, RGB->YUV "
            f"{cfg.h264_yuv_converter}, encoder kept {cfg.h264_keep_encoder}: PSNR mean {mean:.2f} dB, "
            f"min {low:.2f} dB, {kb:.0f} kB per camera per {cfg.clip_frames}-frame clip"
        )
    reduced_decode(logs, (160, 96), rounds)


def _spread(values: list[float]) -> str:
    """Per-round values as "median (min-max)"."""
    return f"{np.median(values):.2f} ({min(values):.2f}-{max(values):.2f})"


def _out(work: Path, run: str) -> Path:
    return work / run.replace(", ", "_").replace(" ", "")


def worker_startup_cpu_s() -> tuple[float, float]:
    """CPU seconds a fresh interpreter spends importing the per-log stage and then filterpy (scipy.stats), as a
    pool's fork server does once (drivewm.curate.pool.WORKER_PRELOAD) and each spawned worker did."""
    code = (
        "import time; import drivewm.curate.executors; a = time.process_time(); import filterpy.kalman; "
        "print(a, time.process_time() - a)"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    stage, smoother = proc.stdout.split()[-2:]
    return float(stage), float(smoother)


def _step_order(name: str) -> int:
    from drivewm.curate.timing import STEPS

    order = (*STEPS, "outside")
    return order.index(name) if name in order else len(order)


def write_hour_log(source: Path, out: Path, seconds: float) -> Path:
    """A long log from a short one: its images again and again with advancing timestamps, the ego
    pose continuing rigidly from where the last loop ended (written message by message)."""
    from drivewm.geometry import invert_T
    from drivewm.logs.reader import read_log
    from drivewm.logs.writer import LogWriter

    log = read_log(source)
    ts, T = log.pose_timestamps_ns, log.T_world_from_ego
    period = int(np.median(np.diff(ts)))
    n, loops = len(ts), int(np.ceil(seconds * 1e9 / (period * len(ts))))
    step = T[-1] @ invert_T(T[0])  # loop k starts where loop k - 1 ended
    frames = {cam: {f.timestamp_ns: f for f in fs} for cam, fs in log.images.items()}
    with LogWriter(out, log.rig, log.scene) as writer:
        D = np.eye(4)
        for k in range(loops):
            for i in range(n):
                t = int(ts[0] + (k * n + i) * period)
                writer.write_pose(t, D @ T[i])
                for cam in log.rig.names:
                    f = frames[cam].get(int(ts[i]))
                    if f is not None:
                        writer.write_encoded_image(cam, t, f.data, f.format)
            D = step @ D
    return out


def scaling(logs: list[Path], work: Path, seconds: float, rounds: int) -> None:
    """1 -> 2 workers on inputs long enough to amortise a pool worker's start-up: each log looped to
    ``seconds`` (:func:`write_hour_log`, in-log dedup off as in :func:`hour`), the fleet recipe at the
    logs' size and at 160x96 on one worker (in-process) and two, interleaved against raw decode."""
    import cv2

    cv2.setNumThreads(1)
    long_logs = []
    for src in logs:
        path = work / f"loop_{seconds:g}s" / f"{src.stem}.mcap"
        if not path.is_file():
            path.parent.mkdir(parents=True, exist_ok=True)
            write_hour_log(src, path, seconds)
        long_logs.append(path)
    off = ["filters.dedup_cosine=1.0"]
    runs = {"raw decode": None}
    for name, extra in (("fleet", []), ("fleet 160x96", SMALL)):
        runs.update({f"{name}, 1 worker": ("fleet", 1, off + extra), f"{name}, 2 workers": ("fleet", 2, off + extra)})
    wall, cpu, others, frames = {k: [] for k in runs}, {k: [] for k in runs}, {k: [] for k in runs}, 0
    stage_cpu = {k: [] for k in runs if runs[k] is not None}  # StepClock ms per camera-frame, without start-up
    for r in range(rounds):
        for name, spec in runs.items():
            with Meter() as m:
                if spec is None:
                    frames = raw_decode(long_logs)
                else:
                    report = curate_run(long_logs, _out(work, f"loop {name}"), *spec)
            wall[name].append(m.wall)
            cpu[name].append(m.cpu)
            others[name].append(m.others)
            if spec is not None:
                stage_cpu[name].append(sum(step_ms(report, frames).values()))
        print(f"  round {r + 1}/{rounds}: " + ", ".join(f"{k} {wall[k][-1]:.1f} s" for k in runs), flush=True)
    med = {k: float(np.median(v)) for k, v in wall.items()}
    med_cpu = {k: float(np.median(v)) for k, v in cpu.items()}
    print(f"\nscaling: {len(long_logs)} logs looped to {seconds:g} s, {frames} camera-frames ({off})")
    for k in runs:
        print(
            f"{k:24s} {frames / med[k]:12.1f} cam-frames/s, {med['raw decode'] / med[k]:.2f}x raw (wall), "
            f"{1e3 * med_cpu[k] / frames:.3f} CPU ms per camera-frame, "
            f"{med_cpu['raw decode'] / med_cpu[k]:.2f}x raw (CPU); other jobs kept {_spread(others[k])} cores busy"
        )
    for name in ("fleet", "fleet 160x96"):
        one, two = f"{name}, 1 worker", f"{name}, 2 workers"
        steady = np.median(stage_cpu[one]), np.median(stage_cpu[two])
        print(
            f"1 -> 2 workers ({name}): {med[one] / med[two]:.2f}x wall, {med_cpu[one] / med_cpu[two]:.2f}x CPU per "
            f"frame on {os.cpu_count()} CPUs (load average now {os.getloadavg()[0]:.1f}); stage CPU ms per "
            f"camera-frame per worker: {steady[0]:.3f} with 1 worker, {steady[1]:.3f} with 2"
        )
    print(
        "  (in this process: 1 worker runs with the stage and filterpy already imported, 2 workers pay a fresh\n"
        "   fork server's imports every run; the runs below pay every import alike)"
    )
    cold(long_logs, work, rounds, off)


def cold(logs: list[Path], work: Path, rounds: int, off: list[str]) -> None:
    """1 -> 2 workers as a shell runs them: every run a fresh ``drivewm curate`` process (its start-up and
    imports included, the same for both), beside a fresh process decoding the logs raw; wall seconds,
    interleaved rounds, medians. (Wall only: a pool's workers are reaped by its fork server, which a
    finished CLI process leaves to exit on its own, so their CPU does not reach this process.)"""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), str(REPO / "benchmarks")])}
    raw = [sys.executable, "-c", RAW_SCRIPT, *map(str, logs)]
    runs = {"raw decode (fresh process)": raw}
    for name, extra in (("fleet", []), ("fleet 160x96", SMALL)):
        for n in (1, 2):
            out = _out(work, f"cold {name} {n}")
            sets = [a for kv in off + extra for a in ("--set", kv)]
            cmd = [sys.executable, "-m", "drivewm.cli", "curate", *map(str, logs), "--out", str(out)]
            runs[f"{name}, {n} worker{'s' * (n > 1)}"] = cmd + ["--recipe", "fleet", "--workers", str(n), *sets]
    wall = {k: [] for k in runs}
    for r in range(rounds):
        for name, cmd in runs.items():
            if "--out" in cmd:
                shutil.rmtree(cmd[cmd.index("--out") + 1], ignore_errors=True)
            t0 = time.perf_counter()
            proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
            wall[name].append(time.perf_counter() - t0)
            if proc.returncode != 0:
                raise SystemExit(f"{name}: {proc.stderr[-2000:]}")
        print(f"  cold round {r + 1}/{rounds}: " + ", ".join(f"{k} {v[-1]:.1f} s" for k, v in wall.items()), flush=True)
    med = {k: float(np.median(v)) for k, v in wall.items()}
    raw_s = med["raw decode (fresh process)"]
    print("\nfresh processes (as from a shell), wall seconds, medians:")
    for k, v in med.items():
        print(f"  {k:28s} {v:7.2f} s  {raw_s / v:.2f}x raw decode")
    for name in ("fleet", "fleet 160x96"):
        one, two = med[f"{name}, 1 worker"], med[f"{name}, 2 workers"]
        print(f"  1 -> 2 workers ({name}): {one / two:.2f}x wall")


#: raw decode in a fresh process, with the allocator setting every curation process makes (as main() does here)
RAW_SCRIPT = """
import sys
from drivewm.workers import reuse_freed_memory
reuse_freed_memory()
from bench_curate import raw_decode
raw_decode(sys.argv[1:])
"""


HOUR_SCRIPT = """
import json, resource, sys, time
import cv2
cv2.setNumThreads(1)
from drivewm.curate import curate, load_curate_config
cfg = load_curate_config(sys.argv[3], sys.argv[4:])
t0, c0 = time.perf_counter(), time.process_time()
report = curate([sys.argv[1]], sys.argv[2], cfg, progress=False)
log = next(iter(report["logs"].values()))
print(json.dumps({"wall_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0, "kept": report["kept"],
                  "dropped": report["dropped"], "frames": log.get("camera_frames"), "status": log["status"],
                  "error": log.get("error"), "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def hour(source: Path, work: Path, seconds: float, recipe: str) -> None:
    log = work / f"hour_{seconds:g}s.mcap"
    if not log.is_file():
        print(f"writing a {seconds:g} s log from {source.name} ...", flush=True)
        write_hour_log(source, log, seconds)
    gb = log.stat().st_size / 2**30
    with Meter() as m:
        frames = raw_decode([log])
    # within-log dedup would drop every repeated loop before encoding; off, so every window costs what new footage would
    overrides = ["filters.dedup_cosine=1.0"]
    out = work / "hour_out"
    shutil.rmtree(out, ignore_errors=True)
    cmd = [sys.executable, "-c", HOUR_SCRIPT, str(log), str(out), recipe, *overrides]
    proc = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(REPO)})
    if proc.returncode != 0:
        raise SystemExit(proc.stderr[-3000:])
    res = json.loads(proc.stdout.strip().splitlines()[-1])
    print(
        f"\nhour-long log: {seconds / 3600:.2f} h, 6 cameras, {frames} camera-frames, {gb:.2f} GB "
        f"({recipe} recipe, {overrides})"
    )
    print(f"  status {res['status']} {res['error'] or ''}; kept {res['kept']} clips, dropped {res['dropped']}")
    print(f"  peak RSS {res['peak_rss_mb']:.0f} MB (limit 2048 MB)")
    print(
        f"  curate {frames / res['wall_s']:.1f} camera-frames/s wall ({res['wall_s']:.0f} s), "
        f"{1e3 * res['cpu_s'] / frames:.3f} CPU ms per camera-frame; raw decode {frames / m.wall:.1f} camera-frames/s, "
        f"{1e3 * m.cpu / frames:.3f} CPU ms; ratio {m.wall / res['wall_s']:.2f}x wall, {m.cpu / res['cpu_s']:.2f}x CPU"
    )


def cache_bytecode(work: Path) -> Path:
    """Every process this benchmark starts (fresh ``drivewm curate`` runs, fork servers, workers) reads
    compiled bytecode, as after a pip install (pip compiles at install; Python caches what it imports).
    Where PYTHONDONTWRITEBYTECODE is set over a ``--no-compile`` install (as on the machine of the
    curate README's figures), each would first compile scipy.stats and the rest from source: ~1 CPU s
    per process. The modules a curation and the raw decode import are compiled once here, before any timed round."""
    os.environ.pop("PYTHONDONTWRITEBYTECODE", None)
    os.environ["PYTHONPYCACHEPREFIX"] = str(work / "pycache")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), str(REPO / "benchmarks")])}
    warm = (
        "from drivewm.cli import build_parser; build_parser(); import drivewm.clips.shards, drivewm.lock, "
        "drivewm.curate.contact_sheet, drivewm.curate.executors, drivewm.curate.pool, av.subtitles.stream, "
        "filterpy.kalman, bench_curate"
    )
    subprocess.run([sys.executable, "-c", warm], env=env, check=True)
    return work / "pycache"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--logs", type=Path, help="benchmark these MCAP logs instead of simulating")
    parser.add_argument("--drives", type=int, default=4, help="simulated drives (default 4)")
    parser.add_argument("--duration", type=float, default=20.0, help="seconds per simulated drive (default 20)")
    parser.add_argument("--rounds", type=int, default=3, help="interleaved rounds (default 3)")
    parser.add_argument("--hour", action="store_true", help="also curate an hour-long log in a fresh process")
    parser.add_argument("--hour-seconds", type=float, default=3600.0, help="length of that log (default 3600)")
    parser.add_argument("--hour-recipe", choices=sorted(RECIPES), default="fleet")
    parser.add_argument("--skip-throughput", action="store_true", help="only the hour-long log")
    parser.add_argument(
        "--max-workers", type=int, choices=(1, 2), default=2, help="1: leave out the 2-worker runs (default 2)"
    )
    parser.add_argument(
        "--scaling-seconds", type=float, help="also time 1 -> 2 workers on the logs looped to this length"
    )
    parser.add_argument("--work", type=Path, default=Path(tempfile.gettempdir()) / "drivewm_bench_curate")
    args = parser.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    if args.logs:
        logs = sorted(args.logs.glob("*.mcap"))
    else:
        print(f"simulating {args.drives} nuscenes6 drives of {args.duration:g} s (kept in {args.work}) ...", flush=True)
        logs = simulate_logs(args.work, args.drives, args.duration)
    print(f"machine: {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} at start")
    print(f"bytecode: compiled once, cached in {cache_bytecode(args.work)} for every process started here")
    # what every curation process sets (drivewm.curate.stage.curate_log), set first here: the raw decode
    # runs in this process too, and so reads the logs with the same allocator as curation, in every round
    from drivewm.workers import reuse_freed_memory

    print(f"malloc: freed blocks reused (glibc mallopt): {reuse_freed_memory()}")
    if not args.skip_throughput:
        throughput(logs, args.work, args.rounds, args.max_workers)
    if args.scaling_seconds:
        scaling(logs, args.work, args.scaling_seconds, args.rounds)
    if args.hour:
        hour(logs[0], args.work, args.hour_seconds, args.hour_recipe)
    print(f"load average {os.getloadavg()[0]:.1f} at the end")


if __name__ == "__main__":
    main()
