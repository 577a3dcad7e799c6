"""EuRoC V1_01_easy stereo pairs (../shared/data/stereo/euroc_v101) as drivewm Cameras."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import yaml

from drivewm.geometry import Camera, invert_T


def load_euroc_camera(sensor_yaml: Path, name: str) -> Camera:
    """A Camera from an EuRoC sensor.yaml; ``T_ego_from_cam`` is the file's T_BS (body from sensor)."""
    text = sensor_yaml.read_text().replace("%YAML:1.0", "")
    d = yaml.safe_load(text)
    fu, fv, cu, cv = d["intrinsics"]
    K = np.array([[fu, 0, cu], [0, fv, cv], [0, 0, 1.0]])
    T = np.asarray(d["T_BS"]["data"], dtype=np.float64).reshape(4, 4)
    width, height = d["resolution"]
    return Camera(name, K, width, height, T, np.asarray(d["distortion_coefficients"], dtype=np.float64))


def load_euroc(root: Path) -> tuple[Camera, Camera, np.ndarray, list[tuple[np.ndarray, np.ndarray]]]:
    """(cam0, cam1, T_cam1_from_cam0, [(image0 RGB, image1 RGB), ...]) of the 19 stereo pairs."""
    cam0 = load_euroc_camera(root / "mav0/cam0/sensor.yaml", "cam0")
    cam1 = load_euroc_camera(root / "mav0/cam1/sensor.yaml", "cam1")
    T_cam1_from_cam0 = invert_T(cam1.T_ego_from_cam) @ cam0.T_ego_from_cam
    pairs = []
    for p0 in sorted((root / "mav0/cam0/data").glob("*.png")):
        p1 = root / "mav0/cam1/data" / p0.name
        read = lambda p: cv2.cvtColor(cv2.imread(str(p), cv2.IMREAD_GRAYSCALE), cv2.COLOR_GRAY2RGB)  # noqa: E731
        pairs.append((read(p0), read(p1)))
    return cam0, cam1, T_cam1_from_cam0, pairs
