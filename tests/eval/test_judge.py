"""The layout judge (drivewm.eval.judge, drivewm.eval.judge_train, ``drivewm judge train|eval``)."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
import torch
from safetensors import safe_open

from drivewm.cli import main
from drivewm.clips import ClipMeta, ShardWriter
from drivewm.clips.format import clip_from_arrays
from drivewm.errors import DrivewmError
from drivewm.eval.judge import Judge, JudgeConfig, class_iou, confusion, predict, segmentation_scores
from drivewm.eval.judge_card import ship_judge
from drivewm.eval.judge_train import RECIPES, augment, class_weights, load_labelled
from drivewm.geometry import load_rig
from drivewm.layout.classes import LABEL_CLASSES, LABEL_ID, UNLABELLED
from drivewm.model_folders import WEIGHTS_DIR, shipped_model
from drivewm.product.release import check_manifest

ROAD, SKY, CAR, PAINT = (LABEL_ID[n] for n in ("road", "sky", "vehicle", "lane_paint"))


def test_iou_and_miou_from_the_confusion_matrix():
    """Hand-counted: truth 6 road, 2 car, 1 unlabelled; prediction hits 5 road and 1 car, calls 1 road a car
    and 1 car road. Road IoU 5 / 7, car 1 / 3; unlabelled pixels count nowhere; absent classes are not averaged."""
    truth = np.array([[ROAD] * 6 + [CAR] * 2 + [UNLABELLED]], np.uint8)
    pred = np.array([[ROAD] * 5 + [CAR, CAR, ROAD, SKY]], np.uint8)
    matrix = confusion(pred, truth)
    assert matrix.sum() == 8 and matrix[ROAD, ROAD] == 5 and matrix[ROAD, CAR] == 1 and matrix[CAR, ROAD] == 1
    assert class_iou(matrix) == pytest.approx({"road": 5 / 7, "vehicle": 1 / 3})
    scores = segmentation_scores(matrix)
    assert scores["miou"] == pytest.approx((5 / 7 + 1 / 3) / 2) and scores["pixel_accuracy"] == pytest.approx(6 / 8)


def test_class_weights_balance_median_frequency_and_cap():
    """Eigen and Fergus's median frequency balancing: road 70%, sky 20%, car 9%, paint 1% -> median 14.5%."""
    labels = np.repeat(np.array([ROAD, SKY, CAR, PAINT], np.uint8), [70, 20, 9, 1])
    weights = class_weights(np.append(labels, UNLABELLED), max_weight=10.0)
    median = (0.2 + 0.09) / 2
    assert weights[ROAD] == pytest.approx(median / 0.7) and weights[CAR] == pytest.approx(median / 0.09)
    assert weights[PAINT] == 10.0  # 14.5 capped
    assert weights[LABEL_ID["building"]] == 0.0 and len(weights) == len(LABEL_CLASSES)


def test_augmentations_keep_the_labels_exact():
    """Crop and flip move a frame and its labels together: a frame that encodes its label in red stays so."""
    labels = np.random.default_rng(0).integers(0, len(LABEL_CLASSES), (30, 50)).astype(np.uint8)
    frame = np.stack([labels * 10, labels, np.zeros_like(labels)], -1)
    flips = 0
    for seed in range(8):
        f, lab = augment(frame, labels, [16, 24], seed)
        assert lab.shape == (16, 24) and np.array_equal(f[..., 0], lab * 10)
        flips += not any(np.array_equal(lab, labels[y : y + 16, x : x + 24]) for y in range(15) for x in range(27))
    assert 0 < flips < 8  # some crops flipped, some not


def test_judge_keeps_any_frame_size_and_the_default_fits_half_a_megabyte_in_fp16():
    judge = Judge(JudgeConfig(base_channels=4, levels=3, groups=2))
    assert judge(torch.zeros(2, 3, 37, 61)).shape == (2, len(LABEL_CLASSES), 37, 61)
    assert sum(p.numel() for p in Judge(JudgeConfig()).parameters()) * 2 <= 500_000
    with pytest.raises(DrivewmError, match="groups"):
        JudgeConfig(base_channels=10, groups=4).validate()


def test_the_shipped_judge_reads_a_frame_and_is_listed():
    judge = Judge.from_pretrained("shipped:judge")
    assert shipped_model("judge").name == "judge"
    out = predict(judge, np.zeros((1, 96, 160, 3), np.uint8))
    assert out.shape == (1, 96, 160) and out.dtype == np.uint8 and out.max() < len(LABEL_CLASSES)
    card = (shipped_model("judge") / "MODEL_CARD.md").read_text()
    assert "lane_paint" in card and "vehicle" in card


@pytest.fixture(scope="module")
def labelled_clips(tmp_path_factory):
    """Two short labelled drives (front3 at 96x64, clear day), one for training, one held out."""
    root = tmp_path_factory.mktemp("judge_data")
    argv = ["simulate", "--rig", "front3", "--width", "96", "--height", "64", "--duration", "1.7", "--labels"]
    for name, seed in (("train", 4), ("heldout", 21)):
        assert main([*argv, "--seed", str(seed), "--out", str(root / name / "logs")]) == 0
        assert main(["curate", str(root / name / "logs"), "--out", str(root / name / "clips"), "--recipe", "test"]) == 0
    return root


@pytest.mark.slow
def test_a_tiny_judge_trained_a_few_steps_beats_the_majority_class_on_a_held_out_drive(labelled_clips, tmp_path):
    out = tmp_path / "judge"
    sets = ["--set", "train.steps=120", "--set", "train.lr=5e-3", "--set", "frame_stride=2"]
    train, held = labelled_clips / "train" / "clips", labelled_clips / "heldout" / "clips"
    assert main(["judge", "train", "--data", str(train), "--out", str(out), "--preset", "debug", *sets]) == 0
    assert (out / "model.safetensors").is_file() and list((out / "samples").glob("*.png"))
    assert json.loads((out / "config.json").read_text())["model_type"] == "judge"
    heldout = load_labelled([held], 2)
    majority = np.full_like(heldout.labels, np.bincount(heldout.labels.ravel()).argmax())
    baseline = segmentation_scores(confusion(majority, heldout.labels))
    report = tmp_path / "eval"
    argv = ["judge", "eval", "--model", str(out), "--data", str(held), "--out", str(report)]
    assert main([*argv, "--frame-stride", "2"]) == 0
    scores = json.loads((report / "judge_eval.json").read_text())
    assert scores["frames"] == len(heldout) and scores["miou"] > baseline["miou"] + 0.1
    assert scores["iou"]["road"] > 0.5 and scores["iou"]["sky"] > 0.5


def test_training_on_clips_without_labels_is_one_clear_error(tmp_path, capsys):
    rig = load_rig("front1").scaled(32, 24, fit="stretch")
    meta = ClipMeta("nolabels", "x.mcap", 0, 10.0, [0, 100_000_000], rig.to_dict())
    clip = clip_from_arrays(meta, {rig.names[0]: np.zeros((2, 24, 32, 3), np.uint8)}, np.stack([np.eye(4)] * 2))
    with ShardWriter(tmp_path / "clips", "c") as writer:
        writer.write(clip)
    assert (
        main(["judge", "train", "--data", str(tmp_path / "clips"), "--out", str(tmp_path / "j"), "--preset", "debug"])
        == 2
    )
    last = capsys.readouterr().err.strip().splitlines()[-1]  # after the progress bar
    assert last.startswith("error: ") and last.endswith("no clip with label maps (drivewm simulate --labels)")
    assert not (tmp_path / "j" / "model.safetensors").exists()


def test_the_debug_recipe_resolves_and_refuses_unknown_fields():
    cfg = RECIPES.resolve("debug", None, ["crop_hw=[32,48]"])
    assert cfg.crop_hw == [32, 48] and cfg.judge.base_channels == 4
    with pytest.raises(DrivewmError, match="nonsense"):
        RECIPES.resolve("debug", None, ["nonsense=1"])


def test_ship_judge_writes_fp16_weights_its_card_and_a_manifest_that_checks(tmp_path):
    """Shipping into a copy of drivewm/weights: fp16 tensors, the judge's card with the held-out figures, every
    file in MANIFEST.json and its sha256 in the shipped card; shipped again, it is recorded as a fine-tune."""
    root = tmp_path / "weights"
    shutil.copytree(WEIGHTS_DIR, root, ignore=shutil.ignore_patterns("judge"))  # the weights before any judge
    manifest = json.loads((root / "MANIFEST.json").read_text())
    manifest["files"] = {k: v for k, v in manifest["files"].items() if not k.startswith("judge/")}
    manifest["training"].pop("judge", None)
    (root / "MANIFEST.json").write_text(json.dumps(manifest))
    run = tmp_path / "run"
    Judge(JudgeConfig(base_channels=4, levels=2, groups=2)).save(run)
    (run / "metrics.jsonl").write_text(json.dumps({"step": 7, "train_seconds": 3.0}) + "\n")
    report = {"iou": {"road": 0.91, "vehicle": 0.5}, "miou": 0.705, "pixel_accuracy": 0.95, "frames": 10}
    report |= {"data": ["heldout"], "by_condition": {"snow:day": {"miou": 0.6, "pixel_accuracy": 0.9}}}
    assert ship_judge(run, report, "a test judge", root)["training"]["judge"] == {"steps": 7, "train_seconds": 3.0}
    manifest = ship_judge(run, report, "a test judge", root)
    assert check_manifest(root) == manifest and manifest["training"]["judge"]["steps"] == 14
    assert {"judge/config.json", "judge/model.safetensors", "judge/MODEL_CARD.md"} <= set(manifest["files"])
    with safe_open(str(root / "judge" / "model.safetensors"), "pt") as f:
        assert {f.get_slice(k).get_dtype() for k in f.keys()} == {"F16"}
    card = (root / "judge" / "MODEL_CARD.md").read_text()
    assert "| vehicle | 0.500 |" in card and "| snow:day | 0.600 | 0.900 |" in card and "a test judge" in card
    shipped_card = (root / "MODEL_CARD.md").read_text()
    assert all(e["sha256"] in shipped_card for e in manifest["files"].values())
    assert shipped_card.count("## Layout judge") == 1
