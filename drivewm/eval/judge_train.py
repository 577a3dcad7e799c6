"""Training and evaluation of the layout judge (drivewm.eval.judge) on labelled simulated clips.

Data: every ``frame_stride``-th frame of every camera of every clip that carries label maps
(``KEY.CAMERA.labels.npz``, ``drivewm simulate --labels`` then ``drivewm curate``), held in memory
as uint8. Loss: cross-entropy weighted by median frequency balancing (Eigen and Fergus 2015,
arXiv 1411.4734, sec. 4: w_c = median_f / f_c over the training pixels, capped at
``max_class_weight``, 0 for a class the data lacks), pixels of no class ignored. Augmentations keep
the labels exact: a random crop and a horizontal flip, drawn from each sample's seed. The shared
loop (drivewm.train.loop) trains it: resume, EMA, checkpoints, metrics.jsonl.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from drivewm.clips.format import Clip
from drivewm.clips.shards import iter_clips
from drivewm.config import at_least, require, to_dict
from drivewm.errors import DrivewmError
from drivewm.eval.judge import NUM_CLASSES, Judge, JudgeConfig, confusion, predict, segmentation_scores, to_signed
from drivewm.layout.classes import LABEL_CLASSES, UNLABELLED
from drivewm.layout.labels import resize_labels
from drivewm.recipe import RecipeBook
from drivewm.train.loop import TrainConfig, TrainTask, train
from drivewm.transfer.retarget import TargetCondition


@dataclasses.dataclass
class JudgeTrainConfig:
    """A judge training run (saved in train_state.pt and printed by ``--dry-run``)."""

    preset: str = "cpu"
    """The preset the run started from (drivewm.eval.judge_train.RECIPES)."""
    judge: JudgeConfig = dataclasses.field(default_factory=JudgeConfig)
    """The network."""
    train: TrainConfig = dataclasses.field(default_factory=TrainConfig)
    """Optimisation and run settings; ``batch_size`` counts crops."""
    crop_hw: list[int] = dataclasses.field(default_factory=lambda: [48, 80])
    """(height, width) px of the training crops (the whole frame where it is smaller)."""
    frame_stride: int = 4
    """Every n-th frame of each clip and camera is a training sample (neighbours are near duplicates)."""
    max_class_weight: float = 10.0
    """Cap of a rare class's loss weight."""
    init: str = ""
    """A judge model folder whose weights a new run starts from ("" = drawn afresh); its network settings
    replace ``judge``'s. A run folder holding a train state resumes instead."""

    def validate(self) -> None:
        at_least(self, 1, "frame_stride", "max_class_weight")
        require(len(self.crop_hw) == 2 and min(self.crop_hw) >= 8, "crop_hw", self.crop_hw, "[height, width] >= 8")


#: Named runs. ``cpu``: what 2 shared CPU cores train in about half an hour; ``debug``: a few steps.
RECIPES = RecipeBook(
    "judge train",
    JudgeTrainConfig,
    {
        "cpu": {
            "train": dict(
                steps=2400,
                budget_minutes=30.0,
                batch_size=16,
                lr=2e-3,
                warmup_steps=50,
                lr_schedule="constant",
                ema_decay=0.995,
                checkpoint_every=200,
            )
        },
        "debug": {
            "judge": dict(base_channels=4, levels=2, groups=2),
            "train": dict(steps=20, batch_size=4, lr=3e-3, warmup_steps=2, ema_decay=0.9, checkpoint_every=20),
        },
    },
    "cpu",
)


@dataclasses.dataclass
class LabelledFrames:
    """Frames and their exact label maps: ``frames`` uint8 (N, H, W, 3), ``labels`` uint8 (N, H, W), and
    the condition (``weather:time_of_day``) of each frame's clip."""

    frames: np.ndarray
    labels: np.ndarray
    conditions: list[str]

    def __len__(self) -> int:
        return len(self.frames)


def clip_frames(
    clip: Clip, frame_stride: int, size_wh: tuple[int, int] | None
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Every ``frame_stride``-th frame of each camera of ``clip`` with label maps, and those maps, at
    ``size_wh`` (W, H; None: the clip's own): uint8 (N, H, W, 3) and (N, H, W); (None, None) without maps."""
    import cv2

    frames, labels = [], []
    keep = list(range(0, clip.meta.num_frames, frame_stride))
    for cam in clip.meta.cameras:
        maps = clip.labels(cam)
        if maps is None:
            continue
        for image, label in zip(clip.frames(cam, keep), maps[keep]):
            same = size_wh is None or image.shape[1::-1] == size_wh
            frames.append(image if same else cv2.resize(image, size_wh, interpolation=cv2.INTER_AREA))
            labels.append(label if size_wh is None else resize_labels(label, size_wh))
    if not frames:
        return None, None
    return np.stack(frames), np.stack(labels)


def load_labelled(locations: list[str | Path], frame_stride: int) -> LabelledFrames:
    """The labelled frames of every clip at ``locations`` (folders or shards), all at the first clip's size;
    none at all raises DrivewmError naming the locations."""
    frames, labels, conditions, size_wh = [], [], [], None
    for clip in tqdm(iter_clips([Path(p) for p in locations]), desc="labelled clips", unit="clip"):
        images, maps = clip_frames(clip, frame_stride, size_wh)
        if images is None:
            continue
        size_wh = size_wh or images.shape[2:0:-1]
        cond = TargetCondition.of(clip.meta)
        frames.append(images)
        labels.append(maps)
        conditions += [cond.name if cond else "unknown"] * len(images)
    if not frames:
        raise DrivewmError(f"{', '.join(map(str, locations))}: no clip with label maps (drivewm simulate --labels)")
    return LabelledFrames(np.concatenate(frames), np.concatenate(labels), conditions)


def class_weights(labels: np.ndarray, max_weight: float) -> torch.Tensor:
    """Median frequency balancing (Eigen and Fergus 2015, sec. 4): w_c = median_f / f_c over the classes
    present, capped at ``max_weight``; 0 for an absent class. (classes,) float32."""
    counts = np.bincount(labels[labels != UNLABELLED].ravel(), minlength=NUM_CLASSES)[:NUM_CLASSES].astype(np.float64)
    freq = counts / max(counts.sum(), 1)
    present = counts > 0
    weights = np.zeros(NUM_CLASSES)
    weights[present] = np.minimum(np.median(freq[present]) / freq[present], max_weight)
    return torch.from_numpy(weights).float()


def augment(frame: np.ndarray, label: np.ndarray, crop_hw: list[int], seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A random crop of ``crop_hw`` and a horizontal flip with probability 1/2, the same for the frame and its
    labels (labels stay exact), drawn from ``seed``."""
    rng = np.random.default_rng(seed)
    h, w = label.shape
    ch, cw = min(crop_hw[0], h), min(crop_hw[1], w)
    y, x = int(rng.integers(0, h - ch + 1)), int(rng.integers(0, w - cw + 1))
    frame, label = frame[y : y + ch, x : x + cw], label[y : y + ch, x : x + cw]
    if rng.random() < 0.5:
        frame, label = frame[:, ::-1], label[:, ::-1]
    return frame, label


class JudgeTask(TrainTask):
    """drivewm.train.loop.TrainTask of the judge: weighted cross-entropy on augmented labelled crops."""

    def __init__(self, cfg: JudgeTrainConfig, data: LabelledFrames):
        self.cfg, self.data = cfg, data
        self.model = Judge(cfg.judge).train()
        self.weights = class_weights(data.labels, cfg.max_class_weight)

    def blocks(self) -> list[torch.nn.Module]:
        return [*self.model.down, *self.model.up]

    def num_samples(self) -> int:
        return len(self.data)

    def tokens_per_sample(self) -> int:
        return self.cfg.crop_hw[0] * self.cfg.crop_hw[1]  # pixels: the loss is per pixel

    def loss(self, forward, indices: list[int], seeds: list[int], device: torch.device) -> torch.Tensor:
        pairs = [augment(self.data.frames[i], self.data.labels[i], self.cfg.crop_hw, s) for i, s in zip(indices, seeds)]
        x = to_signed(np.stack([p[0] for p in pairs])).to(device)  # (B, 3, h, w)
        y = torch.from_numpy(np.stack([p[1] for p in pairs]).astype(np.int64)).to(device)  # (B, h, w)
        logits = forward(x)  # (B, classes, h, w)
        return F.cross_entropy(logits.float(), y, weight=self.weights.to(device), ignore_index=UNLABELLED)

    def ema_judge(self, ema_state: dict[str, torch.Tensor]) -> Judge:
        with torch.random.fork_rng():  # building the network draws weights: keep the run's RNG untouched
            judge = Judge(self.cfg.judge)
        judge.load_state_dict(ema_state)
        return judge.eval()

    def save_model(self, ema_state: dict[str, torch.Tensor], out_dir: Path) -> None:
        self.ema_judge(ema_state).save(out_dir, ema_state, {"class_weights": self.weights.tolist()})

    def sample_grid(self, ema_state: dict[str, torch.Tensor], path: Path) -> None:
        """Rows of frame | true labels | the EMA judge's labels, for frames spread over the data."""
        from drivewm.eval.truth import write_label_sheet

        pick = np.linspace(0, len(self.data) - 1, min(4, len(self.data))).astype(int)
        frames = self.data.frames[pick]
        judged = predict(self.ema_judge(ema_state), frames)
        write_label_sheet(path, [(f"{self.data.conditions[i]}", [frames[k], self.data.labels[i], judged[k]])
                                 for k, i in enumerate(pick)], ["frame", "truth", "judge"])  # fmt: skip


def train_judge(
    cfg: JudgeTrainConfig, data_dirs: list[str | Path], out_dir: str | Path, stop_after: int | None = None
) -> dict:
    """Train a judge model folder into ``out_dir`` on the labelled clips of ``data_dirs`` (resuming when
    ``out_dir`` holds a train state). Returns the last metrics row."""
    cfg.validate()
    if cfg.init:
        cfg = dataclasses.replace(cfg, judge=Judge.from_pretrained(cfg.init).cfg)
    data = load_labelled(data_dirs, cfg.frame_stride)
    torch.manual_seed(cfg.train.seed)  # the network's initial weights
    task = JudgeTask(cfg, data)
    if cfg.init:
        task.model.load_state_dict(Judge.from_pretrained(cfg.init).state_dict())
    record = {**to_dict(cfg), "data": [str(Path(p).resolve()) for p in data_dirs], "frames": len(data)}
    return train(task, cfg.train, out_dir, config_record=record, stop_after=stop_after)


def evaluate_judge(judge: Judge, data: LabelledFrames) -> dict:
    """Per-class IoU, mIoU and pixel accuracy of ``judge`` on ``data``, over all frames and per condition."""
    judged = predict(judge, data.frames)
    conditions = np.array(data.conditions)
    by_condition = {
        name: segmentation_scores(confusion(judged[conditions == name], data.labels[conditions == name]))
        for name in sorted(set(data.conditions))
    }
    return {
        **segmentation_scores(confusion(judged, data.labels)),
        "frames": len(data),
        "classes": list(LABEL_CLASSES),
        "by_condition": by_condition,
    }
