"""The renderer: scene state + rig -> one uint8 RGB image per camera, exact pinhole geometry.

Per pixel, the nearest of two kinds of surface wins (z-buffer on camera depth):
- the ground plane z = 0, textured by a world-anchored top-down map rasterised once per drive
  from the real lane geometry (:mod:`drivewm.sim.ground`), looked up with ``cv2.remap``;
- oriented boxes (vehicles, buildings, lamps, trees), each face a homography-warped texture
  (:mod:`drivewm.sim.boxes`), culled per camera by bounding sphere against the frustum.
Then the condition's per-frame effects: depth fog (Koschmieder), ego headlights, snow flakes
or rain streaks. Same seed, same pixels: every random choice comes from the drive seed.

With ``labels``, each image comes with its exact label map ((H, W) uint8 ids of
:data:`drivewm.layout.classes.LABEL_CLASSES`), drawn in the same pass with the same geometry and
z-buffer: a ground pixel takes the label of the ground texel its ray hits (level 0, nearest: road,
lane paint, sidewalk, kerb, terrain; terrain beyond the drawn range), a box pixel its box's class
(vehicle, building, vegetation, pole), every other pixel is sky. Fog, headlights and weather
particles change the colours only: the label is that of the surface behind them.

Speed (benchmarks/bench_render.py, see docs/simulator.md), CPU time of one core on the busy
2-core development machine, nuscenes6 rig: 150-280 camera-frames/s at 320x192 and 70-125 at
640x360. A 6-camera tick at 320x192 (22-35 ms) costs about 1.9x a highway-env step with 30
vehicles and far more than a SUMO step: the renderer, not the traffic, sets the pace of a drive.
"""

from __future__ import annotations

import cv2
import numpy as np

from drivewm.errors import DrivewmError
from drivewm.geometry import Rig, invert_T
from drivewm.layout.classes import LABEL_ID
from drivewm.logs.types import AgentBox
from drivewm.sim.boxes import BoxSet, FaceTextures, draw_boxes
from drivewm.sim.camera_view import CameraView
from drivewm.sim.conditions import Condition, fog_weight
from drivewm.sim.ground import DETAIL_RES_M, MIP_LEVELS, GroundTexture, build_detail, build_ground
from drivewm.sim.particles import ParticleOverlays
from drivewm.sim.road_edges import stable_unit
from drivewm.sim.scene import RoadMap
from drivewm.sim.textures import object_textures


class Renderer:
    """Renders one drive: built once from the static world, then called per tick."""

    def __init__(
        self,
        rig: Rig,
        road: RoadMap,
        cond: Condition,
        seed: int,
        lo_xy: np.ndarray,
        hi_xy: np.ndarray,
        urban: bool,
        max_range_m: float = 150.0,
        labels: bool = False,
    ):
        self.rig, self.cond, self.seed, self.max_range_m = rig, cond, seed, max_range_m
        lamps = np.array([b.center_xyz[:2] for b in road.props if b.category == "lamp"]).reshape(-1, 2)
        self.ground = build_ground(road, lo_xy, hi_xy, cond, seed, urban, lamps, labels=labels)
        self.detail = build_detail(seed)
        self.views = [CameraView.build(c, self.ground.res_m, MIP_LEVELS, cond, max_range_m) for c in rig.cameras]
        rng = np.random.default_rng([seed, 303])
        textures = [FaceTextures.from_dict(object_textures(b, cond, rng)) for b in road.props]
        self.static = BoxSet.from_boxes(road.props, textures, cond.face_shade, bake=True)
        self.particles = ParticleOverlays(rig, cond, seed)
        self._agent_tex: dict[str, FaceTextures] = {}

    def render(
        self, T_world_from_ego: np.ndarray, agents: list[AgentBox], timestamp_ns: int = 0
    ) -> dict[str, np.ndarray]:
        """Images (H, W, 3) uint8 RGB per camera name for the ego at ``T_world_from_ego``."""
        moving = self._moving(agents)
        return {v.name: self._render_view(v, T_world_from_ego, moving, timestamp_ns) for v in self.views}

    def render_with_labels(
        self, T_world_from_ego: np.ndarray, agents: list[AgentBox], timestamp_ns: int = 0
    ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
        """Images (H, W, 3) uint8 RGB and label maps (H, W) uint8 per camera name (a renderer built with
        ``labels=True``); the images are those :meth:`render` gives."""
        moving = self._moving(agents)
        out = {v.name: self._render_view_labels(v, T_world_from_ego, moving, timestamp_ns) for v in self.views}
        return {n: img for n, (img, _) in out.items()}, {n: lab for n, (_, lab) in out.items()}

    def render_camera(
        self, camera: str, T_world_from_ego: np.ndarray, agents: list[AgentBox], timestamp_ns: int
    ) -> np.ndarray:
        """One camera's image (H, W, 3) uint8 RGB, for a world state of its own (staggered exposures)."""
        view = next(v for v in self.views if v.name == camera)
        return self._render_view(view, T_world_from_ego, self._moving(agents), timestamp_ns)

    def render_camera_with_labels(
        self, camera: str, T_world_from_ego: np.ndarray, agents: list[AgentBox], timestamp_ns: int
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`render_camera` with the label map (H, W) uint8 of the same pass."""
        view = next(v for v in self.views if v.name == camera)
        return self._render_view_labels(view, T_world_from_ego, self._moving(agents), timestamp_ns)

    def _moving(self, agents: list[AgentBox]) -> BoxSet:
        return BoxSet.from_boxes(agents, [self._agent_textures(a) for a in agents], self.cond.face_shade)

    def _agent_textures(self, agent: AgentBox) -> FaceTextures:
        if agent.track_id not in self._agent_tex:
            rng = np.random.default_rng([self.seed, 404, int(stable_unit(agent.track_id) * 2**32)])
            self._agent_tex[agent.track_id] = FaceTextures.from_dict(object_textures(agent, self.cond, rng))
        return self._agent_tex[agent.track_id]

    def _render_view(
        self,
        view: CameraView,
        T_world_from_ego: np.ndarray,
        moving: BoxSet,
        timestamp_ns: int,
        label_img: np.ndarray | None = None,
    ) -> np.ndarray:
        img = view.sky.copy()
        self._draw_ground(img, view, T_world_from_ego)
        zbuf = view.ground_z.copy()
        T_cam_from_world = view.T_cam_from_ego @ invert_T(T_world_from_ego)
        draw_boxes(img, zbuf, view, T_cam_from_world, self.static, self.max_range_m, label_img)
        draw_boxes(img, zbuf, view, T_cam_from_world, moving, self.max_range_m, label_img)
        img = self._fog(img, zbuf, view)
        self.particles.apply(img, view.name, timestamp_ns)
        return img

    def _render_view_labels(
        self, view: CameraView, T_world_from_ego: np.ndarray, moving: BoxSet, timestamp_ns: int
    ) -> tuple[np.ndarray, np.ndarray]:
        if self.ground.labels is None:
            raise DrivewmError("the renderer was built without labels: Renderer(..., labels=True)")
        labels = ground_labels(view, self.ground, T_world_from_ego)
        return self._render_view(view, T_world_from_ego, moving, timestamp_ns, labels), labels

    def _draw_ground(self, img: np.ndarray, view: CameraView, T_world_from_ego: np.ndarray) -> None:
        """Look up the ground texture at each ground pixel's world hit (a 2D rigid motion of the
        fixed ego-frame hits), multiply in the fine grain and the ego's headlights, scatter once."""
        colors = ground_colors(view, self.ground, T_world_from_ego)
        for part, level in view.detail_runs:
            tex = self.detail[level]
            grain_from_ego = _affine_from_ego(T_world_from_ego, np.zeros(2), DETAIL_RES_M * 2**level)
            tc = cv2.transform(view.ground_ego_xy[part], grain_from_ego)[:, 0] % tex.shape[0]
            gain = sample_points(tex, tc, cv2.BORDER_WRAP)
            colors[part] = cv2.multiply(colors[part], cv2.merge([gain, gain, gain]), scale=1.0 / 128.0)
        if view.headlight_gain is not None:
            colors = np.minimum(colors * view.headlight_gain, 255.0).astype(np.uint8)
        flat = img.reshape(-1, 3)
        flat[view.ground_idx] = colors
        flat[view.far_idx] = self.ground.border_rgb

    def _fog(self, img: np.ndarray, zbuf: np.ndarray, view: CameraView) -> np.ndarray:
        """Blend towards the fog colour by transmittance exp(-3.912 d / V) of each pixel's distance."""
        w = view.ground_fog.copy()
        boxes = zbuf < view.ground_z
        w[boxes] = fog_weight(zbuf[boxes] * view.ray_norm[boxes], self.cond.visibility_m)
        return cv2.blendLinear(img, view.fog_image, w, 1.0 - w)


def ground_colors(view: CameraView, ground: GroundTexture, T_world_from_ego: np.ndarray) -> np.ndarray:
    """Colours (N, 3) uint8 of the ground pixels ``view.ground_idx``: the texture of each one's mip
    level, bilinear, at its world hit (``ground.border_rgb`` outside the texture)."""
    colors = np.empty((len(view.ground_idx), 3), np.uint8)
    for level, part in enumerate(view.level_slices):
        if part.stop > part.start:
            texel_from_ego = ground.texel_from_ego(T_world_from_ego, level)
            tc = cv2.transform(view.ground_ego_xy[part], texel_from_ego)[:, 0]
            colors[part] = sample_points(ground.levels[level], tc, cv2.BORDER_CONSTANT, ground.border_rgb)
    return colors


def ground_labels(view: CameraView, ground: GroundTexture, T_world_from_ego: np.ndarray) -> np.ndarray:
    """The label map (H, W) uint8 of the ground alone: the level-0 label texel each ground pixel's ray
    hits (nearest; terrain outside the texture and beyond the drawn range), sky elsewhere."""
    labels = np.full((view.height, view.width), LABEL_ID["sky"], np.uint8)
    tc = cv2.transform(view.ground_ego_xy, ground.texel_from_ego(T_world_from_ego, 0))[:, 0]
    flat = labels.reshape(-1)
    flat[view.ground_idx] = sample_points(
        ground.labels, tc, cv2.BORDER_CONSTANT, LABEL_ID["terrain"], cv2.INTER_NEAREST
    )
    flat[view.far_idx] = LABEL_ID["terrain"]
    return labels


REMAP_ROW = 4096  # cv2.remap wants maps under 32767 rows/cols: points are laid out in rows of this many


def sample_points(
    tex: np.ndarray, coords: np.ndarray, border: int, border_value=0, interpolation: int = cv2.INTER_LINEAR
) -> np.ndarray:
    """Samples of ``tex`` (bilinear, or ``interpolation``) at float texel coordinates (N, 2) (col, row)
    -> (N, C) or (N,)."""
    n = len(coords)
    rows = -(-n // REMAP_ROW)
    grid = np.zeros((rows * REMAP_ROW, 2), np.float32)
    grid[:n] = coords
    grid = grid.reshape(rows, REMAP_ROW, 2)
    out = cv2.remap(tex, grid, None, interpolation, borderMode=border, borderValue=border_value)
    return out.reshape(rows * REMAP_ROW, *tex.shape[2:])[:n]


def _affine_from_ego(T_world_from_ego: np.ndarray, origin_xy: np.ndarray, texel_m: float) -> np.ndarray:
    """2x3 affine (cv2.transform) from ego-frame ground xy to texel (col, row) of a map with texel
    centre 0 at world ``origin_xy`` and ``texel_m`` metres per texel."""
    A = np.empty((2, 3))
    A[:, :2] = T_world_from_ego[:2, :2] / texel_m
    A[:, 2] = (T_world_from_ego[:2, 3] - origin_xy) / texel_m
    return A
