"""Synthetic drive logs for the curation tests: a textured world seen by a rig moving along x.

Every camera sees its own crop of a smooth random texture that slides with the ego motion, so
frames are sharp, well exposed, never frozen, and different logs (seeds) never look alike.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from drivewm.geometry import T_from_xyz_yaw, load_rig
from drivewm.logs.types import DriveLog, ImageFrame, SceneInfo

T0_NS = 1_700_000_000_000_000_000


def texture(seed: int, H: int, W: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    base = rng.integers(0, 256, (H // 6, W // 6, 3), dtype=np.uint8)
    return cv2.resize(base, (W, H), interpolation=cv2.INTER_CUBIC)


def make_log(
    path: str | Path,
    seed: int = 0,
    rig: str = "front3",
    n_frames: int = 40,
    fps: float = 10.0,
    speed_mps: float = 8.0,
    drop: dict[str, list[int]] | None = None,
    nan_poses: list[int] = (),
    corrupt: dict[str, list[int]] | None = None,
    jitter_ns: int = 0,
    tags: dict | None = None,
) -> DriveLog:
    """A DriveLog (not written). ``drop``: camera -> frame indices missing; ``nan_poses``: pose
    indices set to NaN; ``corrupt``: camera -> frame indices whose JPEG bytes are garbage; ``jitter_ns``:
    per-camera constant time offsets up to this."""
    rig_ = load_rig(rig)
    W, H = rig_.cameras[0].width, rig_.cameras[0].height
    tex = texture(seed, H * 2, W * 8)
    period = int(round(1e9 / fps))
    images = {}
    for v, cam in enumerate(rig_.cameras):
        offset = (v * jitter_ns) // max(1, len(rig_.cameras) - 1)
        frames = []
        for i in range(n_frames):
            if drop and i in drop.get(cam.name, []):
                continue
            x = int(v * W + i * speed_mps / fps * 2) % (tex.shape[1] - W)  # ~1.6 px per frame: no false shot cuts
            img = np.ascontiguousarray(tex[H // 2 : H // 2 + H, x : x + W])
            ok, jpg = cv2.imencode(".jpg", cv2.cvtColor(img, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 92])
            data = b"\xff\xd8 not a jpeg" if corrupt and i in corrupt.get(cam.name, []) else jpg.tobytes()
            frames.append(ImageFrame(T0_NS + i * period + offset, data, "jpeg"))
        images[cam.name] = frames
    t = T0_NS + np.arange(n_frames, dtype=np.int64) * period
    poses = np.stack(
        [
            T_from_xyz_yaw(speed_mps * i / fps, 0.02 * (speed_mps * i / fps) ** 2 / 10, 0.0, 0.004 * i)
            for i in range(n_frames)
        ]
    )
    for i in nan_poses:
        poses[i] = np.nan
    scene = SceneInfo(
        tags
        or {
            "weather": "clear",
            "time_of_day": "day",
            "road_type": "highway",
            "traffic_density": "low",
            "source": "synthetic",
        },
        "a synthetic test drive",
    )
    return DriveLog(str(path), rig_, images, t, poses, scene)


def write_synth_log(path: str | Path, **kwargs) -> Path:
    from drivewm.logs.writer import write_log

    return write_log(make_log(path, **kwargs), path)


def write_long_log(
    path: str | Path, seconds: float, moving_s: float, rig: str = "nuscenes6", fps: float = 10.0, seed: int = 0
) -> Path:
    """A long drive written message by message (nothing held): every camera cycles through 25
    pre-encoded crops of a sliding texture; the ego drives at 8 m/s for ``moving_s`` seconds and
    then stands still (those clips are dropped as standing still, after decoding and filtering)."""
    from drivewm.logs.writer import LogWriter

    rig_ = load_rig(rig)
    W, H = rig_.cameras[0].width, rig_.cameras[0].height
    tex = texture(seed, H * 2, W * 8)
    jpegs = {}
    for v, cam in enumerate(rig_.cameras):
        crops = [
            np.ascontiguousarray(tex[H // 2 : H // 2 + H, (v * W + 2 * i) % (tex.shape[1] - W) :][:, :W])
            for i in range(25)
        ]
        jpegs[cam.name] = [
            cv2.imencode(".jpg", c[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, 92])[1].tobytes() for c in crops
        ]
    scene = SceneInfo({"weather": "clear", "time_of_day": "day", "source": "synthetic"}, "a long synthetic drive")
    period = int(round(1e9 / fps))
    with LogWriter(path, rig_, scene) as writer:
        for i in range(int(round(seconds * fps))):
            t = T0_NS + i * period
            writer.write_pose(t, T_from_xyz_yaw(8.0 * min(i / fps, moving_s), 0.0, 0.0, 0.0))
            for cam in rig_.cameras:
                writer.write_encoded_image(cam.name, t, jpegs[cam.name][i % 25], "jpeg")
    return Path(path)
