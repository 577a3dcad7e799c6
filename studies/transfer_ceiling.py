"""How much of the source's cross-view geometry can a transfer that is faithful to the target keep?

The transfer benchmark (benchmarks/bench_transfer.py) asks for two things at once: PSNR to the
simulator's own rendering of the target condition, and cross-view CSE near the source's. This
study scores outputs that need no model on the same held-out pairs, to show how the two relate:

- ``truth``: the simulator's rendering of the drive in the target condition itself;
- ``oracle``: the source's exact geometry at the truth's local look: a guided filter (He et al.
  2013, grey source as the guide, the truth as the input, radius ``--radius`` px) fits the truth as
  a local affine map of the source, so every edge sits where the source's does and every local
  mean and contrast is the truth's;
- ``scaled@A``: the source with its contrast scaled by A around the truth's mean (a global affine
  map: all of the source's structure, a night's or fog's contrast).

For each it prints PSNR and SSIM to the truth, CSE as a ratio to the source's (mean over clips, as
the benchmark's summary), the share of camera pairs with enough verified matches, and the verified
matches of the weakest pair.

    python studies/transfer_ceiling.py HELDOUT_CLIPS [--targets snow:day,clear:night,fog:day]
        [--max-pairs 3] [--radius 4] [--scales 0.15,0.25] [--out ceiling.json]

HELDOUT_CLIPS is the benchmark's folder (the ``transfer_heldout`` drives curated at the size to
score, say 320x192). Numbers: docs/transfer.md ("Gain window").
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from drivewm.sim.paired import parse_conditions
from drivewm.transfer.retarget import TargetCondition

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from transfer_benchmark import ScoredPair, paired_cases  # noqa: E402
from transfer_metrics import cross_view_error, image_scores  # noqa: E402


def guided_filter(guide: np.ndarray, image: np.ndarray, radius: int, eps: float) -> np.ndarray:
    """He et al.'s guided filter: ``image`` (H, W, C) float in [0, 1] as a local affine map of the grey
    ``guide`` (H, W), over boxes of side ``2 radius + 1``; ``eps`` regularises flat regions."""

    def box(a: np.ndarray) -> np.ndarray:
        return cv2.blur(a, (2 * radius + 1, 2 * radius + 1))

    mean_i = box(guide)
    var_i = box(guide * guide) - mean_i * mean_i
    out = np.empty_like(image)
    for c in range(image.shape[-1]):
        p = image[..., c]
        mean_p = box(p)
        a = (box(guide * p) - mean_i * mean_p) / (var_i + eps)
        b = mean_p - a * mean_i
        out[..., c] = box(a) * guide + box(b)
    return out


def oracle(source: np.ndarray, truth: np.ndarray, radius: int, eps: float = 1e-3) -> np.ndarray:
    """uint8 (V, T, H, W, 3): the truth's local look on the source's geometry, frame by frame."""
    out = np.empty_like(truth)
    for v, t in np.ndindex(*truth.shape[:2]):
        guide = cv2.cvtColor(source[v, t], cv2.COLOR_RGB2GRAY).astype(np.float32) / 255
        fitted = guided_filter(guide, truth[v, t].astype(np.float32) / 255, radius, eps)
        out[v, t] = np.clip(np.rint(fitted * 255), 0, 255).astype(np.uint8)
    return out


def scaled(source: np.ndarray, truth: np.ndarray, contrast: float) -> np.ndarray:
    """uint8: the source's deviations from its mean colour times ``contrast``, around the truth's mean."""
    s = source.astype(np.float32)
    axes = (0, 1, 2, 3)
    y = contrast * (s - s.mean(axes)) + truth.astype(np.float32).mean(axes)
    return np.clip(np.rint(y), 0, 255).astype(np.uint8)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("clips", help="held-out paired clips (the transfer benchmark's --data)")
    parser.add_argument("--source", default="clear:day")
    parser.add_argument("--targets", default="snow:day,clear:night,fog:day")
    parser.add_argument("--max-pairs", type=int, default=3, help="pairs per target (the benchmark's)")
    parser.add_argument("--radius", type=int, default=4, help="the oracle's guided-filter radius (px)")
    parser.add_argument("--scales", default="0.15,0.25", help="contrasts of the scaled source")
    parser.add_argument("--out", default="", help="write every row as JSON here")
    args = parser.parse_args()
    source_c = TargetCondition(*parse_conditions(args.source)[0])
    targets = [TargetCondition(w, t) for w, t in parse_conditions(args.targets)]
    scales = [float(a) for a in args.scales.split(",") if a]
    rows = []
    for case in tqdm(paired_cases(args.clips, source_c, targets, args.max_pairs), desc="pairs"):
        scored = ScoredPair.of(case, case.source.videos().shape[2:4])
        outputs = {"truth": scored.target, "oracle": oracle(scored.source, scored.target, args.radius)}
        outputs |= {f"scaled@{a:g}": scaled(scored.source, scored.target, a) for a in scales}
        source_cse = cross_view_error(scored.source, scored.rig)
        for name, out in outputs.items():
            cse = cross_view_error(out, scored.rig)
            rows.append(
                {"pair_id": case.pair_id, "target": case.condition.name, "output": name}
                | image_scores(out, scored.target)
                | {k: cse[k] for k in ("cse", "cse_counted", "cse_pair_matches")}
                | {"source_cse": source_cse["cse"], "source_pair_matches": source_cse["cse_pair_matches"]}
            )
    groups = defaultdict(list)
    for r in rows:
        groups[(r["target"], r["output"])].append(r)
        groups[("all", r["output"])].append(r)
    print("target       output       PSNR   SSIM  CSE/source  pairs counted  weakest pair (source)")
    for (target, name), rs in sorted(groups.items()):
        ok = [r for r in rs if np.isfinite(r["cse"]) and np.isfinite(r["source_cse"])]
        ratio = np.mean([r["cse"] for r in ok]) / np.mean([r["source_cse"] for r in ok]) if ok else float("nan")
        weakest = min(rs, key=lambda r: min(r["cse_pair_matches"].values(), default=0))
        pair = min(weakest["cse_pair_matches"], key=weakest["cse_pair_matches"].get)
        print(
            f"{target:12s} {name:12s} {np.mean([r['psnr'] for r in rs]):5.2f}  {np.mean([r['ssim'] for r in rs]):5.3f}"
            f"  {ratio:8.2f}x  {np.mean([r['cse_counted'] for r in rs]):11.2f}    {pair} "
            f"{weakest['cse_pair_matches'][pair]} ({weakest['source_pair_matches'][pair]})"
        )
    if args.out:
        with open(args.out, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
