"""Scenario-conditioned generation scored against the simulator's truth (issue 66's figures).

Held-out drive windows (one condition's clips of a held-out folder, spread over drives) are regenerated
in each asked condition twice: by a layout model from each window's layout, and by a baseline model
(default ``shipped:multiview``) from the same prompt and the window's own ego path without a layout.
Both are sampled the same way (plain sampling, no post-steps: the network's own frames), keep the
window's pair id, and are scored by ``drivewm judge score`` (PSNR, SSIM, the layout judge's mIoU on
generated frames against on the true frames) and by ``drivewm eval`` (geometry, adherence), beside
``drivewm eval`` of the true clips of the same windows in the same conditions.

    python benchmarks/bench_layout_truth.py --model LAYOUT_MV --heldout HELDOUT_CLIPS --out OUT \\
        [--baseline shipped:multiview] [--windows 3] [--steps 35] [--judge shipped:judge]

Writes OUT/summary.json and prints one table; ~1 minute per generated clip on 2 CPU cores at 160x96.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

from drivewm.atomic import write_json
from drivewm.clips.shards import ShardWriter, iter_clips
from drivewm.generate.config import GenerateConfig, SamplingConfig
from drivewm.generate.multiview import Conditions
from drivewm.generate.protocol import GenerateRequest
from drivewm.generate.registry import load_generator
from drivewm.layout.sources import layouts_from_clips
from drivewm.model_folders import resolve_model_folder
from drivewm.multiview.trajectories import resample_waypoints

PROMPTS = ["heavy snow during the day", "clear weather at night", "dense fog during the day"]


def pick_windows(heldout: Path, out: Path, n: int, condition: tuple[str, str]) -> Path:
    """Copy ``n`` clips of ``heldout`` in ``condition``, spread over its drives, into OUT/sources."""
    clips = [
        c for c in iter_clips(heldout) if (c.meta.tags.get("weather"), c.meta.tags.get("time_of_day")) == condition
    ]
    by_drive: dict[str, list] = {}
    for c in clips:
        by_drive.setdefault(c.meta.pair_id.rsplit("-t", 1)[0], []).append(c)
    picked = []
    while len(picked) < n and any(by_drive.values()):
        for drive in list(by_drive):
            if by_drive[drive] and len(picked) < n:
                picked.append(by_drive[drive].pop(len(by_drive[drive]) // 2))
    sources = out / "sources"
    with ShardWriter(sources, "sources") as writer:
        for c in picked:
            writer.write(c)
    return sources


def generate(model: str, sources: Path, out: Path, prompts: list[str], steps: int, with_layout: bool) -> Path:
    """Every window of ``sources`` in every prompt's condition, along the window's own ego path."""
    gen = load_generator(resolve_model_folder(model), "cpu")
    cfg = GenerateConfig(sampling=SamplingConfig(steps=steps))
    mv = gen.model.cfg.multiview
    rig = gen.model.training_rig
    samples = []
    for i, (source, prompt) in enumerate((s, p) for s in layouts_from_clips(sources) for p in prompts):
        cond = gen.layout_conditions(rig, source)
        if not with_layout:
            cond = Conditions(rig, resample_waypoints(source.waypoints, mv.trajectory_waypoints), cond.speed_mps, None)
        sample = gen.sample(prompt, cfg.sampling.seed + i, cond, GenerateRequest([prompt]), cfg)
        sample.extra.update(layout=source.key, pair_id=source.pair_id, with_layout=with_layout)
        samples.append(sample)
    gen.write(samples, out)
    return out


def run(args: list[str]) -> None:
    print("$ drivewm", " ".join(args), flush=True)
    subprocess.run([sys.executable, "-m", "drivewm.cli", *args], check=True)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--model", required=True)
    p.add_argument("--baseline", default="shipped:multiview")
    p.add_argument("--heldout", required=True, type=Path)
    p.add_argument("--out", required=True, type=Path)
    p.add_argument("--windows", type=int, default=3)
    p.add_argument("--steps", type=int, default=35)
    p.add_argument("--judge", default="shipped:judge")
    p.add_argument("--prompt", action="append", help=f"asked conditions (default {PROMPTS})")
    args = p.parse_args()
    prompts = args.prompt or PROMPTS
    sources = pick_windows(args.heldout, args.out, args.windows, ("clear", "day"))
    runs = {
        "layout": generate(args.model, sources, args.out / "layout", prompts, args.steps, True),
        "baseline": generate(args.baseline, sources, args.out / "baseline", prompts, args.steps, False),
    }
    summary = {}
    for name, folder in runs.items():
        run(
            [
                "judge",
                "score",
                str(folder),
                "--truth",
                str(args.heldout),
                "--model",
                args.judge,
                "--out",
                str(folder / "truth"),
            ]
        )
        run(["eval", str(folder), "--out", str(folder / "eval")])
        summary[name] = {
            "truth": json.loads((folder / "truth" / "scores.json").read_text()),
            "eval": json.loads((folder / "eval" / "metrics.json").read_text()),
        }
    write_json(args.out / "summary.json", summary)
    print(json.dumps({k: v["truth"].get("overall", v["truth"].get("summary")) for k, v in summary.items()}, indent=1))


if __name__ == "__main__":
    main()
