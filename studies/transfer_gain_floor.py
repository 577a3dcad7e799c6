"""Does a floor on the detail gain keep the transfer's weakest camera pair?

At 320x192 the shipped transfer model's cross-view CSE is 1.6x the source's against the 1.5x goal
of issue 18, and the excess is one camera pair (CAM_BACK_RIGHT~CAM_BACK of the roundabout drive)
that keeps fewer than the 68 verified matches a pair needs at night and in fog. The source's
structure comes back scaled by the contrast the transfer keeps (drivewm.transfer.detail), a fifth
at night; the clear source scaled to a quarter of its contrast keeps 68 of that pair's 110 matches
(studies/transfer_ceiling.py). This study gives every output at least ``FLOOR`` of the source's
structure (``restore_detail(min_gain=FLOOR)``) and scores each floor on the benchmark's held-out
pairs: PSNR, SSIM and adherence against the simulator's truth, CSE over the source's (mean over
clips, as bench_transfer.py's summary), the camera pairs counted, and the weakest pair's matches.
SDEdit at sigma 8 (the benchmark's best) gets the same floor, so the PSNR gain is like for like.

The networks run once per pair: their decoded outputs (the model's size) are cached in ``--cache``
and every floor is applied to them.

    python studies/transfer_gain_floor.py HELDOUT_CLIPS --cache CACHE [--floors 0,0.2,0.3,0.4]
        [--model shipped:transfer] [--model-resolution] [--out floor.json]

Numbers: docs/transfer.md ("Detail band").
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from drivewm.diffusion.text2world import Text2World
from drivewm.multiview.coding import decode_views, encode_views, resize_views
from drivewm.transfer.model import Transfer
from drivewm.transfer.resolution import output_size_hw, to_output_size
from drivewm.transfer.retarget import TargetCondition, target_captions

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from transfer_benchmark import ScoredPair, paired_cases, score_output  # noqa: E402
from transfer_metrics import cross_view_error  # noqa: E402

from drivewm.transfer.sdedit import sdedit_latents

STEPS, SDEDIT_SIGMA = 8, 8.0  # the benchmark's: 8 Euler steps each, SDEdit's best sigma


def decoded_outputs(case, model, parent, tokenizer, model_hw) -> dict[str, np.ndarray]:
    """The transfer's and SDEdit's decoded outputs and the coded source, uint8 at the model's size."""
    latents = encode_views(tokenizer, resize_views(case.source.videos(), model_hw), model_hw)
    _, views = target_captions(case.source.meta, case.condition)
    captions = [views[c] for c in case.source.meta.cameras]
    seeds = list(range(len(captions)))
    targets = [case.condition] * len(captions)
    transfer = model.transfer_latents(latents, captions, targets, seeds, STEPS, 1.0, "euler", None)
    sdedit = sdedit_latents(parent, latents, captions, seeds, SDEDIT_SIGMA, STEPS, 1.0, "euler")
    decode = lambda z: decode_views(tokenizer, z)  # noqa: E731
    return {"transfer": decode(transfer), "sdedit": decode(sdedit), "coded": decode(latents)}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("data", type=Path, help="held-out paired clips (the transfer_heldout drives, curated)")
    p.add_argument("--cache", type=Path, required=True, help="folder for the decoded outputs (reused)")
    p.add_argument("--model", default="shipped:transfer")
    p.add_argument("--floors", default="0,0.2,0.3,0.4")
    p.add_argument("--targets", default="snow:day,clear:night,fog:day")
    p.add_argument("--max-pairs", type=int, default=3)
    p.add_argument("--model-resolution", action="store_true", help="score at the model's size")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--out", type=Path)
    args = p.parse_args(argv)
    torch.set_num_threads(args.threads)
    floors = [float(f) for f in args.floors.split(",")]
    model = Transfer.from_pretrained(args.model)
    from drivewm.tokenizer import Tokenizer

    tokenizer = Tokenizer.from_pretrained(model.latent.tokenizer)
    targets = [TargetCondition(*t.split(":")) for t in args.targets.split(",")]
    cases = paired_cases(args.data, TargetCondition("clear", "day"), targets, args.max_pairs)
    _, _, h, w = model.latent.latent_shape
    model_hw = (h * tokenizer.config.spatial_compression, w * tokenizer.config.spatial_compression)
    args.cache.mkdir(parents=True, exist_ok=True)
    parent, rows = None, []
    for case in tqdm(cases, desc="pairs", unit="pair"):
        cached = args.cache / f"{case.pair_id}_{case.condition.name}.npz"
        if not cached.exists():
            parent = parent or Text2World.from_pretrained(model.parent)
            np.savez(cached, **decoded_outputs(case, model, parent, tokenizer, model_hw))
        decoded = np.load(cached)
        full_hw = case.source.videos().shape[2:4]
        scored = ScoredPair.of(case, output_size_hw(full_hw, model_hw, args.model_resolution))
        source_cse = cross_view_error(scored.source, scored.rig)["cse"]
        for floor in floors:
            for method in ("transfer", "sdedit"):
                out = to_output_size(decoded[method], scored.source, decoded["coded"], min_gain=floor)
                row = score_output(case, out, scored, cse=method == "transfer")
                row |= {"pair_id": case.pair_id, "target": case.condition.name, "method": method, "floor": floor}
                rows.append(row | {"source_cse": source_cse})
    by = defaultdict(list)
    for r in rows:
        by[(r["method"], r["floor"])].append(r)
    print("floor  PSNR  SDEdit@8  SSIM  adherence  CSE/source  pairs counted  weakest pair per clip (matches)")
    for floor in floors:
        t, s = by[("transfer", floor)], by[("sdedit", floor)]
        ratio = np.mean([r["cse"] for r in t]) / np.mean([r["source_cse"] for r in t])
        weakest = [min(r["cse_pair_matches"].values(), default=0) for r in t]
        print(
            f"{floor:5.2f} {np.mean([r['psnr'] for r in t]):6.2f} {np.mean([r['psnr'] for r in s]):8.2f} "
            f"{np.mean([r['ssim'] for r in t]):6.3f} {np.mean([r['adherence'] for r in t]):9.2f} {ratio:11.3f} "
            f"{np.mean([r['cse_counted'] for r in t]):14.3f}  {weakest}"
        )
    if args.out:
        args.out.write_text(json.dumps(rows, indent=1, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
