"""ClipLayout: every object a clip's log knows, per frame, in the clip's first ego frame.

The layout is the scene's structure without its look: oriented boxes of the road users (per
frame) and of the static objects (buildings, poles, trees: the same in every frame), and the
road as polylines (lane centres, lane borders with their paint, kerbs, surface outlines). All
geometry is in ``ego0``, the ego frame of the clip's first frame (x forward, y left, z up,
metres; docs/DESIGN.md section 3), so a layout does not depend on where the drive was in the
world; ``T_ego0_from_ego`` places each frame's ego, and a camera of a rig at frame t sits at
``T_ego0_from_ego[t] @ T_ego_from_cam``.

On disk it is the shard member ``KEY.layout.npz`` (:func:`layout_to_npz` / :func:`layout_from_npz`,
``np.load(allow_pickle=False)``): plain arrays, names as unicode arrays, nothing pickled.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from drivewm.errors import DrivewmError
from drivewm.geometry import Rig, invert_T
from drivewm.layout.classes import BOX_CLASSES, LINE_KINDS, PAINTS, check_word
from drivewm.npz import load_npz, npz_bytes

LAYOUT_FORMAT_VERSION = 1
#: The frame index of a static box: present in every frame.
STATIC = -1


@dataclasses.dataclass
class ClipLayout:
    """Boxes and road lines of one clip in its first frame's ego frame (``ego0``).

    Boxes are rows: ``box_frame`` (N,) int32 the frame a road user is seen in, :data:`STATIC` (-1)
    for a static object (every frame); ``box_class`` (N,) one of :data:`BOX_CLASSES`; ``box_track``
    (N,) the track id (the same road user keeps it over frames); ``box_center`` (N, 3) m;
    ``box_size`` (N, 3) length, width, height m; ``box_yaw`` (N,) rad, heading of the box's length
    axis about ego0's z from ego0's x. Boxes stand upright in ego0.
    Lines: line i is ``line_points[line_start[i]:line_start[i + 1]]`` (P, 3) m, of kind
    ``line_kind[i]`` (:data:`LINE_KINDS`; a ``road_surface`` is a closed polygon outline) and paint
    ``line_paint[i]`` (:data:`PAINTS`).
    Frames: ``timestamps_ns`` (T,) int64 and ``T_ego0_from_ego`` (T, 4, 4): the ego pose each frame's
    images were taken at. ego0 is the first frame's ego, and frame 0 the identity, but for a curated
    clip: there ego0 is the clip's first pose as ``KEY.ego.npy`` holds it (smoothed; the frame of its
    ``trajectory_ego``) and each frame sits at the log's own pose, so frame 0 is off the identity by the
    smoothing (centimetres).
    """

    timestamps_ns: np.ndarray
    T_ego0_from_ego: np.ndarray
    box_frame: np.ndarray
    box_class: np.ndarray
    box_track: np.ndarray
    box_center: np.ndarray
    box_size: np.ndarray
    box_yaw: np.ndarray
    line_kind: np.ndarray
    line_paint: np.ndarray
    line_start: np.ndarray
    line_points: np.ndarray

    @property
    def num_frames(self) -> int:
        return len(self.timestamps_ns)

    @property
    def num_boxes(self) -> int:
        return len(self.box_frame)

    def boxes_in_frame(self, t: int) -> np.ndarray:
        """Row indices of the boxes seen in frame ``t``: the static objects and that frame's road users."""
        return np.flatnonzero((self.box_frame == STATIC) | (self.box_frame == t))

    def line(self, i: int) -> np.ndarray:
        """Points (P, 3) of line ``i`` in ego0."""
        return self.line_points[self.line_start[i] : self.line_start[i + 1]]

    def validate(self, where: str) -> None:
        """Raise a one-line DrivewmError naming ``where`` (the clip) and the field: shapes that disagree,
        non-finite poses or geometry, negative sizes, unknown classes, kinds or paints."""
        T, N, L = self.num_frames, self.num_boxes, len(self.line_kind)
        shapes = {
            "timestamps_ns": (T,),
            "T_ego0_from_ego": (T, 4, 4),
            "box_class": (N,),
            "box_track": (N,),
            "box_center": (N, 3),
            "box_size": (N, 3),
            "box_yaw": (N,),
            "line_paint": (L,),
            "line_start": (L + 1,),
        }
        for name, shape in shapes.items():
            if np.shape(getattr(self, name)) != shape:
                raise DrivewmError(
                    f"{where}: layout {name} has shape {np.shape(getattr(self, name))}, expected {shape}"
                )
        if T == 0:
            raise DrivewmError(f"{where}: layout has no frames")
        _check_finite(where, "T_ego0_from_ego", self.T_ego0_from_ego, "frame")
        for name in ("box_center", "box_size", "box_yaw"):
            _check_finite(where, name, getattr(self, name), "box")
        _check_finite(where, "line_points", self.line_points, "point")
        if N and (self.box_size <= 0).any():
            raise DrivewmError(
                f"{where}: layout box_size must be > 0 (box {int(np.argmax((self.box_size <= 0).any(1)))})"
            )
        if N and ((self.box_frame < STATIC) | (self.box_frame >= T)).any():
            raise DrivewmError(f"{where}: layout box_frame must lie in [-1, {T - 1}]")
        start = self.line_start
        if start[0] != 0 or start[-1] != len(self.line_points) or (np.diff(start) < 0).any():
            raise DrivewmError(
                f"{where}: layout line_start does not index line_points ({len(self.line_points)} points)"
            )
        for values, allowed, field in (
            (self.box_class, BOX_CLASSES, "box_class"),
            (self.line_kind, LINE_KINDS, "line_kind"),
            (self.line_paint, PAINTS, "line_paint"),
        ):
            for value in set(values.tolist()):
                check_word(value, allowed, field, where)

    def check_seen_by(self, rig: Rig, where: str) -> None:
        """Raise a one-line DrivewmError when the layout has boxes but none stands in front of any camera
        of ``rig`` in any frame (a layout in the wrong frame, or of another drive)."""
        if self.num_boxes == 0:
            return
        centers = np.concatenate([self.box_center, np.ones((self.num_boxes, 1))], axis=1)  # (N, 4)
        for t in range(self.num_frames):
            rows = centers[self.boxes_in_frame(t)]
            for cam in rig.cameras:
                T_cam_from_ego0 = invert_T(self.T_ego0_from_ego[t] @ cam.T_ego_from_cam)
                if ((rows @ T_cam_from_ego0.T)[:, 2] > 0).any():
                    return
        raise DrivewmError(f"{where}: layout boxes: all {self.num_boxes} lie behind every camera of rig {rig.name}")


def _check_finite(where: str, field: str, values: np.ndarray, unit: str) -> None:
    bad = ~np.isfinite(np.asarray(values, dtype=np.float64))
    if bad.any():
        index = int(np.argwhere(bad)[0][0])
        raise DrivewmError(f"{where}: layout {field} is not finite ({unit} {index})")


FIELDS = tuple(f.name for f in dataclasses.fields(ClipLayout))
#: dtype of each array on disk (names as unicode strings).
DTYPES = {
    "timestamps_ns": np.int64,
    "T_ego0_from_ego": np.float64,
    "box_frame": np.int32,
    "box_class": np.str_,
    "box_track": np.str_,
    "box_center": np.float64,
    "box_size": np.float64,
    "box_yaw": np.float64,
    "line_kind": np.str_,
    "line_paint": np.str_,
    "line_start": np.int64,
    "line_points": np.float64,
}


def layout_to_npz(layout: ClipLayout) -> bytes:
    """The ``KEY.layout.npz`` bytes of ``layout`` (drivewm.npz: no pickles, the same layout the same bytes)."""
    arrays = {"format_version": np.int64(LAYOUT_FORMAT_VERSION)}
    arrays.update({name: np.asarray(getattr(layout, name), dtype=DTYPES[name]) for name in FIELDS})
    return npz_bytes(arrays)


def layout_from_npz(data: bytes, where: str) -> ClipLayout:
    """Parse and validate ``KEY.layout.npz`` bytes; a damaged or foreign file is a one-line DrivewmError."""
    arrays = load_npz(data, f"{where}: layout")
    version = arrays.pop("format_version", None)
    if version is None or int(version) != LAYOUT_FORMAT_VERSION:
        raise DrivewmError(f"{where}: layout format_version {version}, this drivewm reads {LAYOUT_FORMAT_VERSION}")
    missing = [name for name in FIELDS if name not in arrays]
    if missing:
        raise DrivewmError(f"{where}: layout lacks {missing}")
    layout = ClipLayout(**{name: _typed(arrays[name], name, where) for name in FIELDS})
    layout.validate(where)
    return layout


def _typed(values: np.ndarray, name: str, where: str) -> np.ndarray:
    want = DTYPES[name]
    if want is np.str_:
        if values.dtype.kind != "U":
            raise DrivewmError(f"{where}: layout {name} must hold strings, got {values.dtype}")
        return values
    if values.dtype.kind not in "iuf" or (np.dtype(want).kind in "iu" and values.dtype.kind == "f"):
        raise DrivewmError(f"{where}: layout {name} has dtype {values.dtype}, expected {np.dtype(want)}")
    return values.astype(want)
