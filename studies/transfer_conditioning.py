"""Which conditioning makes a transfer model (issue 18: "choose the conditioning by measurement").

The small configuration of tests/transfer/test_must_hold.py: one simulated highway drive rendered
clear and in snow to train on, another drive (never seen) to score, both coded by the fixed pooling
stand-in tokenizer (tests/multiview/mv_standin.py), a tiny random Text2World parent. Each variant of
``transfer.*`` is post-trained from the same parent with the same steps, seed and data, then
transfers the held-out clear clip to snow and is scored against the simulator's own snow rendering
(benchmarks/transfer_benchmark.py), beside SDEdit with the parent at the same Euler steps (the same
network evaluations) and the two references (identity: the source unchanged; tokenizer: the coded
truth). CSE is left out (seconds per clip, and meaningless on 8x8 blocks: see the test's docstring).

    python studies/transfer_conditioning.py [--steps 150] [--out runs/transfer_conditioning]

Prints one row per method (PSNR, SSIM, adherence) and writes OUT/results.json.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import torch

from drivewm.atomic import write_text
from drivewm.diffusion.dit import count_parameters
from drivewm.transfer.model import Transfer
from drivewm.transfer.retarget import TargetCondition
from drivewm.transfer.sdedit import sdedit_latents
from drivewm.transfer.train import RECIPES, train_transfer

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "multiview"))
from mv_standin import PoolTokenizer, write_pooled_cache  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "transfer"))
from transfer_tiny import paired_clips, pooled_parent  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from transfer_benchmark import paired_cases, run_cases, summarize  # noqa: E402

CLEAR, SNOW = TargetCondition("clear", "day"), TargetCondition("snow", "day")

#: Variant name -> ``--set`` overrides of the transfer-train config.
VARIANTS = {
    "source channels + fields": [],
    "source channels, caption only": ["transfer.condition_fields=false"],
    "fields + caption, no source": ["transfer.source=none"],
}


def run(out: Path, steps: int) -> dict:
    train_clips, test_clips = paired_clips(out, 21), paired_clips(out, 22)
    cache = write_pooled_cache(train_clips, out / "latents", PoolTokenizer(8))
    parent = pooled_parent(out / "t2w")
    methods, params = {}, {}
    for name, overrides in VARIANTS.items():
        folder = out / name.replace(" ", "_").replace(",", "").replace("+", "and")
        sets = [f"train.steps={steps}", "train.lr=2e-3", f"train.checkpoint_every={steps}", *overrides]
        tic = time.perf_counter()
        train_transfer(RECIPES.resolve("debug", overrides=sets), out / "t2w", cache, folder)
        model = Transfer.from_pretrained(folder)
        params[name] = count_parameters(model.net)
        print(f"trained {name!r}: {params[name] / 1e3:.1f}k parameters, {time.perf_counter() - tic:.0f} s", flush=True)
        methods[name] = lambda z, c, t, seeds, m=model: m.transfer_latents(z, c, [t] * len(c), seeds, steps=4)
    for s in (0.5, 2.0, 8.0):  # the same 4 Euler steps: the same network evaluations
        methods[f"sdedit@{s:g}"] = lambda z, c, t, seeds, s=s: sdedit_latents(parent, z, c, seeds, s, steps=4)
    cases = paired_cases(test_clips, CLEAR, [SNOW])
    summary = summarize(run_cases(cases, methods, PoolTokenizer(8), cse_for=set()))["all"]
    return {"steps": steps, "pairs": len(cases), "parameters": params, "summary": summary}


def main_study(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--steps", type=int, default=150, help="training steps of every variant")
    p.add_argument("--out", type=Path, default=Path("runs/transfer_conditioning"))
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    result = run(args.out, args.steps)
    print(f"{'method':<32}{'psnr':>8}{'ssim':>8}{'adherence':>11}")
    for name, m in result["summary"].items():
        print(f"{name:<32}{m['psnr']:>8.2f}{m['ssim']:>8.3f}{m['adherence']:>11.2f}")
    write_text(args.out / "results.json", json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main_study())
