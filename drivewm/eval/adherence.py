"""Condition adherence: does a clip show the prompted weather and time of day?

``condition_scores(frames)`` reduces a clip to a few image statistics, each with a physical reason:

- ``luma_mean``, ``luma_p99``: light level (night is dark but keeps bright lamps).
- ``saturation``: mean HSV saturation (overcast, fog and snow wash colours out).
- ``contrast``: RMS contrast of luma (fog lowers it, Koschmieder's law).
- ``dark_channel``: mean of the 15x15 dark channel (He et al. 2009): haze/fog lifts it.
- ``white_fraction``: share of bright, unsaturated pixels (snow cover).
- ``warmth``: mean R - B (dusk light is orange), ``sky_blue``: B - R in the top third (clear sky).
- ``edge_energy``: mean |Laplacian| (fog and rain soften edges).
- ``ground_luma``: mean luma of the bottom third (snow cover is bright, wet asphalt dark).
- ``horizon_contrast``: relative luma spread of the middle third, where distant things are (fog
  flattens it first).
- ``flicker``: mean |high-pass(frame t+1) - high-pass(frame t)| (rain and snow particles move
  from frame to frame while the scene barely changes).

``classify_condition(scores)`` is a nearest-centroid classifier in z-scored feature space, one
centroid per weather x time-of-day pair and per image domain, with centroids and scales fitted on
simulator renders (``python scripts/calibrate_adherence.py``; the numbers are package data,
``drivewm/tables/adherence_calibration.json``). The domains are the renders as logged and the same
renders coded by a video tokenizer at the size generators work at (``coded``): a tokenizer removes
the snowflakes and rain streaks that the flicker and edge statistics see, so its ideal output of a
snow render otherwise reads as fog, and every generated or transferred clip is such an output.
A domain's centroids name their domain third (``snow/day/coded``); the label is the first two parts.
Probabilities are a softmax over negative squared distances.
"""

from __future__ import annotations

import functools
import json

import cv2
import numpy as np

from drivewm import resources
from drivewm.errors import DrivewmError

FEATURES = (
    "luma_mean",
    "luma_p99",
    "saturation",
    "contrast",
    "dark_channel",
    "white_fraction",
    "warmth",
    "sky_blue",
    "edge_energy",
    "ground_luma",
    "horizon_contrast",
    "flicker",
)
DARK_CHANNEL_PATCH = 15  # He et al. 2009 use 15x15 patches
MAX_FRAMES = 8  # statistics are averaged over at most this many evenly spaced frames


def _frame_stats(rgb: np.ndarray) -> dict[str, float]:
    """Statistics of one uint8 RGB (H, W, 3) frame."""
    f = rgb.astype(np.float32) / 255.0
    luma = f @ np.array([0.299, 0.587, 0.114], np.float32)
    hsv = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV).astype(np.float32)
    sat = hsv[..., 1] / 255.0
    dark = cv2.erode(f.min(axis=2), np.ones((DARK_CHANNEL_PATCH, DARK_CHANNEL_PATCH), np.uint8))
    h = f.shape[0]
    top = f[: h // 3]
    return {
        "luma_mean": float(luma.mean()),
        "luma_p99": float(np.percentile(luma, 99)),
        "saturation": float(sat.mean()),
        "contrast": float(luma.std()),
        "dark_channel": float(dark.mean()),
        "white_fraction": float(np.mean((luma > 0.7) & (sat < 0.15))),
        "warmth": float(f[..., 0].mean() - f[..., 2].mean()),
        "sky_blue": float(top[..., 2].mean() - top[..., 0].mean()),
        "edge_energy": float(np.abs(cv2.Laplacian(luma, cv2.CV_32F)).mean()),
        "ground_luma": float(luma[2 * h // 3 :].mean()),
        "horizon_contrast": float(luma[h // 3 : 2 * h // 3].std() / (luma[h // 3 : 2 * h // 3].mean() + 0.05)),
    }


def _high_pass(rgb: np.ndarray) -> np.ndarray:
    luma = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY).astype(np.float32) / 255.0
    return luma - cv2.GaussianBlur(luma, (0, 0), 2.0)


def condition_scores(frames: np.ndarray) -> dict[str, float]:
    """Condition statistics of a clip: uint8 RGB frames (T, H, W, 3), or (V, T, H, W, 3) for all
    cameras (each camera's statistics averaged). Keys: :data:`FEATURES`."""
    frames = np.asarray(frames)
    if frames.dtype != np.uint8 or frames.shape[-1] != 3 or frames.ndim not in (4, 5):
        raise DrivewmError(
            f"condition_scores: expected uint8 (T, H, W, 3) or (V, T, H, W, 3), got {frames.dtype} {frames.shape}"
        )
    views = frames if frames.ndim == 5 else frames[None]
    per_view = [_view_scores(v) for v in views]
    return {k: float(np.mean([s[k] for s in per_view])) for k in FEATURES}


def _view_scores(video: np.ndarray) -> dict[str, float]:
    idx = np.unique(np.linspace(0, len(video) - 1, min(MAX_FRAMES, len(video))).round().astype(int))
    stats = [_frame_stats(video[i]) for i in idx]
    out = {k: float(np.mean([s[k] for s in stats])) for k in stats[0]}
    if len(video) > 1:
        diffs = [np.abs(_high_pass(video[i + 1]) - _high_pass(video[i])).mean() for i in idx if i + 1 < len(video)]
        out["flicker"] = float(np.mean(diffs)) if diffs else 0.0
    else:
        out["flicker"] = 0.0
    return out


def classify_condition(scores: dict[str, float], calibration: dict | None = None) -> dict:
    """Predicted weather and time of day of a clip from :func:`condition_scores`.

    Nearest centroid over the joint weather x time-of-day classes in z-scored feature space
    (weather looks different by day and by night, so one centroid per pair), probabilities a
    softmax over -d^2 / 2, then summed per weather and per time of day.
    Returns ``{"weather": str, "weather_prob": {class: p}, "time_of_day": str, "time_of_day_prob": {...}}``.
    ``calibration`` defaults to the simulator-fitted tables (:func:`load_calibration`).
    """
    if calibration is None:
        calibration = load_calibration()
    x = np.array([scores[k] for k in calibration["features"]])
    z = (x - np.asarray(calibration["mean"])) / np.asarray(calibration["std"])
    names = list(calibration["centroids"])
    d2 = np.array([np.sum((z - np.asarray(calibration["centroids"][n])) ** 2) for n in names])
    p = np.exp(-(d2 - d2.min()) / 2)
    p /= p.sum()
    out: dict = {}
    for i, field in enumerate(("weather", "time_of_day")):
        probs: dict[str, float] = {}
        for name, pi in zip(names, p):
            label = name.split("/")[i]
            probs[label] = probs.get(label, 0.0) + float(pi)
        out[field] = max(probs, key=probs.get)
        out[f"{field}_prob"] = probs
    return out


@functools.cache
def load_calibration() -> dict:
    """The simulator-fitted classifier tables shipped with the package (drivewm/tables/adherence_calibration.json)."""
    return json.loads((resources.package_dir("tables") / "adherence_calibration.json").read_text())


def adherence(scores: dict[str, float], prompted: dict[str, str], calibration: dict | None = None) -> dict:
    """Per-clip adherence: for each prompted field (weather, time_of_day) whether the classifier
    agrees (1.0 / 0.0) and the probability it gives the prompted class."""
    pred = classify_condition(scores, calibration)
    out: dict = {"predicted": {"weather": pred["weather"], "time_of_day": pred["time_of_day"]}, "prompted": {}}
    for field in ("weather", "time_of_day"):
        out["prompted"][field] = prompted.get(field)
        want = prompted.get(field)
        if want and want in pred[f"{field}_prob"]:
            out[f"{field}_match"] = float(pred[field] == want)
            out[f"{field}_prob"] = pred[f"{field}_prob"][want]
    return out
