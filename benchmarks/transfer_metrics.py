"""What a transferred clip is scored on (benchmarks/bench_transfer.py, tests/transfer/, studies/).

Against the simulator's own rendering of the same drive in the target condition: PSNR and SSIM
(drivewm.tokenizer.metrics). Geometry kept: SIFT matches between each source frame and its
transferred frame (drivewm.eval.matching) must lie where they were (the median displacement, px),
and the cross-view Sampson error (CSE, drivewm.eval.consistency) must stay near the source's.
Condition shown: the eval's adherence classifier (drivewm.eval.adherence) must name the target.
Videos are uint8 (V, T, H, W, 3) in rig order throughout.
"""

from __future__ import annotations

import numpy as np
import torch
from einops import rearrange

from drivewm.eval.adherence import adherence, condition_scores
from drivewm.eval.config import EvalConfig
from drivewm.eval.consistency import cross_sampson, overlapping_pairs
from drivewm.eval.matching import FrameMatcher
from drivewm.geometry import Rig
from drivewm.tokenizer.metrics import psnr, ssim
from drivewm.transfer.retarget import TargetCondition

CSE_KEYS = ("cse", "cse_calibrated", "cse_counted", "cse_counted_px")  # what cross_view_error returns


def _signed(videos: np.ndarray) -> torch.Tensor:
    """uint8 (V, T, H, W, 3) -> float (V, 3, T, H, W) in [-1, 1]."""
    return rearrange(torch.from_numpy(np.ascontiguousarray(videos)).float() / 127.5 - 1, "v t h w c -> v c t h w")


def image_scores(pred: np.ndarray, target: np.ndarray) -> dict[str, float]:
    """PSNR (dB) and SSIM of ``pred`` against ``target``, both uint8 (V, T, H, W, 3)."""
    a, b = _signed(pred), _signed(target)
    return {"psnr": psnr(a, b), "ssim": float(ssim(a, b))}


def sift_shift_px(source: np.ndarray, transferred: np.ndarray, cfg: EvalConfig | None = None) -> dict[str, float]:
    """Median distance (px) between the positions of SIFT matches of each source frame and the same
    frame transferred, pooled over views and frames (a kept geometry gives ~0), and the match count."""
    matcher = FrameMatcher((cfg or EvalConfig()).match)
    shifts = []
    for v in range(len(source)):
        for t in range(source.shape[1]):
            m = matcher.match(("s", v, t), source[v, t], ("x", v, t), transferred[v, t])
            shifts.append(np.linalg.norm(m.uv_a - m.uv_b, axis=1))
    d = np.concatenate(shifts) if shifts else np.zeros(0)
    return {"median_px": float(np.median(d)) if len(d) else float("nan"), "matches": int(len(d))}


def cross_view_error(videos: np.ndarray, rig: Rig, cfg: EvalConfig | None = None) -> dict[str, float]:
    """CSE of a clip as ``drivewm eval`` scores it (px; NaN without enough matches): ``cse`` under the
    F fitted to the matches (the benchmark's headline) and ``cse_calibrated`` under the F of the
    rig's calibration (which also catches views that moved against each other); and what makes up
    ``cse``: ``cse_counted`` the share of camera pairs with enough verified matches (the others count
    at the failed-pair penalty, 4 px) and ``cse_counted_px`` the mean over those pairs only; beside
    them ``cse_pair_matches``, the verified matches of each camera pair ("A~B"), to see which missed."""
    cfg = cfg or EvalConfig()
    pairs = overlapping_pairs(rig, cfg.consistency)
    if not pairs:
        return dict.fromkeys(CSE_KEYS, float("nan")) | {"cse_pair_matches": {}}
    named = {name: videos[i] for i, name in enumerate(rig.names)}
    result = cross_sampson(named, rig, pairs, cfg.epipolar, FrameMatcher(cfg.match))
    fitted = result["fitted"]
    return {
        "cse": float(fitted["value_px"]),
        "cse_calibrated": float(result["calibrated"]["value_px"]),
        "cse_counted": float(fitted["counted_fraction"]),
        "cse_counted_px": float(fitted["counted_mean_px"]),
        "cse_pair_matches": {f"{a}~{b}": int(n) for (a, b), n in zip(pairs, fitted["pair_matches"])},
    }


def adherent(videos: np.ndarray, target: TargetCondition) -> dict:
    """The adherence classifier on a clip: its prediction, and whether it names the target's weather,
    its time of day, and both (``match``)."""
    result = adherence(condition_scores(videos), {"weather": target.weather, "time_of_day": target.time_of_day})
    both = result.get("weather_match", 0.0) * result.get("time_of_day_match", 0.0)
    return {**result, "match": float(both)}
