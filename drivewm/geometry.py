"""Geometry shared by every stage: SE(3), quaternions, pinhole cameras, rigs, epipolar relations.

Conventions (docs/DESIGN.md section 3): world and ego are right-handed, z up; ego is x forward, y left,
origin on the ground under the rear axle. Cameras are OpenCV (x right, y down, z forward).
Transforms are 4x4 ``T_a_from_b`` mapping points in frame b into frame a. Points are (..., 3).
"""

from __future__ import annotations

import dataclasses
import difflib
from pathlib import Path

import numpy as np

from drivewm import resources
from drivewm.config import load_yaml
from drivewm.errors import DrivewmError
from drivewm.paths import check_name

RIGS_ENV = "DRIVEWM_RIGS"
"""Environment variable: folders (os.pathsep-separated) of the user's own NAME.yaml rigs, searched first."""

# Rotation taking OpenCV camera axes (x right, y down, z forward) to a z-up body frame looking
# along its +x (x forward, y left, z up): columns are the camera axes written in body coordinates.
R_BODY_FROM_OPENCV = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


# ----------------------------------------------------------------------------- SE(3)


def make_T(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """4x4 transform from a 3x3 rotation and a translation (3,)."""
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = np.asarray(t, dtype=np.float64).reshape(3)
    return T


def invert_T(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform (..., 4, 4), without a general matrix inverse."""
    R = T[..., :3, :3]
    t = T[..., :3, 3]
    out = np.zeros_like(T)
    Rt = np.swapaxes(R, -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, t)
    out[..., 3, 3] = 1.0
    return out


def transform_points(T_b_from_a: np.ndarray, points_a: np.ndarray) -> np.ndarray:
    """Map points (..., 3) in frame a into frame b."""
    return points_a @ T_b_from_a[:3, :3].T + T_b_from_a[:3, 3]


def rot_z(yaw_rad: float | np.ndarray) -> np.ndarray:
    """Rotation about +z by ``yaw_rad`` (counter-clockwise seen from above): (3, 3), or (..., 3, 3)
    for an array of angles."""
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    R = np.zeros((*np.shape(yaw_rad), 3, 3))
    R[..., 0, 0], R[..., 0, 1], R[..., 1, 0], R[..., 1, 1], R[..., 2, 2] = c, -s, s, c, 1.0
    return R


def euler_to_R(roll_rad: float, pitch_rad: float, yaw_rad: float) -> np.ndarray:
    """Rotation R = Rz(yaw) Ry(pitch) Rx(roll) (intrinsic z-y'-x'', ISO 8855 angles)."""
    cr, sr = np.cos(roll_rad), np.sin(roll_rad)
    cp, sp = np.cos(pitch_rad), np.sin(pitch_rad)
    Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    Ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    return rot_z(yaw_rad) @ Ry @ Rx


def T_from_xyz_yaw(x: float, y: float, z: float, yaw_rad: float) -> np.ndarray:
    """Planar pose: translation (x, y, z) and heading ``yaw_rad`` about +z."""
    return make_T(rot_z(yaw_rad), [x, y, z])


def yaw_of(T: np.ndarray) -> float:
    """Heading of a transform's x axis in the xy plane, radians."""
    return float(np.arctan2(T[1, 0], T[0, 0]))


def quat_xyzw_to_R(quat_xyzw: np.ndarray) -> np.ndarray:
    """Unit quaternion (x, y, z, w) -> 3x3 rotation. The input is normalised first."""
    x, y, z, w = np.asarray(quat_xyzw, dtype=np.float64) / np.linalg.norm(quat_xyzw)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def R_to_quat_xyzw(R: np.ndarray) -> np.ndarray:
    """3x3 rotation -> unit quaternion (x, y, z, w) with w >= 0 (Shepperd's method)."""
    m = np.asarray(R, dtype=np.float64)
    tr = np.trace(m)
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s]
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s, (m[1, 0] - m[0, 1]) / s]
    q = np.array(q)
    q /= np.linalg.norm(q)
    return q if q[3] >= 0 else -q


def nearest_rotation(M: np.ndarray) -> np.ndarray:
    """The rotation closest to a 3x3 matrix in the Frobenius norm: U diag(1, 1, det(U V^T)) V^T from
    the SVD M = U S V^T (the orthogonal Procrustes solution, Higham 1988). Rotations read from text
    (KITTI-style 3x4 poses with ~7 digits) are off orthonormal by ~1e-7; this puts them back."""
    U, _, Vt = np.linalg.svd(np.asarray(M, dtype=np.float64))
    S = np.eye(3)
    S[2, 2] = np.sign(np.linalg.det(U @ Vt))
    return U @ S @ Vt


def rotation_angle_deg(R: np.ndarray) -> float:
    """Angle of a rotation matrix in degrees (geodesic distance to identity), taken on the nearest
    rotation: arccos((tr R - 1) / 2) of a matrix off orthonormal by e is off by ~sqrt(e) rad near
    identity (1e-7 -> 0.03 deg), which would swamp small relative-pose errors."""
    c = np.clip((np.trace(nearest_rotation(R)) - 1.0) / 2.0, -1.0, 1.0)
    return float(np.degrees(np.arccos(c)))


def check_pose(T: np.ndarray, where: str) -> None:
    """Raise DrivewmError if ``T`` is not a finite rigid 4x4 transform."""
    T = np.asarray(T)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise DrivewmError(f"{where}: pose is not a finite 4x4 transform")
    R = T[:3, :3]
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-4) or np.linalg.det(R) < 0:
        raise DrivewmError(f"{where}: pose rotation is not orthonormal")


# ----------------------------------------------------------------------------- pinhole


def check_intrinsics(K: np.ndarray, where: str) -> None:
    """Raise DrivewmError unless ``K`` is a finite, invertible pinhole matrix
    [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0 (H&Z eq. 6.10)."""
    K = np.asarray(K)
    if K.shape != (3, 3) or not np.all(np.isfinite(K)):
        raise DrivewmError(f"{where}: K must be a finite 3x3 matrix")
    if K[0, 0] <= 0 or K[1, 1] <= 0:
        raise DrivewmError(f"{where}: K is singular or flipped (fx={K[0, 0]:g}, fy={K[1, 1]:g}; both must be > 0)")
    if not np.allclose(K[2], [0.0, 0.0, 1.0]) or K[1, 0] != 0:
        raise DrivewmError(f"{where}: K must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]], got {K.tolist()}")


def project(K: np.ndarray, points_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pinhole projection of camera-frame points (N, 3) -> pixels (N, 2) and depth z (N,).

    Pixel centres are at integer coordinates (OpenCV). Points with z <= 0 get NaN pixels.
    """
    z = points_cam[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = (points_cam[:, :2] / z[:, None]) @ K[:2, :2].T + K[:2, 2]
    uv[z <= 0] = np.nan
    return uv, z


def backproject(K: np.ndarray, uv: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """Pixels (N, 2) at depths z (N,) -> camera-frame points (N, 3)."""
    rays = pixel_rays(K, uv)
    return rays * np.asarray(depth)[:, None]


def pixel_rays(K: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Camera-frame ray directions with z = 1 for pixels (N, 2)."""
    xy = (uv - K[:2, 2]) @ np.linalg.inv(K[:2, :2]).T
    return np.concatenate([xy, np.ones((len(uv), 1))], axis=1)


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrix [v]_x of v (3,), or (..., 3, 3) of vectors (..., 3)."""
    v = np.asarray(v)
    out = np.zeros((*v.shape[:-1], 3, 3), dtype=np.result_type(v, np.float64))
    out[..., 0, 1], out[..., 0, 2], out[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    return out - np.swapaxes(out, -1, -2)


def essential_from_T(T_b_from_a: np.ndarray) -> np.ndarray:
    """Essential matrix E with x_b^T E x_a = 0 for normalised points of cameras a and b.

    E = [t]_x R (Hartley & Zisserman eq. 9.8) where (R, t) = T_b_from_a.
    """
    return skew(T_b_from_a[:3, 3]) @ T_b_from_a[:3, :3]


def fundamental_from_T(K_a: np.ndarray, K_b: np.ndarray, T_b_from_a: np.ndarray) -> np.ndarray:
    """Fundamental matrix F with x_b^T F x_a = 0 in pixels: F = K_b^-T E K_a^-1 (H&Z eq. 9.12)."""
    F = np.linalg.inv(K_b).T @ essential_from_T(T_b_from_a) @ np.linalg.inv(K_a)
    return F / np.linalg.norm(F)


def sampson_distance_sq(F: np.ndarray, x_a: np.ndarray, x_b: np.ndarray) -> np.ndarray:
    """Squared Sampson distance (px^2) of correspondences x_a <-> x_b (N, 2) under x_b^T F x_a = 0:
    (N,), or (H, N) for H matrices F (H, 3, 3) scored on the same correspondences.

    H&Z eq. 11.9: (x_b^T F x_a)^2 / ((F x_a)_1^2 + (F x_a)_2^2 + (F^T x_b)_1^2 + (F^T x_b)_2^2);
    the same quantity as OpenCV's ``cv2.sampsonDistance(x_a, x_b, F)``.
    """
    ha = np.concatenate([x_a, np.ones((len(x_a), 1))], axis=1)
    hb = np.concatenate([x_b, np.ones((len(x_b), 1))], axis=1)
    Fa = ha @ np.swapaxes(F, -1, -2)
    Fb = hb @ F
    num = np.sum(hb * Fa, axis=-1) ** 2
    den = Fa[..., 0] ** 2 + Fa[..., 1] ** 2 + Fb[..., 0] ** 2 + Fb[..., 1] ** 2
    return num / den


# ----------------------------------------------------------------------------- rigs


#: Largest image side (px) a camera may have: twice an 8K video's width, far beyond any automotive camera.
MAX_IMAGE_PX = 16384


@dataclasses.dataclass
class Camera:
    """One calibrated camera of a rig.

    ``K`` is the 3x3 pinhole matrix in pixels for an image of ``width`` x ``height``;
    ``distortion`` holds OpenCV coefficients (k1, k2, p1, p2[, k3...]) or is empty;
    ``T_ego_from_cam`` maps OpenCV camera-frame points into the ego frame.
    """

    name: str
    K: np.ndarray
    width: int
    height: int
    T_ego_from_cam: np.ndarray
    distortion: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))

    def __post_init__(self) -> None:
        """Every camera is checked where it is made (rig files, logs, clips), so a bad calibration is
        one clear error at the input, never a LinAlgError deep inside a metric."""
        where = f"camera {self.name!r}"
        check_name(self.name, "camera name")
        for side in ("width", "height"):  # a typo's 1e8 px had sized every frame buffer and video to it
            value = getattr(self, side)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 0 < value <= MAX_IMAGE_PX:
                raise DrivewmError(f"{where}: {side} must be a positive integer <= {MAX_IMAGE_PX}, got {value!r}")
        check_intrinsics(self.K, where)
        check_pose(self.T_ego_from_cam, f"{where} T_ego_from_cam")
        if not np.all(np.isfinite(self.distortion)):
            raise DrivewmError(f"{where}: distortion coefficients must be finite")

    def scaled(self, width: int, height: int, fit: str = "same") -> Camera:
        """The same camera after its images were resized to ``width`` x ``height``.

        Pixel centres are at integer coordinates, so a resize by s maps u to (u + 0.5) s - 0.5
        (what cv2.resize does): fx' = s fx, cx' = (cx + 0.5) s - 0.5. ``fit`` says how the image
        was resized when the aspect ratio changes: ``same`` (default) refuses an aspect change of
        more than one pixel of rounding, ``stretch`` scales each axis by its own ratio (cv2.resize
        to the new size; fx and fy then differ), ``crop`` scales both axes by the larger ratio and
        cuts the overflow evenly from both sides (centre crop, square pixels kept)."""
        sx, sy = width / self.width, height / self.height
        if fit == "same":
            if abs(self.width * sy - width) > 1.0 and abs(self.height * sx - height) > 1.0:
                raise DrivewmError(
                    f"camera {self.name}: {self.width}x{self.height} -> {width}x{height} changes the aspect ratio; "
                    "say whether the images were stretched or centre-cropped (fit='stretch' or 'crop')"
                )
        elif fit == "crop":
            sx = sy = max(sx, sy)
        elif fit != "stretch":
            raise DrivewmError(f"camera {self.name}: fit {fit!r} is not 'same', 'stretch' or 'crop'")
        # Centre crop: the scaled image is (W sx) x (H sy); (W sx - width) / 2 columns go on each side.
        off_x, off_y = (self.width * sx - width) / 2, (self.height * sy - height) / 2
        K = self.K.copy()
        K[0, :2] *= sx
        K[1, :2] *= sy
        K[0, 2] = (self.K[0, 2] + 0.5) * sx - 0.5 - off_x
        K[1, 2] = (self.K[1, 2] + 0.5) * sy - 0.5 - off_y
        return dataclasses.replace(self, K=K, width=width, height=height)

    def to_dict(self) -> dict:
        """YAML/JSON-ready dict (the rig-file layout)."""
        return {
            "name": self.name,
            "width": self.width,
            "height": self.height,
            "K": self.K.tolist(),
            "distortion": self.distortion.tolist(),
            "T_ego_from_cam": self.T_ego_from_cam.tolist(),
        }


@dataclasses.dataclass
class Rig:
    """An ordered list of cameras (docs/DESIGN.md section 3). Order is the view order in models."""

    name: str
    cameras: list[Camera]

    @property
    def names(self) -> list[str]:
        return [c.name for c in self.cameras]

    def camera(self, name: str) -> Camera:
        for c in self.cameras:
            if c.name == name:
                return c
        raise DrivewmError(f"rig {self.name}: no camera named {name!r} (has {self.names})")

    def scaled(self, width: int, height: int, fit: str = "same") -> Rig:
        """Every camera at a new image size (``fit``: see :meth:`Camera.scaled`)."""
        return Rig(self.name, [c.scaled(width, height, fit) for c in self.cameras])

    def subset(self, names: list[str]) -> Rig:
        """The cameras named, in that order."""
        return Rig(self.name, [self.camera(n) for n in names])

    def to_dict(self) -> dict:
        return {"name": self.name, "cameras": [c.to_dict() for c in self.cameras]}


def load_rig(name_or_path: str | Path) -> Rig:
    """Load a rig by name (``nuscenes6``) or YAML path. See ``drivewm/rigs/README.md``."""
    path = resources.find("rigs", name_or_path, "rig", env=RIGS_ENV)
    return rig_from_dict(load_yaml(path), str(path))


#: The keys of a rig, and of a camera in it (and in its ``defaults``); any other is refused, so a misspelt
#: ``yaw_dg`` or ``distorsion`` never leaves a calibration silently at its default.
RIG_KEYS = ("name", "defaults", "cameras")
CAMERA_KEYS = (
    "name", "width", "height", "K", "distortion", "T_ego_from_cam",
    "hfov_deg", "xyz", "roll_deg", "pitch_deg", "yaw_deg", "rotation_wxyz",
)  # fmt: skip


def rig_from_dict(data: dict, where: str = "rig") -> Rig:
    """Build a rig from its dict form: explicit ``K``/``T_ego_from_cam`` or the compact form
    (``hfov_deg``, ``xyz``, ``yaw_deg``/``pitch_deg``/``roll_deg``; see drivewm/rigs/README.md).
    Unknown keys are refused with the nearest known one suggested."""
    if not isinstance(data, dict) or not isinstance(data.get("cameras"), list) or not data["cameras"]:
        raise DrivewmError(f"{where}: a rig needs a non-empty 'cameras' list")
    check_keys(data, RIG_KEYS, where)
    defaults = data.get("defaults", {})
    if not isinstance(defaults, dict) or not all(isinstance(c, dict) for c in data["cameras"]):
        raise DrivewmError(f"{where}: 'defaults' and every entry of 'cameras' must be mappings")
    check_keys(defaults, CAMERA_KEYS, f"{where}: defaults")
    cams = [_camera_from_dict({**defaults, **c}, where, i) for i, c in enumerate(data["cameras"])]
    names = [c.name for c in cams]
    if len(set(names)) != len(names):
        raise DrivewmError(f"{where}: duplicate camera names {names}")
    return Rig(str(data.get("name", Path(where).stem)), cams)


def _camera_from_dict(d: dict, rig_where: str, index: int) -> Camera:
    """Camera ``index`` of a rig file; every value is checked, so a bad file is one DrivewmError naming the field."""
    if not isinstance(d.get("name"), str):
        raise DrivewmError(f"{rig_where}: camera {index}: 'name' must be a string, got {d.get('name')!r}")
    where = f"{rig_where}: camera {d['name']!r}"
    check_keys(d, CAMERA_KEYS, where)
    width, height = _integer(d, "width", where), _integer(d, "height", where)
    if "K" in d:
        K = _numbers(d["K"], (3, 3), f"{where} K")
    elif "hfov_deg" in d:
        hfov = float(_numbers(d["hfov_deg"], (), f"{where} hfov_deg"))
        if not 0 < hfov < 180:
            raise DrivewmError(f"{where}: hfov_deg must be in (0, 180), got {hfov}")
        f = 0.5 * width / np.tan(np.radians(hfov) / 2)
        K = np.array([[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1.0]])
    else:
        raise DrivewmError(f"{where}: give K or hfov_deg")
    if "T_ego_from_cam" in d:
        T = _numbers(d["T_ego_from_cam"], (4, 4), f"{where} T_ego_from_cam")
    elif "xyz" in d and "rotation_wxyz" in d:  # a calibration record: the OpenCV camera's rotation into ego
        w, x, y, z = _numbers(d["rotation_wxyz"], (4,), f"{where} rotation_wxyz")
        T = make_T(quat_xyzw_to_R(np.array([x, y, z, w])), _numbers(d["xyz"], (3,), f"{where} xyz"))
    elif "xyz" in d:
        angles = [float(_numbers(d.get(k, 0.0), (), f"{where} {k}")) for k in ("roll_deg", "pitch_deg", "yaw_deg")]
        R_ego_from_body = euler_to_R(*np.radians(angles))
        T = make_T(R_ego_from_body @ R_BODY_FROM_OPENCV, _numbers(d["xyz"], (3,), f"{where} xyz"))
    else:
        raise DrivewmError(f"{where}: give T_ego_from_cam or xyz + yaw_deg")
    dist = _numbers(d.get("distortion", []), None, f"{where} distortion").reshape(-1)
    try:
        return Camera(d["name"], K, width, height, T, dist)
    except DrivewmError as exc:
        raise DrivewmError(f"{rig_where}: {exc}") from None


def check_keys(d: dict, known: tuple[str, ...], where: str) -> None:
    """Refuse a key of ``d`` that is not in ``known``, suggesting the nearest known one (difflib)."""
    for key in d:
        if key not in known:
            near = difflib.get_close_matches(str(key), known, n=1, cutoff=0.6)
            hint = f"did you mean {near[0]!r}? " if near else ""
            raise DrivewmError(f"{where}: unknown key {key!r} ({hint}known: {', '.join(known)})")


def _integer(d: dict, key: str, where: str) -> int:
    value = d.get(key)
    if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
        raise DrivewmError(f"{where}: {key} must be a positive integer, got {value!r}")
    return value


def _numbers(value: object, shape: tuple[int, ...] | None, where: str) -> np.ndarray:
    """``value`` as a finite float64 array of ``shape`` (None: any 1-D length); ragged or non-numeric
    input is refused."""
    if isinstance(value, (str, bytes, bool)):
        raise DrivewmError(f"{where}: expected numbers, got {value!r}")
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (ValueError, TypeError, OverflowError):
        raise DrivewmError(f"{where}: expected {'x'.join(map(str, shape or ['N']))} numbers, got {value!r}") from None
    if (shape is not None and arr.shape != shape) or (shape is None and arr.ndim > 1) or not np.all(np.isfinite(arr)):
        raise DrivewmError(f"{where}: expected finite numbers of shape {shape or '(N,)'}, got {value!r}")
    return arr
