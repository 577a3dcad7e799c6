"""Each filter drops what it should, with its reason, on real-looking frames."""

import sys
from pathlib import Path

import cv2
import numpy as np

from drivewm.curate.captions import Captioner, ClipInfo, TemplateCaptioner, classify_manoeuvre, load_captioner
from drivewm.curate.config import FilterConfig
from drivewm.curate.dedup import grey_embedding, key_frames, near_duplicates
from drivewm.curate.filters import bad_exposure_fraction, frozen_fraction, judge, score_grey, sharpness
from drivewm.curate.images import analysis_grey
from drivewm.geometry import load_rig

sys.path.insert(0, str(Path(__file__).parent))
from synth import texture  # noqa: E402


def score_clip(frames: np.ndarray, positions_world: np.ndarray | None, cfg: FilterConfig) -> dict[str, float]:
    """All filter scores of one clip of uint8 RGB frames (V, T, H, W, 3), as curation scores the
    thumbnails it makes while streaming (drivewm.curate.filters.score_grey)."""
    grey = np.stack([np.stack([analysis_grey(f) for f in cam]) for cam in frames])  # (V, T, h, 160)
    return score_grey(grey, positions_world, cfg)


def clip_embedding(frames: np.ndarray) -> np.ndarray:
    """(V, T, H, W, 3) uint8 RGB -> the dedup embedding (drivewm.curate.dedup.grey_embedding) of its
    key frames' analysis thumbnails, as curation makes them while streaming."""
    keep = key_frames(frames.shape[1])
    return grey_embedding(np.stack([[analysis_grey(cam[t]) for t in keep] for cam in frames]))


def moving_clip(seed=0, V=2, T=17, H=96, W=160, step=2):
    tex = texture(seed, H, W * 4)
    return np.stack([np.stack([tex[:, v * W + t * step : v * W + t * step + W] for t in range(T)]) for v in range(V)])


def test_filters_drop_with_reasons():
    cfg = FilterConfig()
    moving = np.cumsum(np.full((17, 3), [1.0, 0, 0]), axis=0)
    good = moving_clip()
    assert judge(score_clip(good, moving, cfg), cfg) is None
    assert judge(score_clip(good, np.zeros((17, 3)), cfg), cfg) == "ego_standing_still"
    blurred = np.stack([[cv2.GaussianBlur(f, (0, 0), 6) for f in cam] for cam in good])
    assert judge(score_clip(blurred, moving, cfg), cfg) == "blurry"
    dark = (good // 20).astype(np.uint8)
    assert judge(score_clip(dark, moving, cfg), cfg) == "bad_exposure"
    frozen = np.repeat(good[:, :1], 17, axis=1)
    assert judge(score_clip(frozen, moving, cfg), cfg) == "frozen_frames"
    static = FilterConfig(min_camera_motion_px=0.5)
    still = np.repeat(good[:, :1], 17, axis=1)
    still[:, :, 30:55, 60:100] = good[:, :, 30:55, 60:100]  # something moves before a fixed camera
    assert judge(score_clip(still, None, static), static) == "static_camera"
    assert judge(score_clip(good, None, static), static) is None


def test_bad_exposure_per_tick_over_all_cameras():
    """Each tick's picture is every camera's pixels together, from exact sums: checked against the
    plain (T, V*h*w) float64 formulation on random clips, some ticks dark with lamps, some blown out."""
    rng = np.random.default_rng(0)
    for case in range(100):
        V, T = int(rng.integers(1, 7)), int(rng.integers(2, 18))
        grey = rng.integers(0, int(rng.integers(1, 256)), (V, T, 24, 40), dtype=np.uint8)
        grey[:, rng.random(T) < 0.3] = 255
        dark_luma, highlight, bright = rng.uniform(0, 120), rng.uniform(0, 255), rng.uniform(0, 1)
        per_tick = np.moveaxis(grey, 1, 0).reshape(T, -1).astype(np.float64)
        mean = per_tick.mean(axis=1)
        dark = (mean < dark_luma) & (np.percentile(per_tick, 99, axis=1) < highlight)
        blown = (per_tick >= 250).mean(axis=1) > bright
        got = bad_exposure_fraction(grey, dark_luma, highlight, bright)
        assert got == (float((dark | blown).mean()), float(mean.mean())), case


def test_dedup_embedding_separates_copies_from_other_moments():
    a, b = moving_clip(seed=1), moving_clip(seed=2)
    brighter = np.clip(a.astype(int) + 20, 0, 255).astype(np.uint8)
    tex = texture(1, 96, 640)
    later = np.stack(
        [np.stack([tex[:, 300 + t * 2 : 460 + t * 2] for t in range(17)]) for _ in range(2)]
    )  # same world, elsewhere
    E = np.stack([clip_embedding(x) for x in (a, brighter, b, later)])
    dups = near_duplicates(E, 0.985)
    assert [(i, j) for i, j, _ in dups] == [(1, 0)]  # only the re-exposed copy


def test_template_captions_name_conditions_and_directions():
    rig = load_rig("nuscenes6")
    info = ClipInfo(
        {"weather": "snow", "time_of_day": "night", "road_type": "urban_grid", "traffic_density": "high"},
        "",
        rig.cameras,
        "left turn",
        8.0,
    )
    caption, views = TemplateCaptioner().caption(info)
    assert (
        caption.startswith("A snow night drive on an urban grid in high traffic")
        and "turning left at 29 km/h" in caption
    )
    assert views["CAM_BACK"].startswith("The back camera") and views["CAM_FRONT_LEFT"].startswith(
        "The front-left camera"
    )
    t = np.linspace(0, 1.6, 17)
    left = np.stack([10 * np.sin(t), 10 * (1 - np.cos(t)), 0 * t], 1)
    assert classify_manoeuvre(left, t, np.full(17, 10.0)) == "left turn"
    lane = np.stack([10 * t, 3.0 * t / 1.6, 0 * t], 1)
    assert classify_manoeuvre(lane, np.zeros(17), np.full(17, 10.0)) == "lane change to the left"
    assert classify_manoeuvre(lane, np.zeros(17), np.linspace(10, 0.5, 17)) == "stopping"


class CountingCaptioner(Captioner):
    """A stand-in for a vision-language model: describes what it sees."""

    def caption(self, clip_info):
        views = {
            c.name: f"{c.name} sees mean luma {clip_info.frames[i].mean():.0f}" for i, c in enumerate(clip_info.cameras)
        }
        return f"{len(clip_info.cameras)} views", views


def test_captioner_is_swappable_from_a_recipe():
    import pytest

    from drivewm.errors import DrivewmError

    captioner = load_captioner(f"{__name__}:CountingCaptioner")
    rig = load_rig("front3")
    info = ClipInfo({}, "", rig.cameras, "straight", 5.0, moving_clip(V=3))
    caption, views = captioner.caption(info)
    assert caption == "3 views" and set(views) == set(rig.names)
    with pytest.raises(DrivewmError, match="importable"):
        load_captioner("no.such.module:Nope")


def test_sharpness_and_frozen_fraction_are_exact():
    """The Laplacian variance and the mean absolute frame differences from OpenCV's sums equal the
    exact integer formulation (Python integers over int64 numpy), on random and binary thumbnails."""
    rng = np.random.default_rng(1)
    for case in range(60):
        h = int(rng.integers(2, 120))
        g = rng.integers(0, 256, (h, 160), dtype=np.uint8) if case % 2 else rng.integers(0, 2, (h, 160), np.uint8) * 255
        lap = cv2.Laplacian(g, cv2.CV_16S).astype(np.int64).ravel()
        n = lap.size
        assert sharpness(g[None, None]) == (n * int((lap * lap).sum()) - int(lap.sum()) ** 2) / (n * n), case
    for case in range(40):
        V, T = int(rng.integers(1, 7)), int(rng.integers(2, 18))
        grey = rng.integers(0, int(rng.integers(1, 256)), (V, T, 24, 40), dtype=np.uint8)
        grey[:, rng.random(T) < 0.3] = grey[:, :1]  # some frames repeat the first
        sad = np.abs(np.diff(grey.astype(np.int64), axis=1)).sum(axis=(2, 3))
        threshold = rng.uniform(0, 3)
        expected = float((sad / (24 * 40) < threshold).any(axis=0).mean())
        assert frozen_fraction(grey, threshold) == expected, case
