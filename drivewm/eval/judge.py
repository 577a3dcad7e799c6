"""The layout judge: a compact U-Net that reads a camera frame and names each pixel's label class.

It reads the classes of :data:`drivewm.layout.classes.LABEL_CLASSES` (road, lane paint, vehicle,
building, vegetation, sky, ...) back from a frame, so that a generated clip's structure can be
compared with the layout it was asked to draw (drivewm.eval.truth). The network is the U-Net of
Ronneberger et al. 2015 (arXiv 1505.04597) made small: ``levels`` 2x down-samplings, two 3x3
convolutions with GroupNorm and SiLU per stage, bilinear up-sampling and skip concatenation.
Trained by drivewm.eval.judge_train on simulated frames with the renderer's exact label maps.

Scores are the usual segmentation ones from a confusion matrix (:func:`confusion`): per-class IoU
TP / (TP + FP + FN), and mIoU, the mean IoU over the classes present in the truth.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from drivewm.config import at_least, from_dict, require, to_dict
from drivewm.layout.classes import LABEL_CLASSES, UNLABELLED
from drivewm.train.checkpoint import load_model_folder, load_weights, save_model_folder

MODEL_TYPE = "judge"
NUM_CLASSES = len(LABEL_CLASSES)


@dataclasses.dataclass
class JudgeConfig:
    """Size of the judge network."""

    base_channels: int = 10
    """Channels of the full-resolution stage; each lower stage doubles them."""
    levels: int = 3
    """2x down-samplings (a frame's height and width are padded to a multiple of 2**levels)."""
    groups: int = 2
    """GroupNorm groups of every stage (divides ``base_channels``)."""
    classes: list[str] = dataclasses.field(default_factory=lambda: list(LABEL_CLASSES))
    """The label classes the output channels name, in id order (LABEL_CLASSES when trained)."""

    def validate(self) -> None:
        at_least(self, 1, "base_channels", "levels", "groups")
        require(self.base_channels % self.groups == 0, "groups", self.groups, "a divisor of base_channels")
        require(self.classes == list(LABEL_CLASSES), "classes", self.classes, f"{list(LABEL_CLASSES)}")


def _stage(c_in: int, c_out: int, groups: int) -> nn.Sequential:
    """Two 3x3 convolutions, each followed by GroupNorm and SiLU."""
    return nn.Sequential(
        nn.Conv2d(c_in, c_out, 3, padding=1),
        nn.GroupNorm(groups, c_out),
        nn.SiLU(),
        nn.Conv2d(c_out, c_out, 3, padding=1),
        nn.GroupNorm(groups, c_out),
        nn.SiLU(),
    )


class Judge(nn.Module):
    """U-Net segmenter: frames (B, 3, H, W) in [-1, 1] -> class logits (B, classes, H, W)."""

    def __init__(self, cfg: JudgeConfig):
        super().__init__()
        cfg.validate()
        self.cfg = cfg
        widths = [cfg.base_channels * 2**i for i in range(cfg.levels + 1)]
        self.down = nn.ModuleList([_stage(3, widths[0], cfg.groups)])
        self.down.extend(_stage(a, b, cfg.groups) for a, b in zip(widths[:-1], widths[1:]))
        self.up = nn.ModuleList(_stage(b + a, a, cfg.groups) for a, b in zip(widths[:-1], widths[1:]))
        self.head = nn.Conv2d(widths[0], len(cfg.classes), 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h, w = x.shape[-2:]
        m = 2**self.cfg.levels
        x = F.pad(x, (0, -w % m, 0, -h % m), mode="replicate")  # (B, 3, H', W'), multiples of 2**levels
        skips = []
        for i, stage in enumerate(self.down):
            x = stage(x if i == 0 else F.max_pool2d(x, 2))  # (B, C_i, H' / 2^i, W' / 2^i)
            skips.append(x)
        for stage, skip in zip(reversed(self.up), reversed(skips[:-1])):
            x = F.interpolate(x, size=skip.shape[-2:], mode="bilinear", align_corners=False)
            x = stage(torch.cat([x, skip], dim=1))  # (B, C_i, H' / 2^i, W' / 2^i)
        return self.head(x)[..., :h, :w]  # (B, classes, H, W)

    @classmethod
    def from_pretrained(cls, path: str | Path) -> Judge:
        """The judge of a model folder (``model_type`` judge; ``shipped:judge`` names the installed one)."""
        info, state = load_model_folder(path, MODEL_TYPE)
        model = cls(from_dict(JudgeConfig, info["config"], f"{path} config"))
        load_weights(model, {k: v.float() for k, v in state.items()}, path)
        return model.eval()

    def save(self, path: str | Path, state: dict[str, torch.Tensor] | None = None, extra: dict | None = None) -> None:
        """Write the model folder ``path`` from ``state`` (e.g. EMA weights; default: this module's)."""
        save_model_folder(path, MODEL_TYPE, to_dict(self.cfg), state or self.state_dict(), extra)


def to_signed(frames: np.ndarray) -> torch.Tensor:
    """uint8 RGB (N, H, W, 3) -> float (N, 3, H, W) in [-1, 1]."""
    return torch.from_numpy(np.ascontiguousarray(frames)).permute(0, 3, 1, 2).float() / 127.5 - 1


@torch.no_grad()
def predict(judge: Judge, frames: np.ndarray, batch: int = 32) -> np.ndarray:
    """The judge's label map of each frame: uint8 RGB (N, H, W, 3) -> uint8 (N, H, W) class ids."""
    device = next(judge.parameters()).device
    out = [
        judge(to_signed(frames[i : i + batch]).to(device)).argmax(1).to(torch.uint8).cpu().numpy()
        for i in range(0, len(frames), batch)
    ]
    return np.concatenate(out) if out else np.zeros((0, *frames.shape[1:3]), np.uint8)


def confusion(pred: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(classes, classes) int64 pixel counts, row = true class, column = predicted class; pixels whose
    truth is UNLABELLED are left out."""
    keep = truth != UNLABELLED
    index = truth[keep].astype(np.int64) * NUM_CLASSES + pred[keep].astype(np.int64)
    return np.bincount(index, minlength=NUM_CLASSES**2).reshape(NUM_CLASSES, NUM_CLASSES)


def class_iou(matrix: np.ndarray) -> dict[str, float]:
    """IoU = TP / (TP + FP + FN) of every class present in the truth (row sum > 0), by class name."""
    tp = np.diag(matrix).astype(np.float64)
    union = matrix.sum(0) + matrix.sum(1) - tp
    return {name: float(tp[i] / union[i]) for i, name in enumerate(LABEL_CLASSES) if matrix[i].sum() > 0}


def segmentation_scores(matrix: np.ndarray) -> dict:
    """``iou`` per class present, ``miou`` (their mean; NaN with none) and ``pixel_accuracy`` of a confusion matrix."""
    iou = class_iou(matrix)
    total = matrix.sum()
    return {
        "miou": float(np.mean(list(iou.values()))) if iou else float("nan"),
        "pixel_accuracy": float(np.trace(matrix) / total) if total else float("nan"),
        "iou": iou,
    }
