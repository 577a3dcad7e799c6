"""Weather and time of day are visible and measurable in the renders, on the same drive and tick.

Statistics (all on uint8 RGB, computed over the six views):
- luminance: mean Rec.601 luma Y / 255 (night is dark);
- snow cover: fraction of lower-half pixels that are bright (HSV value > 0.7) and unsaturated
  (saturation < 0.15): snow on the ground;
- far detail: mean |Laplacian of Y| / 255 in the band of rows around the horizon, where the
  ground is 15 m and more away (fog washes out contrast with depth);
- warmth: mean R / mean B (dusk light is orange);
- saturation: mean HSV saturation (overcast and rain are grey).
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from drivewm.sim import SimConfig
from drivewm.sim.conditions import condition_for
from drivewm.sim.drives import record
from drivewm.sim.props import place_props
from drivewm.sim.render import Renderer
from drivewm.sim.world import TEXTURE_MARGIN_M, sim_rig

pytestmark = pytest.mark.slow  # renders one drive in every condition

CONDITIONS = [
    ("clear", "day"),
    ("snow", "day"),
    ("clear", "night"),
    ("fog", "day"),
    ("clear", "dusk"),
    ("overcast", "day"),
    ("rain", "day"),
]


def stats(images: dict[str, np.ndarray]) -> dict[str, float]:
    imgs = list(images.values())
    hsv = (
        np.concatenate([cv2.cvtColor(i, cv2.COLOR_RGB2HSV_FULL).reshape(-1, 3) for i in imgs]).astype(np.float64) / 255
    )
    lower = (
        np.concatenate([cv2.cvtColor(i[i.shape[0] // 2 :], cv2.COLOR_RGB2HSV_FULL).reshape(-1, 3) for i in imgs]) / 255
    )
    y = np.concatenate([cv2.cvtColor(i, cv2.COLOR_RGB2GRAY).ravel() for i in imgs]) / 255
    h = imgs[0].shape[0]
    lap = [
        np.abs(cv2.Laplacian(cv2.cvtColor(i, cv2.COLOR_RGB2GRAY).astype(np.float32) / 255, cv2.CV_32F))[
            h // 2 - h // 8 : h // 2 + h // 12
        ]
        for i in imgs
    ]
    rgb = np.concatenate([i.reshape(-1, 3) for i in imgs]).astype(np.float64)
    return {
        "luminance": float(y.mean()),
        "far_detail": float(np.mean(lap)),
        "saturation": float(hsv[:, 1].mean()),
        "snow_cover": float(np.mean((lower[:, 2] > 0.7) & (lower[:, 1] < 0.15))),
        "warmth": float(rgb[:, 0].mean() / rgb[:, 2].mean()),
    }


@pytest.fixture(scope="module")
def renders() -> dict[tuple[str, str], dict[str, float]]:
    cfg = SimConfig(source="highway", scenario="merge", duration_s=1.0, seed=21)
    rec = record(cfg)
    xy = rec.ego_xy()
    lo, hi = xy.min(axis=0) - TEXTURE_MARGIN_M, xy.max(axis=0) + TEXTURE_MARGIN_M
    rec.road.props = place_props(rec.road, lo, hi, cfg.seed, urban=False)
    tick = rec.ticks[5]
    out = {}
    for weather, tod in CONDITIONS:
        r = Renderer(sim_rig(cfg), rec.road, condition_for(weather, tod), cfg.seed, lo, hi, urban=False)
        out[weather, tod] = stats(r.render(tick.T_world_from_ego, tick.agents, tick.timestamp_ns))
    return out


def test_night_is_dark(renders) -> None:
    assert renders["clear", "night"]["luminance"] < 0.35 * renders["clear", "day"]["luminance"]


def test_snow_covers_the_ground(renders) -> None:
    assert renders["snow", "day"]["snow_cover"] > renders["clear", "day"]["snow_cover"] + 0.3


def test_fog_washes_out_far_detail(renders) -> None:
    assert renders["fog", "day"]["far_detail"] < 0.5 * renders["clear", "day"]["far_detail"]


def test_dusk_is_warm_and_dimmer(renders) -> None:
    day, dusk, night = renders["clear", "day"], renders["clear", "dusk"], renders["clear", "night"]
    assert dusk["warmth"] > day["warmth"] + 0.2
    assert night["luminance"] < dusk["luminance"] < 0.85 * day["luminance"]


def test_overcast_and_rain_are_grey(renders) -> None:
    day = renders["clear", "day"]
    assert renders["overcast", "day"]["saturation"] < 0.8 * day["saturation"]
    assert renders["rain", "day"]["saturation"] < 0.8 * day["saturation"]
    assert renders["rain", "day"]["luminance"] < 0.85 * day["luminance"]
