"""Scoring generated clips against the simulator's truth: the same drive, window and condition, rendered.

A generated clip keeps its source clip's ``pair_id`` (``<drive_id>-t<start tick>``, drivewm.sim.paired)
and names the condition it was asked for in its ``weather`` and ``time_of_day`` tags, as ``drivewm
transfer`` writes them (drivewm.transfer.retarget). Its truth is the clip of the truth folder with the
same pair id in that condition. Each pair is scored on:

- appearance: PSNR (dB) and SSIM (Wang et al. 2004, eq. 13: 11x11 Gaussian window, sigma 1.5,
  K1 = 0.01, K2 = 0.03, dynamic range 255, per frame and channel), over every camera and frame;
- structure: the layout judge (drivewm.eval.judge) reads each frame's label classes; its per-class IoU
  and mIoU against the truth's exact label maps on the generated frames, beside the same on the true
  frames, and their ratio (generated / true: 1 = the generated frames show the layout as well as the
  simulator's own). Vehicles and lane paint are reported apart.

A generated clip without a truth (no pair id, no condition, no partner, other cameras or frame count,
a truth without label maps) is listed in ``unpaired`` with the reason. Frames of another size than the
truth's are resized to it (area interpolation), and the clip's ``resized`` says so.
"""

from __future__ import annotations

import dataclasses
from collections import defaultdict
from pathlib import Path

import cv2
import numpy as np
import torch
from tqdm import tqdm

from drivewm.atomic import write_bytes, write_json
from drivewm.clips.format import Clip
from drivewm.clips.shards import iter_clips
from drivewm.config import at_least
from drivewm.device import resolve_device
from drivewm.errors import DrivewmError
from drivewm.eval.judge import Judge, confusion, predict, segmentation_scores
from drivewm.layout.classes import LABEL_CLASSES
from drivewm.tokenizer.metrics import psnr, ssim
from drivewm.transfer.retarget import TargetCondition

#: Classes reported apart: the road users and the paint a layout must put where the truth has them.
KEY_CLASSES = ("vehicle", "lane_paint")
SHEET_NAME = "contact_sheet.png"
SCORES_NAME = "scores.json"


@dataclasses.dataclass
class ScoreOptions:
    """How ``drivewm judge score`` scores."""

    frame_stride: int = 1
    """The judge reads every n-th frame (PSNR and SSIM use every frame)."""
    sheet_clips: int = 6
    """Pairs shown on the contact sheet (spread over the conditions)."""
    device: str = "auto"
    """Where the judge runs."""

    def validate(self) -> None:
        at_least(self, 1, "frame_stride")
        at_least(self, 0, "sheet_clips")


@dataclasses.dataclass
class Pair:
    """A generated clip and the simulator's truth of its drive, window and asked condition."""

    generated: Clip
    truth: Clip
    condition: str


def condition_name(clip: Clip) -> str | None:
    """``weather:time_of_day`` of a clip's tags, or None when they name none."""
    cond = TargetCondition.of(clip.meta)
    return cond.name if cond else None


def index_truth(location: str | Path) -> dict[tuple[str, str], Clip]:
    """The truth clips at ``location`` by (pair id, condition); none raises DrivewmError."""
    truth = {(c.meta.pair_id, condition_name(c)): c for c in iter_clips(location) if c.meta.pair_id}
    if not truth:
        raise DrivewmError(f"{location}: no clip with a pair id (simulated drives curated from drivewm logs)")
    return truth


def pair_reason(clip: Clip, truth: Clip | None) -> str | None:
    """Why ``clip`` cannot be scored against ``truth`` (None: it can)."""
    if not clip.meta.pair_id:
        return "no pair_id in its metadata"
    if condition_name(clip) is None:
        return f"no weather/time_of_day tags naming the asked condition ({clip.meta.tags})"
    if truth is None:
        return f"no truth clip with pair_id {clip.meta.pair_id} in {condition_name(clip)}"
    if clip.meta.cameras != truth.meta.cameras:
        return f"cameras {clip.meta.cameras}, the truth's {truth.meta.cameras}"
    if clip.meta.num_frames != truth.meta.num_frames:
        return f"{clip.meta.num_frames} frames, the truth {truth.meta.num_frames}"
    if any(truth.labels(c) is None for c in truth.meta.cameras):
        return f"truth {truth.key} has no label maps (drivewm simulate --labels)"
    return None


def pair_clips(generated: str | Path, truth: str | Path) -> tuple[list[Pair], list[dict]]:
    """(pairs, unpaired) of the generated clips at ``generated`` against the truth at ``truth``;
    ``unpaired`` rows name the clip and the reason. No generated clip raises DrivewmError."""
    index = index_truth(truth)
    pairs, unpaired = [], []
    for clip in iter_clips(generated):
        partner = index.get((clip.meta.pair_id, condition_name(clip)))
        reason = pair_reason(clip, partner)
        if reason is None:
            pairs.append(Pair(clip, partner, condition_name(clip)))
        else:
            unpaired.append({"clip": clip.key, "reason": reason})
    if not pairs and not unpaired:
        raise DrivewmError(f"{generated}: no clips to score")
    return pairs, unpaired


def videos_at(views: np.ndarray, size_wh: tuple[int, int]) -> np.ndarray:
    """uint8 videos (V, T, H, W, 3) at ``size_wh`` (W, H), resized by area interpolation where they differ."""
    if views.shape[3:1:-1] == size_wh:
        return views
    return np.stack([[cv2.resize(f, size_wh, interpolation=cv2.INTER_AREA) for f in view] for view in views])


def appearance(generated: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    """PSNR (dB, peak 255) and SSIM (Wang et al. 2004, dynamic range 255) of uint8 (V, T, H, W, 3) videos.

    drivewm.tokenizer.metrics.ssim sets C1 = (0.01 L)^2, C2 = (0.03 L)^2 with L = 2; given pixel values
    / 127.5 in [0, 2] it is the standard SSIM of the 8-bit images (SSIM is unchanged when the pixels and
    L scale together). On values shifted to [-1, 1] its luminance term would differ from the paper's."""
    a, b = (
        torch.from_numpy(np.ascontiguousarray(v)).permute(0, 4, 1, 2, 3).double() / 127.5 for v in (generated, truth)
    )
    return {"psnr": psnr(a - 1, b - 1), "ssim": float(ssim(a, b))}


def judge_views(judge: Judge, videos: np.ndarray, stride: int) -> np.ndarray:
    """The judge's labels of every ``stride``-th frame of uint8 (V, T, H, W, 3): uint8 (V, T', H, W)."""
    frames = videos[:, ::stride]
    return predict(judge, frames.reshape(-1, *frames.shape[2:])).reshape(frames.shape[:-1])


def structure(conf_generated: np.ndarray, conf_truth: np.ndarray) -> dict:
    """The judge on generated frames against the judge on true frames: mIoU of each and their ratio, per-class
    IoU of each and ratio, with :data:`KEY_CLASSES` also at the top level."""
    gen, true = segmentation_scores(conf_generated), segmentation_scores(conf_truth)
    per_class = {name: _compared(gen["iou"].get(name, 0.0), iou) for name, iou in true["iou"].items()}
    return {
        "miou_generated": gen["miou"],
        "miou_truth": true["miou"],
        "miou_ratio": _ratio(gen["miou"], true["miou"]),
        **{name: per_class.get(name) for name in KEY_CLASSES},
        "per_class": per_class,
    }


def _compared(generated: float, truth: float) -> dict[str, float]:
    return {"generated": generated, "truth": truth, "ratio": _ratio(generated, truth)}


def _ratio(a: float, b: float) -> float:
    return a / b if b > 0 else float("nan")


@dataclasses.dataclass
class Tally:
    """Scores summed over a set of pairs (a condition, or all)."""

    confusion_generated: np.ndarray = dataclasses.field(
        default_factory=lambda: np.zeros((len(LABEL_CLASSES),) * 2, np.int64)
    )
    confusion_truth: np.ndarray = dataclasses.field(
        default_factory=lambda: np.zeros((len(LABEL_CLASSES),) * 2, np.int64)
    )
    psnr: list[float] = dataclasses.field(default_factory=list)
    ssim: list[float] = dataclasses.field(default_factory=list)

    def summary(self) -> dict:
        return {
            "clips": len(self.psnr),
            "psnr": float(np.mean(self.psnr)),
            "ssim": float(np.mean(self.ssim)),
            **structure(self.confusion_generated, self.confusion_truth),
        }


def score_pair(judge: Judge, pair: Pair, stride: int) -> tuple[dict, np.ndarray, np.ndarray, dict]:
    """One pair's row (appearance and structure), its two confusion matrices, and the frames the sheet shows."""
    cams = pair.truth.meta.get_rig().cameras
    size_wh = (cams[0].width, cams[0].height)
    own = pair.generated.videos()
    generated, truth = videos_at(own, size_wh), pair.truth.videos()
    labels = np.stack([pair.truth.labels(c) for c in pair.truth.meta.cameras])[:, ::stride]  # (V, T', H, W)
    judged_gen, judged_truth = judge_views(judge, generated, stride), judge_views(judge, truth, stride)
    conf_gen, conf_truth = confusion(judged_gen, labels), confusion(judged_truth, labels)
    row = {"clip": pair.generated.key, "truth": pair.truth.key, "pair_id": pair.truth.meta.pair_id}
    row |= {"condition": pair.condition, "resized": generated.shape != own.shape}
    row |= appearance(generated, truth) | structure(conf_gen, conf_truth)
    t = labels.shape[1] // 2
    shown = {"generated": generated[0, t * stride], "truth": truth[0, t * stride]}
    shown |= {"judge_generated": judged_gen[0, t], "judge_truth": judged_truth[0, t]}
    for clip in (pair.generated, pair.truth):
        clip._decoded.clear()  # decoded videos are the bulk of memory: keep one pair's at a time
    return row, conf_gen, conf_truth, shown


def score_against_truth(
    generated: str | Path, truth: str | Path, model: str | Path, out: str | Path, options: ScoreOptions
) -> dict:
    """Score the generated clips at ``generated`` against the truth at ``truth`` with the judge ``model``;
    writes ``out/scores.json`` and ``out/contact_sheet.png`` and returns the scores. No pair at all raises
    DrivewmError (naming the first unpaired clips) and writes nothing."""
    options.validate()
    judge = Judge.from_pretrained(model).to(resolve_device(options.device))
    pairs, unpaired = pair_clips(generated, truth)
    if not pairs:
        named = "; ".join(f"{u['clip']}: {u['reason']}" for u in unpaired[:3])
        raise DrivewmError(f"{generated}: no generated clip has a truth in {truth} ({named})")
    tallies: dict[str, Tally] = defaultdict(Tally)
    rows, sheet = [], []
    shown_conditions = _sheet_picks(pairs, options.sheet_clips)
    for i, pair in enumerate(tqdm(pairs, desc="score", unit="clip")):
        row, conf_gen, conf_truth, shown = score_pair(judge, pair, options.frame_stride)
        rows.append(row)
        for tally in (tallies[pair.condition], tallies["all"]):
            tally.confusion_generated += conf_gen
            tally.confusion_truth += conf_truth
            tally.psnr.append(row["psnr"])
            tally.ssim.append(row["ssim"])
        if i in shown_conditions:
            sheet.append((f"{row['clip']} ({pair.condition})", list(shown.values())))
    scores = {
        "generated": str(generated),
        "truth": str(truth),
        "model": str(model),
        "options": dataclasses.asdict(options),
        "classes": list(LABEL_CLASSES),
        "overall": tallies.pop("all").summary(),
        "by_condition": {name: tallies[name].summary() for name in sorted(tallies)},
        "clips": rows,
        "unpaired": unpaired,
    }
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_label_sheet(out / SHEET_NAME, sheet, ["generated", "truth", "judge on generated", "judge on truth"])
    write_json(out / SCORES_NAME, scores)
    return scores


def _sheet_picks(pairs: list[Pair], n: int) -> set[int]:
    """Indices of ``n`` pairs for the sheet, round-robin over the conditions (each condition's first pair first)."""
    by_condition: dict[str, list[int]] = defaultdict(list)
    for i, pair in enumerate(pairs):
        by_condition[pair.condition].append(i)
    order = [idx[k] for k in range(len(pairs)) for _, idx in sorted(by_condition.items()) if k < len(idx)]
    return set(order[:n])


def colour_labels(labels: np.ndarray) -> np.ndarray:
    """Label map (H, W) uint8 -> RGB (H, W, 3) in the viewer's class colours (drivewm.logs.viewer.LABEL_RGB);
    pixels of no class black."""
    from drivewm.logs.viewer import LABEL_RGB

    table = np.zeros((256, 3), np.uint8)
    for i, name in enumerate(LABEL_CLASSES):
        table[i] = LABEL_RGB[name]
    return table[labels]


def write_label_sheet(path: str | Path, rows: list[tuple[str, list[np.ndarray]]], headers: list[str]) -> None:
    """A PNG of titled rows, each a row of images (RGB (H, W, 3)) or label maps ((H, W), coloured), under
    the column ``headers``."""
    blocks = []
    for title, images in rows:
        row = np.concatenate([colour_labels(im) if im.ndim == 2 else im for im in images], axis=1)
        blocks += [_bar(row.shape[1], title), row]
    width = blocks[0].shape[1] if blocks else 320 * len(headers)
    cell = width // max(1, len(headers))
    head = np.concatenate([_bar(cell, h) for h in headers], axis=1)
    sheet = np.concatenate([np.pad(head, ((0, 0), (0, width - head.shape[1]), (0, 0))), *blocks], axis=0)
    ok, png = cv2.imencode(".png", cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR))
    if not ok:
        raise DrivewmError(f"{path}: cannot encode the contact sheet")
    write_bytes(path, png.tobytes())


def _bar(width: int, text: str) -> np.ndarray:
    """A white bar ``width`` px wide with ``text`` in black."""
    bar = np.full((16, width, 3), 255, np.uint8)
    cv2.putText(bar, text, (3, 12), cv2.FONT_HERSHEY_SIMPLEX, 0.35, (0, 0, 0), 1, cv2.LINE_AA)
    return bar
