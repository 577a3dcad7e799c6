"""The layout renderer: a clip's layout drawn into every camera of any rig, a scenario-map video.

Per camera and frame, with the simulator's own exact pinhole machinery (:mod:`drivewm.sim.camera_view`,
:mod:`drivewm.sim.boxes`):
- the ground: a top-down map of the layout, rasterised once per clip in ego0 (road surface, then
  lane borders coloured by paint and kerbs on it), looked up at each ground pixel's hit through its
  mip level, as the simulator draws its ground (the ground is the plane z = 0 of each frame's ego);
- the boxes: solid cuboids coloured by class, shaded by a fixed light, the front face and the
  front of the sides and top lighter (the heading cue), each face clipped at the near plane and
  filled by the pixel-centre rule, depth-ordered by a z-buffer against the ground and each other;
- sky black, ground off the road dark grey.
Output: uint8 RGB (V, T, H, W, 3) at the rig's size, and on request the label map of the same pass
(ids of :data:`drivewm.layout.classes.LABEL_CLASSES`).
"""

from __future__ import annotations

import dataclasses
import json
import math

import cv2
import numpy as np

from drivewm.config import above, at_least
from drivewm.errors import DrivewmError
from drivewm.geometry import Rig, invert_T
from drivewm.layout.classes import LABEL_ID, ROAD_USERS, label_id
from drivewm.layout.clip_layout import ClipLayout
from drivewm.logs.types import AgentBox
from drivewm.sim.boxes import BoxSet, FaceTextures, draw_boxes
from drivewm.sim.camera_view import CameraView
from drivewm.sim.conditions import condition_for
from drivewm.sim.ground import MIP_LEVELS, GroundTexture
from drivewm.sim.render import ground_colors, ground_labels

#: Box colours (RGB) by class: road users in blues and magentas, the static world in earth tones.
CLASS_RGB = {
    "car": (30, 110, 255),
    "van": (0, 190, 255),
    "truck": (120, 70, 255),
    "bus": (170, 40, 230),
    "motorcycle": (255, 120, 200),
    "bicycle": (255, 60, 160),
    "pedestrian": (255, 0, 90),
    "building": (210, 130, 70),
    "pole": (190, 190, 190),
    "lamp": (255, 240, 130),
    "trunk": (130, 85, 40),
    "crown": (40, 170, 60),
    "vegetation": (40, 170, 60),
    "barrier": (230, 200, 0),
    "sign": (255, 40, 40),
}
ROAD_RGB = (75, 75, 85)
OFF_ROAD_RGB = (28, 28, 28)
SKY_RGB = (0, 0, 0)
#: Line colours by (kind, paint); a kind or paint not listed is not drawn (lane centres are not paint).
LINE_RGB = {
    ("lane_boundary", "solid"): (255, 255, 255),
    ("lane_boundary", "dashed"): (255, 210, 0),
    ("road_edge", ""): (255, 70, 50),
    ("road_edge", "solid"): (255, 70, 50),
    ("road_edge", "dashed"): (255, 70, 50),
}
LINE_WIDTH_M = 0.3
#: Width of a lane border in the label map (m): paint's own width (the simulator paints 0.15 m,
#: drivewm.sim.ground.MARKING_WIDTH_M); the colour map draws lines wider to be seen far away.
PAINT_WIDTH_M = 0.15
#: Fixed light for the box shading (unit vector in ego0, from above and the front left).
LIGHT_DIR = np.array([0.3, 0.4, 0.866]) / np.linalg.norm([0.3, 0.4, 0.866])


@dataclasses.dataclass
class LayoutRenderConfig:
    """How a layout is drawn."""

    max_range_m: float = 150.0
    """Ground and boxes farther than this from a camera are not drawn."""
    map_margin_m: float = 160.0
    """The ground map covers the clip's ego path and this much around it (beyond: off-road colour)."""
    texel_m: float = 0.12
    """Ground map texel (m), coarser only where the map would exceed ``max_map_texels``. One texel size
    for every clip lets clips of one rig share the cameras' precomputed rays (the renderer's set-up)."""
    max_map_texels: int = 12_000_000
    """Texels of the ground map at most."""

    def validate(self) -> None:
        above(self, 0, "max_range_m", "texel_m", "max_map_texels")
        at_least(self, 0, "map_margin_m")


class LayoutRenderer:
    """Renders one layout into every camera of ``rig``: built once (ground map, static boxes, camera
    rays), then :meth:`render` or :meth:`render_frame`."""

    def __init__(self, rig: Rig, layout: ClipLayout, cfg: LayoutRenderConfig | None = None):
        sizes = {(c.width, c.height) for c in rig.cameras}
        if len(sizes) > 1:
            raise DrivewmError(f"rig {rig.name}: cameras of several sizes {sorted(sizes)}; scale the rig to one size")
        self.rig, self.layout, self.cfg = rig, layout, cfg or LayoutRenderConfig()
        self.cfg.validate()
        self.ground = _ground_map(layout, self.cfg)
        cond = condition_for("clear", "day")  # CameraView precomputes a sky and fog the renderer does not use
        self.views = [
            CameraView.build(c, self.ground.res_m, MIP_LEVELS, cond, self.cfg.max_range_m) for c in rig.cameras
        ]
        static = np.flatnonzero(layout.box_frame == -1)
        self.static = _box_set(layout, static)
        self._frames = [_box_set(layout, np.flatnonzero(layout.box_frame == t)) for t in range(layout.num_frames)]

    def render(self, labels: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Every camera and frame: uint8 RGB (V, T, H, W, 3), all cameras at one size (the rig's); with
        ``labels`` also the label maps (V, T, H, W) uint8."""
        frames = [self.render_frame(t, labels) for t in range(self.layout.num_frames)]
        if not labels:
            return np.stack(frames, axis=1)
        return np.stack([f[0] for f in frames], axis=1), np.stack([f[1] for f in frames], axis=1)

    def render_frame(self, t: int, labels: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Frame ``t`` in every camera: (V, H, W, 3) uint8 RGB (and (V, H, W) label maps)."""
        T_ego0_from_ego = self.layout.T_ego0_from_ego[t]
        out = [self._view(v, T_ego0_from_ego, self._frames[t], labels) for v in self.views]
        if not labels:
            return np.stack(out)
        return np.stack([img for img, _ in out]), np.stack([lab for _, lab in out])

    def _view(self, view: CameraView, T_ego0_from_ego: np.ndarray, moving: BoxSet, labels: bool):
        img = np.empty((view.height, view.width, 3), np.uint8)
        img[:] = SKY_RGB
        flat = img.reshape(-1, 3)
        flat[view.ground_idx] = ground_colors(view, self.ground, T_ego0_from_ego)
        flat[view.far_idx] = OFF_ROAD_RGB
        label_img = ground_labels(view, self.ground, T_ego0_from_ego) if labels else None
        zbuf = view.ground_z.copy()
        T_cam_from_ego0 = view.T_cam_from_ego @ invert_T(T_ego0_from_ego)
        draw_boxes(img, zbuf, view, T_cam_from_ego0, self.static, self.cfg.max_range_m, label_img)
        draw_boxes(img, zbuf, view, T_cam_from_ego0, moving, self.cfg.max_range_m, label_img)
        return (img, label_img) if labels else img


def render_layout(rig: Rig, layout: ClipLayout, cfg: LayoutRenderConfig | None = None) -> np.ndarray:
    """The layout video of every camera: uint8 RGB (V, T, H, W, 3) (the rig's cameras share one size)."""
    return LayoutRenderer(rig, layout, cfg).render()


# ----------------------------------------------------------------------------- the ground map

#: The cameras' precomputed rays and ground hits (drivewm.sim.camera_view) of the last rigs rendered, by
#: (rig, texel size, range): they depend on nothing else, and cost as much as drawing a few frames.
_VIEWS: dict[tuple[str, float, float], list[CameraView]] = {}


def _views(rig: Rig, texel_m: float, max_range_m: float) -> list[CameraView]:
    key = (json.dumps(rig.to_dict(), sort_keys=True), texel_m, max_range_m)
    if key not in _VIEWS:
        cond = condition_for("clear", "day")  # CameraView also precomputes a sky and fog the layout does not use
        if len(_VIEWS) >= 4:
            del _VIEWS[next(iter(_VIEWS))]
        _VIEWS[key] = [CameraView.build(c, texel_m, MIP_LEVELS, cond, max_range_m) for c in rig.cameras]
    return _VIEWS[key]


def _ground_map(layout: ClipLayout, cfg: LayoutRenderConfig) -> GroundTexture:
    """The layout's road drawn top-down in ego0 around the clip's ego path, with its mip pyramid, and
    the label of each level-0 texel (road, lane paint, terrain)."""
    path = layout.T_ego0_from_ego[:, :2, 3]
    lo, hi = path.min(axis=0) - cfg.map_margin_m, path.max(axis=0) + cfg.map_margin_m
    ext = hi - lo
    res = max(cfg.texel_m, math.sqrt(ext[0] * ext[1] / cfg.max_map_texels))
    shape = (int(math.ceil(ext[1] / res)) + 1, int(math.ceil(ext[0] / res)) + 1)
    rgb = np.empty((*shape, 3), np.uint8)
    rgb[:] = OFF_ROAD_RGB
    labels = np.full(shape, LABEL_ID["terrain"], np.uint8)
    px = lambda p: np.round((p[:, :2] - lo) / res * 16).astype(np.int32)  # noqa: E731  4 fractional bits
    surfaces = [px(layout.line(i)) for i in np.flatnonzero(layout.line_kind == "road_surface")]
    surfaces = [s for s in surfaces if len(s) >= 3]
    cv2.fillPoly(rgb, surfaces, ROAD_RGB, cv2.LINE_8, 4)
    cv2.fillPoly(labels, surfaces, LABEL_ID["road"], cv2.LINE_8, 4)
    thick, paint_thick = max(1, int(round(LINE_WIDTH_M / res))), max(1, int(round(PAINT_WIDTH_M / res)))
    for i, (kind, paint) in enumerate(zip(layout.line_kind, layout.line_paint)):
        color = LINE_RGB.get((str(kind), str(paint)))
        if color is None or kind == "road_surface":
            continue
        cv2.polylines(rgb, [px(layout.line(i))], False, color, thick, cv2.LINE_AA, 4)
        if kind == "lane_boundary":
            cv2.polylines(labels, [px(layout.line(i))], False, LABEL_ID["lane_paint"], paint_thick, cv2.LINE_8, 4)
    levels = [rgb]
    for _ in range(MIP_LEVELS - 1):
        levels.append(cv2.pyrDown(levels[-1]))
    return GroundTexture(lo, res, levels, OFF_ROAD_RGB, labels)


# ----------------------------------------------------------------------------- the boxes


def _box_set(layout: ClipLayout, rows: np.ndarray) -> BoxSet:
    """The boxes of ``rows`` as a BoxSet in ego0, each face a solid shaded colour (baked)."""
    boxes = [
        AgentBox(
            str(layout.box_track[r]),
            str(layout.box_class[r]),
            layout.box_center[r],
            layout.box_size[r],
            float(layout.box_yaw[r]),
        )
        for r in rows
    ]
    textures = [_class_textures(b.category) for b in boxes]
    labels = np.array([label_id(b.category) for b in boxes], np.uint8)
    boxes = BoxSet.from_boxes(boxes, textures, _shade, bake=True, labels=labels)
    # solid faces: exact pixel-centre coverage; nearest first, so that hidden faces are skipped
    return dataclasses.replace(boxes, interpolation=cv2.INTER_NEAREST, front_to_back=True)


def _shade(normals: np.ndarray) -> np.ndarray:
    """Brightness of faces with outward normals (..., 3): ambient plus Lambert under :data:`LIGHT_DIR`."""
    return 0.55 + 0.45 * np.maximum(0.0, normals @ LIGHT_DIR)


_TEXTURES: dict[str, FaceTextures] = {}


def _class_textures(box_class: str) -> FaceTextures:
    """Face textures of a class (cached): its colour, the front face and the front texel of the sides and
    top lighter for road users (the heading cue); one colour for static objects."""
    if box_class not in _TEXTURES:
        base = np.array(CLASS_RGB[box_class], np.float32)
        light = base * 0.35 + 255 * 0.65
        heading = box_class in ROAD_USERS
        texel = lambda c: np.asarray(c, np.uint8).reshape(1, 1, 3)  # noqa: E731
        row = np.stack([light if heading else base, base, base, base]).astype(np.uint8)  # front first
        faces = {
            "front": texel(light if heading else base),
            "back": texel(base),
            "left": row[None],  # texture columns run front to back on the left face
            "right": row[::-1][None],  # and back to front on the right face
            "top": row[:, None],  # rows run front to back on the top
            "bottom": texel(base),
        }
        _TEXTURES[box_class] = FaceTextures.from_dict(faces)
    return _TEXTURES[box_class]
