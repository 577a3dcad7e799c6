"""The clip: synchronized multi-camera frames, ego poses and metadata (docs/DESIGN.md section 4).

On disk a clip is ``KEY.CAMERA.mp4`` per camera, ``KEY.json`` (:class:`ClipMeta`),
``KEY.ego.npy`` (T_world_from_ego per frame, (T, 4, 4) float64), when its log knows the scene's
structure ``KEY.layout.npz`` (:class:`drivewm.layout.ClipLayout`), and when its log has label maps
``KEY.CAMERA.labels.npz`` per camera (:mod:`drivewm.layout.labels`), inside a WebDataset tar.
Generated samples use the same format, so the benchmark scores real and generated clips alike.
"""

from __future__ import annotations

import dataclasses
import json
import numbers

import numpy as np

from drivewm.clips.video import H264Encoder, decode_mp4, encode_mp4
from drivewm.config import from_dict
from drivewm.errors import DrivewmError
from drivewm.geometry import Rig, rig_from_dict
from drivewm.layout.clip_layout import ClipLayout, layout_from_npz
from drivewm.layout.labels import labels_from_npz
from drivewm.paths import check_name

CLIP_FORMAT_VERSION = 1


@dataclasses.dataclass
class ClipMeta:
    """``KEY.json``. Times are integer ns; the rig is at the clip's image size.

    ``trajectory_ego``: the future ego trajectory the multi-view model is conditioned on,
    (N, 3) waypoints (m) in the first frame's ego frame, spaced ``trajectory_dt_s`` apart
    starting one step after the first frame. ``quality``: filter scores by filter name.
    ``sync_error_ns``: worst camera skew against the reference clock over the clip.
    ``camera_timestamps_ns``: camera name -> the exposure time (ns) of each of its frames, as
    logged, for rigs whose cameras do not fire at the tick (staggered exposures, jitter); empty
    (and omitted from the JSON) when every camera's frames are exactly at ``timestamps_ns``. Read
    it through :meth:`camera_times_ns`, which falls back to ``timestamps_ns``.
    ``extra``: anything else (generated clips record model, prompt, seed, trajectory name).
    ``pair_id``: the same drive window in other conditions has the same id (simulated drives:
    ``<drive_id>-t<start tick>``, see drivewm.sim.paired); "" = no known partner.
    ``tags["ego_motion"] == "unknown"`` (clips of logs without ego poses, e.g. ``import-video``): the
    ego poses are identity placeholders and ``trajectory_ego`` is empty; read :attr:`ego_motion_known`.
    """

    key: str
    source_log: str
    start_time_ns: int
    fps: float
    timestamps_ns: list[int]
    rig: dict
    caption: str = ""
    view_captions: dict[str, str] = dataclasses.field(default_factory=dict)
    tags: dict[str, str] = dataclasses.field(default_factory=dict)
    quality: dict[str, float] = dataclasses.field(default_factory=dict)
    sync_error_ns: int = 0
    camera_timestamps_ns: dict[str, list[int]] = dataclasses.field(default_factory=dict)
    trajectory_ego: list[list[float]] = dataclasses.field(default_factory=list)
    trajectory_dt_s: float = 0.0
    extra: dict = dataclasses.field(default_factory=dict)
    pair_id: str = ""
    format_version: int = CLIP_FORMAT_VERSION

    @property
    def num_frames(self) -> int:
        return len(self.timestamps_ns)

    @property
    def cameras(self) -> list[str]:
        return [c["name"] for c in self.rig["cameras"]]

    @property
    def ego_motion_known(self) -> bool:
        """False for clips whose log had no ego poses: their ``KEY.ego.npy`` holds identity placeholders,
        which no reader may take for a car standing still."""
        return self.tags.get("ego_motion") != "unknown"

    def get_rig(self) -> Rig:
        """The rig, checked (camera names, finite invertible K, rigid poses)."""
        return rig_from_dict(self.rig, f"clip {self.key}")

    def camera_times_ns(self, camera: str) -> list[int]:
        """Exposure time (ns) of each frame of ``camera``: its own if recorded, else the clip's."""
        return self.camera_timestamps_ns.get(camera, self.timestamps_ns)

    def to_json(self) -> dict:
        data = dataclasses.asdict(self)
        if not self.camera_timestamps_ns:  # synchronized rigs: clips stay as they were before the field
            del data["camera_timestamps_ns"]
        return data

    @classmethod
    def from_json(cls, data: dict, where: str) -> ClipMeta:
        """Parse and check ``KEY.json`` (types, key, cameras, rig); fields of newer writers are ignored."""
        if not isinstance(data, dict):
            raise DrivewmError(f"{where}: clip metadata is not a JSON object")
        version = data.get("format_version")
        if version != CLIP_FORMAT_VERSION:
            raise DrivewmError(f"{where}: clip format_version {version!r}, this drivewm reads {CLIP_FORMAT_VERSION}")
        names = {f.name for f in dataclasses.fields(cls)}
        meta = from_dict(cls, {k: v for k, v in data.items() if k in names}, f"{where} metadata", finite=False)
        validate_meta(meta, where)
        return meta


@dataclasses.dataclass
class Clip:
    """One clip in memory. ``mp4`` holds the encoded video per camera (rig order); ``videos``
    decodes on first use to uint8 RGB (T, H, W, 3) per camera. ``layout_npz``: the
    ``KEY.layout.npz`` bytes, None for a clip whose log knew no layout (read with :meth:`layout`).
    ``labels_npz``: camera name -> ``KEY.CAMERA.labels.npz`` bytes, for the cameras with label maps
    (read with :meth:`labels`)."""

    meta: ClipMeta
    mp4: dict[str, bytes]
    T_world_from_ego: np.ndarray
    _decoded: dict[str, np.ndarray] = dataclasses.field(default_factory=dict, repr=False)
    layout_npz: bytes | None = dataclasses.field(default=None, repr=False)
    labels_npz: dict[str, bytes] = dataclasses.field(default_factory=dict, repr=False)

    @property
    def key(self) -> str:
        return self.meta.key

    @property
    def has_layout(self) -> bool:
        return self.layout_npz is not None

    def layout(self) -> ClipLayout | None:
        """The clip's layout (validated, one frame per clip frame), or None when its log had none."""
        if self.layout_npz is None:
            return None
        layout = layout_from_npz(self.layout_npz, f"clip {self.key}")
        if layout.num_frames != self.meta.num_frames:
            raise DrivewmError(
                f"clip {self.key}: layout has {layout.num_frames} frames, the clip {self.meta.num_frames}"
            )
        return layout

    def labels(self, camera: str) -> np.ndarray | None:
        """The label map of each of ``camera``'s frames, uint8 (T, H, W) at the clip's image size (ids of
        drivewm.layout.classes.LABEL_CLASSES; frame t labels image t), or None without label maps."""
        if camera not in self.labels_npz:
            return None
        labels = labels_from_npz(self.labels_npz[camera], f"clip {self.key} {camera}")
        cam = self.meta.get_rig().camera(camera)
        if labels.shape != (self.meta.num_frames, cam.height, cam.width):
            raise DrivewmError(
                f"clip {self.key} {camera}: labels are {labels.shape}, the video "
                f"({self.meta.num_frames}, {cam.height}, {cam.width})"
            )
        return labels

    def video(self, camera: str) -> np.ndarray:
        """Frames of one camera, uint8 RGB (T, H, W, 3)."""
        if camera not in self._decoded:
            if camera not in self.mp4:
                raise DrivewmError(f"clip {self.key}: no video for camera {camera!r}")
            self._decoded[camera] = decode_mp4(self.mp4[camera], self.meta.num_frames, f"clip {self.key} {camera}")
        return self._decoded[camera]

    def frames(self, camera: str, indices: list[int]) -> np.ndarray:
        """Some frames of one camera, uint8 RGB (len(indices), H, W, 3), converting only these from
        the decoded video (unless it is decoded already)."""
        if camera in self._decoded:
            return self._decoded[camera][indices]
        if camera not in self.mp4:
            raise DrivewmError(f"clip {self.key}: no video for camera {camera!r}")
        unique = sorted(set(indices))
        got = decode_mp4(self.mp4[camera], self.meta.num_frames, f"clip {self.key} {camera}", keep=unique)
        return got[[unique.index(i) for i in indices]]

    def videos(self) -> np.ndarray:
        """All cameras in rig order, uint8 (V, T, H, W, 3)."""
        return np.stack([self.video(c) for c in self.meta.cameras])


def clip_from_arrays(
    meta: ClipMeta,
    frames: dict[str, np.ndarray],
    T_world_from_ego: np.ndarray,
    crf: int = 18,
    preset: str = "veryfast",
    threads: int = 0,
    yuv_converter: str = "swscale",
    encoders: dict[str, H264Encoder] | None = None,
) -> Clip:
    """Encode per-camera uint8 (T, H, W, 3) arrays into a :class:`Clip` (validating the meta);
    ``crf``, ``preset``, ``threads``, ``yuv_converter``: the H.264 settings of
    :func:`drivewm.clips.video.encode_mp4`. ``encoders``: per camera an open encoder to use instead
    (its own settings apply), kept over the clips of a log (:class:`drivewm.clips.video.H264Encoder`)."""
    validate_meta(meta)
    if encoders is not None:
        mp4 = {c: encoders[c].encode(frames[c]) for c in meta.cameras}
    else:
        mp4 = {c: encode_mp4(frames[c], meta.fps, crf, preset, threads, yuv_converter) for c in meta.cameras}
    clip = Clip(meta, mp4, np.asarray(T_world_from_ego, dtype=np.float64))
    clip._decoded.update({c: frames[c] for c in meta.cameras})
    return clip


def validate_meta(meta: ClipMeta, where: str = "") -> None:
    """Raise DrivewmError if the metadata breaks the contract: the key and camera names become file
    names (``KEY.CAMERA.mp4``), so both must be safe names (drivewm.paths); the rig must load."""
    prefix = f"{where}: " if where else ""
    check_name(meta.key, f"{prefix}clip key")
    if not meta.fps > 0 or not np.isfinite(meta.fps) or meta.num_frames == 0:
        raise DrivewmError(f"{prefix}clip {meta.key}: needs a finite fps > 0 and at least one timestamp")
    _check_rig(meta)
    _check_trajectory(meta, prefix)
    for camera, times in meta.camera_timestamps_ns.items():
        if camera not in meta.cameras or len(times) != meta.num_frames:
            raise DrivewmError(
                f"clip {meta.key}: camera_timestamps_ns[{camera!r}] must name a rig camera and have "
                f"{meta.num_frames} times, got {len(times)}"
            )


def _check_trajectory(meta: ClipMeta, prefix: str) -> None:
    """``trajectory_ego`` is empty or finite (N, 3) waypoints, ``trajectory_dt_s`` finite and >= 0: the multi-view
    data and eval read them as arrays, where a ragged or NaN row would fail late or train on NaN."""
    waypoints = np.asarray(meta.trajectory_ego, dtype=object)
    ok = waypoints.size == 0 or (waypoints.ndim == 2 and waypoints.shape[1] == 3)
    ok = ok and all(isinstance(v, numbers.Real) and not isinstance(v, (bool, np.bool_)) for v in waypoints.ravel())
    if not ok or not np.isfinite(np.asarray(waypoints, dtype=np.float64)).all():
        raise DrivewmError(f"{prefix}clip {meta.key}: trajectory_ego must be finite [[x, y, z], ...] waypoints (m)")
    if not (np.isfinite(meta.trajectory_dt_s) and meta.trajectory_dt_s >= 0):
        raise DrivewmError(f"{prefix}clip {meta.key}: trajectory_dt_s must be finite and >= 0 s")


#: Rigs (canonical JSON) that loaded: a log's clips, or a shard's, share one rig, and checking its cameras
#: (intrinsics, rigid poses) costs ~1 ms for 6 cameras against ~0.09 ms for the JSON (curation checked every
#: clip's rig twice: clip_from_arrays and ShardWriter.write both validate).
_LOADED_RIGS: set[str] = set()


def _check_rig(meta: ClipMeta) -> None:
    """``meta.get_rig()`` (raises for a rig that does not load), skipped for a rig equal to one that loaded."""
    try:
        key = json.dumps(meta.rig, sort_keys=True, allow_nan=True)
    except (TypeError, ValueError):  # not plain JSON (numpy values): check it every time
        key = None
    if key is not None and key in _LOADED_RIGS:
        return
    meta.get_rig()
    if key is not None and len(_LOADED_RIGS) < 256:
        _LOADED_RIGS.add(key)
