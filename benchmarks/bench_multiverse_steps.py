"""Quality and time of ``drivewm multiverse --renderer model`` against the sampler's step count.

The futures of bench_multiverse.py's recorded nuscenes6 drive (five plans, branched at 2 s) are generated
by a multi-view model (``--renderer model``; drivewm.multiverse.model_cameras) at each ``--steps`` count
with the model's own sampler (generate's defaults: Heun, guidance 7), and scored on the network's own
frames (no post-step), every camera of every future, against two references:

- ``truth``: the simulator's renderer drawing the same future at the model's frame size (what the
  futures' layouts look like; the shipped model is not conditioned on road users, so this is a floor
  that mostly measures the look);
- ``most steps``: the same futures generated with the most steps of the list (how far fewer steps move
  the frames from what the default gives).

PSNR in dB and SSIM (drivewm.tokenizer.metrics) over the futures' frames; CPU and wall seconds per window
(one 17-frame window of all six cameras) with ``--threads`` torch threads.

    python benchmarks/bench_multiverse_steps.py --model shipped:multiview --steps 35,6,10,20 --horizon 1.6
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import tempfile
import time
from pathlib import Path

os.environ.setdefault("SDL_VIDEODRIVER", "offscreen")
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # idle OpenMP threads sleep (bench_multiverse.py)

import numpy as np  # noqa: E402
import torch  # noqa: E402

from drivewm.model_folders import resolve_model_folder  # noqa: E402
from drivewm.multiverse import MultiverseConfig  # noqa: E402
from drivewm.multiverse.cameras import SimCameras  # noqa: E402
from drivewm.multiverse.model_cameras import ModelCameras, load_world_model  # noqa: E402
from drivewm.multiverse.replay import branch_log  # noqa: E402
from drivewm.sim import SimConfig, simulate  # noqa: E402
from drivewm.tokenizer.metrics import psnr, ssim  # noqa: E402

PLANS = ["keep", "left", "right", "brake", "accelerate"]


def as_video(frames: list[dict[str, np.ndarray]]) -> torch.Tensor:
    """Per future {camera: uint8 (T, H, W, 3)} -> one float video (N, 3, T, H, W) in [-1, 1]."""
    views = [torch.from_numpy(v) for f in frames for v in f.values()]
    return torch.stack(views).permute(0, 4, 1, 2, 3).float() / 127.5 - 1


def scores(x: torch.Tensor, ref: torch.Tensor) -> dict[str, float]:
    return {"psnr_db": round(psnr(x, ref), 3), "ssim": round(float(ssim(x, ref)), 4)}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", default="shipped:multiview")
    p.add_argument("--steps", default="35,6,10,20", help="sampler step counts, comma-separated")
    p.add_argument("--horizon", type=float, default=1.6, help="seconds per future (1.6: one window each)")
    p.add_argument("--threads", type=int, default=os.cpu_count(), help="torch threads (default: every core)")
    p.add_argument("--out", default="", help="also write the figures to this JSON file")
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    steps = [int(s) for s in args.steps.split(",")]
    generator = load_world_model(resolve_model_folder(args.model), "cpu")
    with tempfile.TemporaryDirectory(prefix="bench-multiverse-steps-") as tmp:
        drive = SimConfig(source="highway", scenario="highway", rig="nuscenes6", width=320, height=192, seed=7)
        drive.duration_s = 2.0 + args.horizon + 0.5
        log = simulate(drive, Path(tmp) / "drive.mcap", progress=False)
        cfg = MultiverseConfig(log=str(log), at_s=2.0, horizon_s=args.horizon, plans=PLANS, seed=7)
        branch = branch_log(cfg)
    generated, rows = {}, []
    for n in steps:
        cams = ModelCameras(branch, generator, cfg.prompt, cfg.seed, n, progress=False)
        w0, c0 = time.perf_counter(), time.process_time()
        generated[n] = as_video(cams.futures_frames(branch.futures))  # the past's windows timed too
        wall, cpu = time.perf_counter() - w0, time.process_time() - c0
        k = cams.windows_sampled
        rows.append({"steps": n, "windows": k, "cpu_s_per_window": cpu / k, "wall_s_per_window": wall / k})
        print(f"{n} steps: {k} windows, {cpu / k:.1f} s CPU, {wall / k:.1f} s wall per window", flush=True)
    truth_cams = SimCameras(dataclasses.replace(branch, rig=cams.rig))
    truth = as_video([truth_cams.frames(f) for f in branch.futures])
    most = max(steps)
    for row in rows:
        row["truth"] = scores(generated[row["steps"]], truth)
        row[f"vs_{most}_steps"] = scores(generated[row["steps"]], generated[most]) if row["steps"] != most else None
    print(f"{args.model}, {generator.model.cfg.multiview.temporal_compression}x frames, {args.threads} thread(s):")
    for row in sorted(rows, key=lambda r: r["steps"]):
        print(json.dumps(row))
    if args.out:
        Path(args.out).write_text(json.dumps({"model": args.model, "threads": args.threads, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
