"""The transfer benchmark (benchmarks/bench_transfer.py): held-out paired drives, every method scored
against the simulator's truth. Importable by the tests and studies that score as it does (they put
this folder on ``sys.path``).

For each pair id with a clip in the source condition and one in the target condition, the source
clip is coded by the tokenizer and transferred by every method; each output is decoded and scored
(transfer_metrics.py): PSNR / SSIM against the target clip, SIFT displacement against the
source frames, CSE against the source's, adherence to the target. Two references frame the numbers:
``identity`` (the source clip itself, what a method that changes nothing scores) and ``tokenizer``
(the true target coded and decoded, the best any latent method can reach without the source's
detail); beside them ``identity~noise`` (the source with Gaussian noise of NOISE_LEVELS added,
invisible) gives the measures' resolution: a camera pair with barely the verified matches it needs
in the source can lose them to that noise and count at the failed-pair penalty, so a difference in
CSE ratio smaller than this row's distance from 1 says nothing about the method. With ``detail``
(the default of ``drivewm transfer``) every method's output gets the source detail the tokenizer
dropped back (drivewm.transfer.detail), the same for all. Clips larger than the model's size are
scored at their own size, as ``drivewm transfer`` writes them: methods and the tokenizer reference
work at the model's size and are upsampled (drivewm.transfer.resolution); ``model_resolution``
scores everything at the model's size instead. Methods take the same number of network evaluations
(``nfe``, :func:`network_evaluations`) when run with the same sampler, steps and guidance."""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
from transfer_metrics import CSE_KEYS, adherent, cross_view_error, image_scores, sift_shift_px

from drivewm.clips.format import Clip
from drivewm.clips.shards import iter_clips
from drivewm.geometry import Rig
from drivewm.multiview.coding import code_views, decode_views, encode_views, resize_views
from drivewm.transfer.detail import BAND_PX
from drivewm.transfer.resolution import output_size_hw, rig_at_size, to_output_size
from drivewm.transfer.retarget import TargetCondition, target_captions

NOISE_LEVELS = 1.0  # sigma (uint8 levels) of the noise in the ``identity~noise`` reference
NOISE_NAME = "identity~noise"
REFERENCES = ("identity", NOISE_NAME, "tokenizer")  # rows that are no method: no network evaluations


def pair_drive(pair_id: str) -> str:
    """The drive of a ``pair_id`` (``<drive_id>-t<start tick>``, drivewm.curate.stage.pair_id): every
    window of one drive shares it."""
    return pair_id.rsplit("-t", 1)[0]


def network_evaluations(steps: int, guidance: float, sampler: str) -> int:
    """Denoiser calls of one sample, the unit the benchmark compares methods at: Euler N, Heun 2N - 1
    (no correction on the last step), x2 with CFG. Transfer and its SDEdit baseline both sample with
    drivewm.diffusion.sampling.sample (from pure noise, or from the source noised to ``start_sigma``:
    Meng et al. 2022, arXiv 2108.01073, sec. 3); the Karras schedule then runs from the start down to
    0, so N steps cost the same from any start."""
    calls = steps if sampler == "euler" else 2 * steps - 1
    return calls * (1 if guidance == 1.0 else 2)


#: A method: (raw source latents (V, c, t, h, w), view captions, target, seeds) -> raw latents.
Method = Callable[[torch.Tensor, list[str], TargetCondition, list[int]], torch.Tensor]


@dataclasses.dataclass
class PairCase:
    """One held-out pair: the source clip and the simulator's rendering of it in the target condition."""

    pair_id: str
    source: Clip
    target: Clip
    condition: TargetCondition


def paired_cases(
    location: str | Path, source: TargetCondition, targets: list[TargetCondition], max_per_target: int | None = None
) -> list[PairCase]:
    """Cases of the clips at ``location``: for each target, the pair ids that have a clip in ``source``
    and one in that target (sorted by id), at most ``max_per_target`` of them spread over the drives:
    the first clip of every drive, then the second of every drive, and so on (a drive is a pair id
    without its ``-t<start tick>``), so a subset spans every drive even where curation dropped a clip."""
    by_id: dict[str, dict[TargetCondition, Clip]] = defaultdict(dict)
    for clip in iter_clips(location):
        cond = TargetCondition.of(clip.meta)
        if clip.meta.pair_id and cond is not None:
            by_id[clip.meta.pair_id][cond] = clip
    cases = []
    for target in targets:
        ids = sorted(i for i, group in by_id.items() if source in group and target in group)
        if max_per_target is not None and len(ids) > max_per_target:
            ids = spread_over_drives(ids)[:max_per_target]
        cases += [PairCase(i, by_id[i][source], by_id[i][target], target) for i in ids]
    return cases


def spread_over_drives(pair_ids: list[str]) -> list[str]:
    """Sorted ``pair_ids`` reordered round-robin over their drives (sorted): each drive's first clip,
    then each drive's second, and so on."""
    by_drive: dict[str, list[str]] = defaultdict(list)
    for pid in sorted(pair_ids):
        by_drive[pair_drive(pid)].append(pid)
    drives = [by_drive[d] for d in sorted(by_drive)]
    return [clips[i] for i in range(max(map(len, drives), default=0)) for clips in drives if i < len(clips)]


def band_name(method: str, band_px: float, shared_look: bool = True) -> str:
    """A method's row name at a detail band (drivewm.transfer.detail), with its look shared between
    cameras or each view's own: the method's own name at the defaults (BAND_PX, shared)."""
    name = method if band_px == BAND_PX else f"{method}~band{band_px:g}"
    return name if shared_look else f"{name}~own-look"


@dataclasses.dataclass
class ScoredPair:
    """A case's source and true target at the size outputs are scored at, uint8 (V, T, H, W, 3), and the
    rig at that size."""

    source: np.ndarray
    target: np.ndarray
    rig: Rig

    @classmethod
    def of(cls, case: PairCase, size_hw: tuple[int, int]) -> ScoredPair:
        source = case.source.videos()
        rig = rig_at_size(case.source.meta.get_rig(), source.shape[2:4], size_hw)
        return cls(resize_views(source, size_hw), resize_views(case.target.videos(), size_hw), rig)


def score_output(case: PairCase, out: np.ndarray, scored: ScoredPair, cse: bool = True) -> dict:
    """Every measure of one output uint8 (V, T, H, W, 3) of ``case`` at ``scored``'s size; ``cse`` False
    skips the costly CSE (NaN: seconds per clip, where everything else is a fraction of a second)."""
    no_cse = dict.fromkeys(CSE_KEYS, math.nan)
    row = {**image_scores(out, scored.target), **(cross_view_error(out, scored.rig) if cse else no_cse)}
    shift = sift_shift_px(scored.source, out)
    row |= {"sift_shift_px": shift["median_px"], "sift_matches": shift["matches"]}
    adh = adherent(out, case.condition)
    return row | {"adherence": adh["match"], "predicted": adh["predicted"]}


@torch.no_grad()
def run_cases(
    cases: list[PairCase],
    methods: dict[str, Method],
    tokenizer,
    seed: int = 0,
    progress=None,
    cse_for: set[str] | None = None,
    device: torch.device | str = "cpu",
    detail: bool = False,
    model_hw: tuple[int, int] | None = None,
    model_resolution: bool = False,
    detail_bands: tuple[float, ...] = (BAND_PX,),
    looks: tuple[bool, ...] = (True,),
) -> list[dict]:
    """One row per (case, method, or reference) with its scores; CSE only for the outputs named in
    ``cse_for`` (None: all). The tokenizer codes on ``device`` (where it is); methods take and return
    latents on the CPU. Methods work at ``model_hw`` (None: the clips' own size); outputs are scored at
    the size ``drivewm transfer`` writes (the source's when larger, unless ``model_resolution``),
    upsampled as it does (drivewm.transfer.resolution); ``detail``: every method's output gets the
    source's lost detail back, once per ``detail_bands`` and per ``looks`` (True: the transfer's look
    shared between cameras, as ``drivewm transfer`` does by default; False: each view's own), rows
    named by :func:`band_name`: one network run, several bands and looks."""
    if not detail:
        detail_bands = (BAND_PX,)
    rows = []
    for case in cases:
        full = case.source.videos()
        size_hw = model_hw or full.shape[2:4]
        scored = ScoredPair.of(case, output_size_hw(full.shape[2:4], size_hw, model_resolution))
        latents = encode_views(tokenizer, resize_views(full, size_hw), size_hw, device)
        _, views = target_captions(case.source.meta, case.condition)
        captions = [views[c] for c in case.source.meta.cameras]
        seeds = [seed + v for v in range(len(captions))]
        source_cse = cross_view_error(scored.source, scored.rig)  # {cse, cse_calibrated} of the source
        truth_cse = cross_view_error(scored.target, scored.rig)  # and of the simulator's own target render
        coded_truth = code_views(tokenizer, case.target.videos(), size_hw, device)
        outputs = {
            "identity": scored.source,
            NOISE_NAME: with_noise(scored.source, NOISE_LEVELS, seed),
            "tokenizer": to_output_size(coded_truth, scored.source, None),
        }
        coded_src = decode_views(tokenizer, latents, device) if detail else None
        for name, method in methods.items():
            out = decode_views(tokenizer, method(latents, captions, case.condition, seeds), device)
            for band, shared in itertools.product(detail_bands, looks):
                rig = scored.rig if shared else None
                outputs[band_name(name, band, shared)] = to_output_size(out, scored.source, coded_src, band, rig=rig)
        for name, out in outputs.items():
            row = {"pair_id": case.pair_id, "target": case.condition.name, "method": name}
            row |= {f"source_{k}": v for k, v in source_cse.items()} | {f"truth_{k}": v for k, v in truth_cse.items()}
            wants_cse = cse_for is None or name in cse_for
            row |= score_output(case, out, scored, wants_cse and name != "identity")
            if wants_cse and name == "identity":  # the source itself: its CSE is the source's, already measured
                row |= source_cse
            rows.append(row)
        if progress is not None:
            progress(case, rows[-len(outputs) :])
    return rows


def with_noise(videos: np.ndarray, sigma: float, seed: int) -> np.ndarray:
    """uint8 ``videos`` plus Gaussian noise of ``sigma`` levels (drawn from ``seed``), rounded and clipped."""
    noise = np.random.default_rng(seed).normal(0.0, sigma, videos.shape)
    return np.clip(np.rint(videos + noise), 0, 255).astype(np.uint8)


def summarize(rows: list[dict]) -> dict[str, dict[str, dict[str, float]]]:
    """{target (and "all"): {method: means of psnr, ssim, adherence; medians of sift_shift_px; CSE ratios
    (fitted and calibrated) as mean output CSE over mean source CSE on the clips where both are finite,
    and ``truth_`` the same ratio of the simulator's own target render (what the condition itself
    does to CSE: snow, fog and night lose cross-view matches); clip count}}."""
    groups: dict[tuple[str, str], list[dict]] = defaultdict(list)
    for r in rows:
        groups[(r["target"], r["method"])].append(r)
        groups[("all", r["method"])].append(r)
    out: dict = defaultdict(dict)
    for (target, method), rs in sorted(groups.items()):
        shifts = [r["sift_shift_px"] for r in rs if math.isfinite(r["sift_shift_px"])]
        out[target][method] = {
            "clips": len(rs),
            "psnr": float(np.mean([r["psnr"] for r in rs])),
            "ssim": float(np.mean([r["ssim"] for r in rs])),
            "sift_shift_px": float(np.median(shifts)) if shifts else math.nan,
            "adherence": float(np.mean([r["adherence"] for r in rs])),
        }
        for key in ("cse_counted", "cse_counted_px"):  # what makes up CSE: pairs counted, their own mean
            for who in ("", "source_", "truth_"):
                values = [r.get(who + key, math.nan) for r in rs]
                finite = [v for v in values if math.isfinite(v)]
                out[target][method][who + key] = float(np.mean(finite)) if finite else math.nan
        for key in ("cse", "cse_calibrated"):
            ok = [r for r in rs if math.isfinite(r[key]) and math.isfinite(r[f"source_{key}"])]
            source = np.mean([r[f"source_{key}"] for r in ok]) if ok else math.nan
            ratio = np.mean([r[key] for r in ok]) / source if ok else math.nan
            truth = [r.get(f"truth_{key}", math.nan) for r in ok]
            truth_ratio = np.mean(truth) / source if ok and all(map(math.isfinite, truth)) else math.nan
            out[target][method] |= {
                f"{key}_ratio": float(ratio),
                f"truth_{key}_ratio": float(truth_ratio),
                f"{key}_nan_clips": len(rs) - len(ok),
            }
    return dict(out)
