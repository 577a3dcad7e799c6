"""The ground as one top-down texture per drive, rasterised once with cv2 from the real lane geometry.

Texel (col, row) covers world (x, y) = origin_xy + res_m * (col, row) (z = 0). The texture is
world-anchored and fully determined by the seed, so the same asphalt grain, kerb and lane
marking is seen from every camera and every tick: feature matches across views and time obey
the true geometry. Lighting of the condition is baked in; a mip pyramid (levels 2^k coarser)
keeps distant ground from aliasing.
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np

from drivewm.layout.classes import LABEL_ID
from drivewm.sim.conditions import Condition, to_uint8
from drivewm.sim.scene import RoadMap, polyline_normals

GRASS, SIDEWALK, KERB, ASPHALT = 0, 1, 2, 3
#: Albedo per class, RGB in [0, 1], and its grain amplitude (relative luminance noise).
ALBEDO = {
    GRASS: ((0.26, 0.36, 0.17), 0.22),
    SIDEWALK: ((0.60, 0.59, 0.56), 0.10),
    KERB: ((0.72, 0.72, 0.70), 0.08),
    ASPHALT: ((0.25, 0.25, 0.26), 0.16),
}
SNOW_ALBEDO = (0.93, 0.94, 0.97)
SLUSH_ALBEDO = (0.70, 0.71, 0.73)
PAINT_ALBEDO = (0.88, 0.88, 0.84)
MARKING_WIDTH_M = 0.15
DASH_M, GAP_M = 3.0, 6.0
KERB_WIDTH_M = 0.35
SIDEWALK_WIDTH_M = 3.5
SLAB_M = 1.5  # sidewalk slab size: joints every 1.5 m
MIP_LEVELS = 5
DETAIL_RES_M = 0.025  # fine grain texel (m); the grain tile repeats every DETAIL_TEXELS * DETAIL_RES_M = 51 m
DETAIL_TEXELS = 2048
DETAIL_LEVELS = 3  # grain drawn where the ground footprint of a pixel is under 2**3 grain texels


@dataclasses.dataclass
class GroundTexture:
    """Mip pyramid of the lit ground texture: ``levels[k]`` is (H_k, W_k, 3) uint8 RGB at
    ``res_m * 2**k`` metres per texel, texel centres at ``origin_xy + res_k * (col, row)``.
    ``labels``: the label id (drivewm.layout.classes) of each texel of level 0, (H_0, W_0) uint8, or
    None when not asked for."""

    origin_xy: np.ndarray
    res_m: float
    levels: list[np.ndarray]
    border_rgb: tuple[int, int, int]
    labels: np.ndarray | None = None

    def texel_coords(self, world_xy: np.ndarray, level: int) -> np.ndarray:
        """World points (N, 2) -> float texel coordinates (N, 2) (col, row) in ``levels[level]``."""
        # pyrDown keeps texel k of level l+1 centred on texel 2k of level l.
        return (world_xy - self.origin_xy) / (self.res_m * 2**level)

    def texel_from_ego(self, T_world_from_ego: np.ndarray, level: int) -> np.ndarray:
        """2x3 affine taking ego-frame ground points (x, y) to texel coordinates of ``levels[level]``."""
        A = np.empty((2, 3))
        A[:, :2] = T_world_from_ego[:2, :2] / (self.res_m * 2**level)
        A[:, 2] = self.texel_coords(T_world_from_ego[:2, 3], level)
        return A


def build_ground(
    road: RoadMap,
    lo_xy: np.ndarray,
    hi_xy: np.ndarray,
    cond: Condition,
    seed: int,
    urban: bool,
    lamp_xy: np.ndarray,
    max_texels: int = 8_000_000,
    min_res_m: float = 0.06,
    labels: bool = False,
) -> GroundTexture:
    """Rasterise the road map inside the world box [lo_xy, hi_xy] into a lit mip pyramid.

    Colour = class albedo (tinted, with paint and tyre tracks drawn in, uint8) x a per-texel
    gain = grain/patch luminance x ambient light x street-lamp pools, in cv2 per channel.
    ``labels``: also each texel's label id (road, lane paint, sidewalk, kerb, terrain), drawn with the
    same polygons and lines (no random draw: the colours are the same either way).
    """
    ext = hi_xy - lo_xy
    res = max(min_res_m, math.sqrt(ext[0] * ext[1] / max_texels))
    W, H = int(math.ceil(ext[0] / res)) + 1, int(math.ceil(ext[1] / res)) + 1
    raster = _Raster(lo_xy, res, (H, W))
    rng = np.random.default_rng([seed, 101])
    classes = _classes(road, raster, urban)
    label_map = _labels(classes, road, raster) if labels else None
    base = _base_colors(classes, cond, raster, road, rng)
    gain = _luminance_noise(classes, rng, raster, cond)
    if urban and not cond.snow:
        _slab_joints(gain, raster, classes)
    gain *= np.float32(cond.ambient)
    if cond.lamps_on and len(lamp_xy):
        gain *= 1.0 + _lamp_pools(raster, lamp_xy) / max(cond.ambient, 0.05) * 0.5
    lit = cv2.merge([cv2.multiply(ch, gain, dtype=cv2.CV_8U) for ch in cv2.split(base)])
    levels = [lit]
    for _ in range(MIP_LEVELS - 1):
        levels.append(cv2.pyrDown(levels[-1]))
    border = tuple(int(c) for c in levels[-1].reshape(-1, 3).mean(axis=0))
    return GroundTexture(np.asarray(lo_xy, dtype=np.float64), res, levels, border, label_map)


@dataclasses.dataclass
class _Raster:
    origin_xy: np.ndarray
    res_m: float
    shape: tuple[int, int]

    def px(self, points_xy: np.ndarray) -> np.ndarray:
        """World (N, 2) -> int32 texel coords with 4 fractional bits (cv2 ``shift=4``)."""
        return np.round((points_xy - self.origin_xy) / self.res_m * 16).astype(np.int32)

    def width_px(self, metres: float) -> int:
        return max(1, int(round(metres / self.res_m)))


def _classes(road: RoadMap, raster: _Raster, urban: bool) -> np.ndarray:
    road_mask = np.zeros(raster.shape, np.uint8)
    cv2.fillPoly(road_mask, [raster.px(p) for p in road.surface_polygons if len(p) >= 3], 1, cv2.LINE_8, 4)
    classes = np.full(raster.shape, GRASS, np.uint8)
    dist_m = cv2.distanceTransform(1 - road_mask, cv2.DIST_L2, 3) * raster.res_m  # metres to the paved area
    if urban:
        classes[dist_m <= SIDEWALK_WIDTH_M] = SIDEWALK
    classes[dist_m <= KERB_WIDTH_M] = KERB
    classes[road_mask > 0] = ASPHALT
    return classes


def _labels(classes: np.ndarray, road: RoadMap, raster: _Raster) -> np.ndarray:
    """Label ids (H, W) uint8 of the ground classes, with the lane markings (the polylines
    :func:`_markings` paints, without anti-aliasing) as lane paint."""
    lut = np.zeros(len(ALBEDO), np.uint8)
    for ground_class, name in ((GRASS, "terrain"), (SIDEWALK, "sidewalk"), (KERB, "kerb"), (ASPHALT, "road")):
        lut[ground_class] = LABEL_ID[name]
    labels = lut[classes]
    _markings(labels, road, raster, LABEL_ID["lane_paint"], cv2.LINE_8)
    return labels


def _value_noise(shape: tuple[int, int], cell_px: int, rng: np.random.Generator) -> np.ndarray:
    """Smooth noise (H, W) float32 ~ N(0, 1) with features about ``cell_px`` texels across."""
    h, w = shape[0] // cell_px + 3, shape[1] // cell_px + 3
    coarse = rng.standard_normal((h, w)).astype(np.float32)
    fine = cv2.resize(coarse, (w * cell_px, h * cell_px), interpolation=cv2.INTER_CUBIC)
    return fine[cell_px : cell_px + shape[0], cell_px : cell_px + shape[1]]


def _luminance_noise(classes: np.ndarray, rng: np.random.Generator, raster: _Raster, cond: Condition) -> np.ndarray:
    """Relative luminance (H, W) float32 around 1: texel grain plus patches of ~0.6 m and ~6 m."""
    lum = rng.standard_normal(classes.shape, dtype=np.float32)
    lum += 0.8 * _value_noise(classes.shape, max(2, raster.width_px(0.6)), rng)
    lum += 0.6 * _value_noise(classes.shape, max(2, raster.width_px(6.0)), rng)
    amp = np.array([ALBEDO[c][1] for c in (GRASS, SIDEWALK, KERB, ASPHALT)], np.float32) * (0.3 if cond.snow else 1.0)
    lum *= amp[classes]
    lum += 1.0
    return np.maximum(lum, 0.0, out=lum)


def _base_colors(
    classes: np.ndarray, cond: Condition, raster: _Raster, road: RoadMap, rng: np.random.Generator
) -> np.ndarray:
    """(H, W, 3) uint8 albedo under the condition's tint (not its brightness), paint drawn in."""
    lut = np.array([ALBEDO[c][0] for c in (GRASS, SIDEWALK, KERB, ASPHALT)], np.float32)
    if cond.snow:
        lut[[GRASS, SIDEWALK, KERB]] = SNOW_ALBEDO
        lut[ASPHALT] = SLUSH_ALBEDO
    if cond.wet:
        lut *= np.array([[0.8], [0.7], [0.7], [0.55]], np.float32)
    unlit = lambda rgb: tuple(float(v) for v in to_uint8(cond.tinted(np.asarray(rgb, np.float32))))  # noqa: E731
    colors = np.stack([unlit(c) for c in lut]).astype(np.uint8)
    base = colors[classes]
    _scatter_spots(base, classes, colors, raster, rng)
    if cond.snow:
        _tyre_tracks(base, road, raster, unlit(np.asarray(SLUSH_ALBEDO) * 0.6))
    paint = np.asarray(PAINT_ALBEDO) * (0.8 if cond.wet else 1.0)
    _markings(base, road, raster, unlit(0.85 * np.asarray(SLUSH_ALBEDO) + 0.15 * paint if cond.snow else paint))
    return base


SPOTS_PER_M2 = 0.6  # stones, tar patches and tufts per square metre


def _scatter_spots(
    img: np.ndarray, classes: np.ndarray, colors: np.ndarray, raster: _Raster, rng: np.random.Generator
) -> None:
    """Scatter small darker/lighter blobs (0.05-0.3 m): the stable, blob-like detail SIFT keys on."""
    H, W = classes.shape
    n = int(SPOTS_PER_M2 * H * W * raster.res_m**2)
    cols, rows = rng.uniform(0, W, n), rng.uniform(0, H, n)
    radii = np.maximum(1, (rng.uniform(0.05, 0.3, n) / raster.res_m)).astype(int)
    factors = rng.choice([0.55, 0.7, 1.3, 1.5], n)
    aspect = rng.uniform(0.5, 1.0, n)
    angles = rng.uniform(0, 180, n)
    for c, r, rad, f, a, ang in zip(cols.astype(int), rows.astype(int), radii, factors, aspect, angles):
        color = tuple(float(v) for v in np.minimum(colors[classes[r, c]] * f, 255))
        cv2.ellipse(img, (int(c), int(r)), (int(rad), max(1, int(rad * a))), float(ang), 0, 360, color, -1, cv2.LINE_AA)


def _slab_joints(lum: np.ndarray, raster: _Raster, classes: np.ndarray) -> None:
    """Darken joints between sidewalk slabs (world-anchored SLAB_M grid) in ``lum`` in place."""
    H, W = raster.shape
    x = raster.origin_xy[0] + raster.res_m * np.arange(W)
    y = raster.origin_xy[1] + raster.res_m * np.arange(H)
    jx = np.abs(((x + SLAB_M / 2) % SLAB_M) - SLAB_M / 2) < 0.6 * raster.res_m + 0.02
    jy = np.abs(((y + SLAB_M / 2) % SLAB_M) - SLAB_M / 2) < 0.6 * raster.res_m + 0.02
    joint = (jy[:, None] | jx[None, :]) & (classes == SIDEWALK)
    lum[joint] *= 0.7


def _markings(img: np.ndarray, road: RoadMap, raster: _Raster, color, line_type: int = cv2.LINE_AA) -> None:
    """Paint lane borders into ``img``: solid lines whole, dashed lines as DASH_M/GAP_M dashes."""
    thick = raster.width_px(MARKING_WIDTH_M)
    for b in road.boundaries:
        if b.line_type == "none" or len(b.points_xy) < 2:
            continue
        pieces = [b.points_xy] if b.line_type == "solid" else _dashes(b.points_xy)
        cv2.polylines(img, [raster.px(p) for p in pieces if len(p) >= 2], False, color, thick, line_type, 4)


def _dashes(points_xy: np.ndarray) -> list[np.ndarray]:
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points_xy, axis=0), axis=1))])
    out = []
    for start in np.arange(0.0, s[-1], DASH_M + GAP_M):
        ts = np.linspace(start, min(start + DASH_M, s[-1]), 4)
        out.append(np.stack([np.interp(ts, s, points_xy[:, 0]), np.interp(ts, s, points_xy[:, 1])], axis=1))
    return out


def _tyre_tracks(img: np.ndarray, road: RoadMap, raster: _Raster, color) -> None:
    """Two darker wheel tracks per lane in the snow, 0.85 m either side of the centre line."""
    for c in road.lane_centers:
        if len(c) < 2:
            continue
        n = polyline_normals(c)
        for off in (-0.85, 0.85):
            cv2.polylines(img, [raster.px(c + off * n)], False, color, raster.width_px(0.5), cv2.LINE_AA, 4)


def _lamp_pools(raster: _Raster, lamp_xy: np.ndarray, radius_m: float = 9.0) -> np.ndarray:
    """Street-lamp light on the ground (H, W) float32 in [0, ~1]: a Gaussian pool under each lamp head."""
    scale = 8
    small = np.zeros((raster.shape[0] // scale + 1, raster.shape[1] // scale + 1), np.float32)
    centers = (lamp_xy - raster.origin_xy) / (raster.res_m * scale)
    for c in centers:
        cv2.circle(
            small, (int(round(c[0])), int(round(c[1]))), max(1, int(radius_m / 2 / (raster.res_m * scale))), 1.0, -1
        )
    small = cv2.GaussianBlur(small, (0, 0), radius_m / 2 / (raster.res_m * scale))
    return cv2.resize(small, (small.shape[1] * scale, small.shape[0] * scale), interpolation=cv2.INTER_LINEAR)[
        : raster.shape[0], : raster.shape[1]
    ]


def build_detail(seed: int) -> list[np.ndarray]:
    """World-anchored fine grain: a tileable relative-luminance map (uint8, 128 = 1.0) and its mip
    levels, multiplied onto the near ground where the drive texture is coarser than a pixel."""
    rng = np.random.default_rng([seed, 111])
    n = DETAIL_TEXELS
    grain = rng.standard_normal((n, n)).astype(np.float32)
    lum = 0.3 * grain + 3.0 * _wrap_blur(grain, 2.5) + 6.0 * _wrap_blur(grain, 6.0)
    lum = 128.0 * (1.0 + 0.22 * lum / lum.std())
    levels = [np.clip(lum, 0, 255).astype(np.uint8)]
    for _ in range(DETAIL_LEVELS - 1):
        levels.append(cv2.pyrDown(levels[-1]))
    return levels


def _wrap_blur(img: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian blur of a periodic tile (padded by wrapping, so the tile stays seamless)."""
    pad = int(4 * sigma) + 1
    return cv2.GaussianBlur(np.pad(img, pad, mode="wrap"), (0, 0), sigma)[pad:-pad, pad:-pad]
