"""Clip filters: each a small function scoring a clip; :func:`judge` turns scores into a drop reason.

Frames are uint8 RGB (V, T, H, W, 3). Scores go into ``ClipMeta.quality`` under the filter's
name, so users can re-filter from the manifest with other thresholds. Image statistics are
computed on grey frames downscaled to 160 px width (cheap and resolution-independent).
"""

from __future__ import annotations

import cv2
import numpy as np

from drivewm.curate.config import FilterConfig


def sharpness(grey: np.ndarray) -> float:
    """Blur score: variance of the Laplacian (Pech-Pacheco et al. 2000), median over frames, min over cameras."""
    per = np.array([[_laplacian_var(f) for f in cam] for cam in grey])
    return float(np.median(per, axis=1).min())


def _laplacian_var(grey: np.ndarray) -> float:
    """Variance of the Laplacian of one (h, w) uint8 image. The Laplacian of uint8 is an integer in
    [-1020, 1020], exact in int16; OpenCV sums it and its squares in doubles, within far less than
    0.5 of the integers for an analysis thumbnail (160 px wide), so the rounded sums are exact and
    the variance (n q - s^2) / n^2 in Python integers is rounded once, at 45 % of the CPU of
    ``cv2.meanStdDev`` (which agrees to ~1e-15)."""
    lap = cv2.Laplacian(grey, cv2.CV_16S)
    n, s, q = lap.size, round(cv2.sumElems(lap)[0]), round(cv2.norm(lap, cv2.NORM_L2SQR))
    return (n * q - s * s) / (n * n)


def bad_exposure_fraction(
    grey: np.ndarray, dark_luma: float, dark_highlight: float, bright_fraction: float
) -> tuple[float, float]:
    """Fraction of ticks whose rig-wide picture (all cameras together) is too dark or blown out, and
    the mean luma. Too dark: mean luma below ``dark_luma`` *and* the brightest 1 % below
    ``dark_highlight`` (a night street with lamps and headlights is footage; a fade to black is not).
    One dark camera (a rear camera at night) does not condemn the tick."""
    V, T = grey.shape[:2]
    pixels = grey[:, 0].size  # per tick, all cameras
    # per frame in OpenCV: exact integer sums (doubles below 2^53) and counts, the same means as float64
    # over a (T, V*h*w) copy at a seventh of numpy's CPU over the (V, T, h, w) array
    frames = grey.reshape(V * T, *grey.shape[2:])
    sums = np.array([cv2.sumElems(f)[0] for f in frames]).reshape(V, T)
    mean = sums.sum(axis=0) / pixels
    dark = mean < dark_luma
    if dark.any():  # the percentile (a partial sort of every pixel) only where it can matter
        per_tick = np.moveaxis(grey[:, dark], 1, 0).reshape(int(dark.sum()), -1)  # (dark ticks, V*h*w)
        dark[dark] = np.percentile(per_tick, 99, axis=1) < dark_highlight
    bright = [cv2.countNonZero(cv2.threshold(f, 249, 255, cv2.THRESH_BINARY)[1]) for f in frames]  # >= 250
    blown = np.array(bright).reshape(V, T).sum(axis=0) / pixels > bright_fraction
    return float((dark | blown).mean()), float(mean.mean())


def frozen_fraction(grey: np.ndarray, frozen_diff: float) -> float:
    """Fraction of consecutive frame pairs (any camera) whose mean absolute difference is below ``frozen_diff``."""
    # (V, T-1): OpenCV's L1 norm is the exact integer sum of |a - b| that numpy's int16 mean divides, at a
    # quarter of its CPU
    diff = np.array([[cv2.norm(cam[t], cam[t + 1], cv2.NORM_L1) for t in range(len(cam) - 1)] for cam in grey])
    diff = diff.reshape(grey.shape[0], grey.shape[1] - 1) / grey[0, 0].size
    return float((diff < frozen_diff).any(axis=0).mean())


def camera_motion_px(grey: np.ndarray, pairs: int = 4) -> float:
    """Static-camera score: 75th percentile of the Farneback flow magnitude (px at 160 px width) of
    the reference camera, averaged over a few frame pairs. A moving camera moves most of the
    picture (a dashcam's road and verges: 1-1.5 px at 10 fps); objects passing a fixed camera
    cover less than a quarter of it, leaving the percentile near 0. (Flat sky and road give no
    flow either way, which is why the median is not used.)"""
    cam = grey[0]
    steps = np.linspace(0, cam.shape[0] - 2, min(pairs, cam.shape[0] - 1)).round().astype(int)
    mags = []
    for t in steps:
        flow = cv2.calcOpticalFlowFarneback(cam[t], cam[t + 1], None, 0.5, 3, 15, 3, 5, 1.2, 0)
        mags.append(float(np.percentile(np.linalg.norm(flow, axis=-1), 75)))
    return float(np.mean(mags))


def ego_distance_m(positions_world: np.ndarray) -> float:
    """Path length (m) of the ego positions (T, 3)."""
    return float(np.linalg.norm(np.diff(positions_world, axis=0), axis=1).sum())


def score_grey(grey: np.ndarray, positions_world: np.ndarray | None, cfg: FilterConfig) -> dict[str, float]:
    """All filter scores of one clip from its grey thumbnails (V, T, h, 160) uint8
    (drivewm.curate.images.analysis_grey, made once per frame while streaming). ``positions_world``
    None means the ego motion is unknown."""
    bad, luma = bad_exposure_fraction(grey, cfg.dark_luma, cfg.dark_highlight, cfg.bright_fraction)
    scores = {
        "sharpness": sharpness(grey),
        "bad_exposure_fraction": bad,
        "mean_luma": luma,
        "frozen_fraction": frozen_fraction(grey, cfg.frozen_diff),
    }
    if positions_world is not None:
        scores["ego_distance_m"] = ego_distance_m(positions_world)
    elif cfg.min_camera_motion_px > 0:
        scores["camera_motion_px"] = camera_motion_px(grey)
    return scores


def judge(scores: dict[str, float], cfg: FilterConfig) -> str | None:
    """The first failing filter's reason, or None to keep the clip. Order: cheapest evidence first."""
    if scores["bad_exposure_fraction"] > cfg.max_bad_exposure_fraction:
        return "bad_exposure"
    if scores["frozen_fraction"] > cfg.max_frozen_fraction:
        return "frozen_frames"
    if scores["sharpness"] < cfg.min_sharpness:
        return "blurry"
    if scores.get("ego_distance_m", np.inf) < cfg.min_ego_distance_m:
        return "ego_standing_still"
    if scores.get("camera_motion_px", np.inf) < cfg.min_camera_motion_px:
        return "static_camera"
    return None
