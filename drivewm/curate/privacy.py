"""Privacy: blur faces and licence plates before clips are encoded.

What is available: opencv-python-headless 5 ships neither the Haar cascades (``cv2.data`` holds
no XML; ``CascadeClassifier`` left for opencv_contrib) nor YuNet weights. So:

- faces: ``cv2.FaceDetectorYN`` (YuNet, Wu et al. 2023) when the user gives the ONNX file
  (``privacy.face_model``); without it, enabling privacy is an error rather than a silent no-op.
- plates: a classical detector (no weights, :func:`plate_candidates`). Measured on the 8 real
  dashcam stills in ../shared/data (8 legible plates, centres annotated by hand in
  tests/curate/test_privacy.py): it covers 4 of 8 plates with about 2 false boxes per image.
  A weak fallback: fleets that must anonymise should plug in a trained detector (any callable
  image -> boxes works in :class:`Anonymizer`).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from drivewm.curate.config import PrivacyConfig
from drivewm.errors import DrivewmError

Box = tuple[int, int, int, int]  # x, y, w, h in pixels


def blur_boxes(image_rgb: np.ndarray, boxes: list[Box], kernel_frac: float = 0.5) -> np.ndarray:
    """A copy of ``image_rgb`` with a strong Gaussian blur inside each box (clipped to the image)."""
    out = image_rgb.copy()
    H, W = out.shape[:2]
    for x, y, w, h in boxes:
        x0, y0, x1, y1 = max(0, x), max(0, y), min(W, x + w), min(H, y + h)
        if x1 - x0 < 2 or y1 - y0 < 2:
            continue
        k = max(3, int(min(x1 - x0, y1 - y0) * kernel_frac) | 1)
        out[y0:y1, x0:x1] = cv2.GaussianBlur(out[y0:y1, x0:x1], (k, k), 0)
    return out


class YuNetFaces:
    """Face boxes from OpenCV's YuNet (``cv2.FaceDetectorYN``) with a user-supplied ONNX model."""

    def __init__(self, model_path: str, score: float):
        if not Path(model_path).is_file():
            raise DrivewmError(f"privacy.face_model {model_path!r}: no such file (YuNet ONNX from opencv_zoo)")
        self.detector = cv2.FaceDetectorYN.create(model_path, "", (320, 320), score)

    def __call__(self, image_rgb: np.ndarray) -> list[Box]:
        H, W = image_rgb.shape[:2]
        self.detector.setInputSize((W, H))
        _, faces = self.detector.detect(cv2.cvtColor(image_rgb, cv2.COLOR_RGB2BGR))
        return [] if faces is None else [tuple(int(v) for v in f[:4]) for f in faces]


def plate_candidates(image_rgb: np.ndarray, tophat: float = 35.0) -> list[Box]:
    """Licence-plate-like regions: small bright rectangles (white top-hat, a plate is brighter than
    the car around it) of plate shape (aspect 1.5-3.5, 0.005-0.3 % of the image), mostly filled,
    with dark strokes (characters) inside and strong vertical edges."""
    grey = cv2.cvtColor(image_rgb, cv2.COLOR_RGB2GRAY)
    H, W = grey.shape
    k = max(9, W // 40)
    top = cv2.morphologyEx(grey, cv2.MORPH_TOPHAT, cv2.getStructuringElement(cv2.MORPH_RECT, (k, k // 2)))
    mask = cv2.morphologyEx((top > tophat).astype(np.uint8), cv2.MORPH_CLOSE, np.ones((3, 3), np.uint8))
    grad_x = np.abs(cv2.Sobel(grey, cv2.CV_32F, 1, 0))
    boxes = []
    for c in cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)[0]:
        x, y, w, h = cv2.boundingRect(c)
        if not (1.5 <= w / max(h, 1) <= 3.5 and 5e-5 <= w * h / (H * W) <= 3e-3 and cv2.contourArea(c) > 0.5 * w * h):
            continue
        roi = grey[y : y + h, x : x + w]
        dark = float((roi < roi.max() * 0.6).mean())
        if 0.03 < dark < 0.6 and float(grad_x[y : y + h, x : x + w].mean()) > 20:
            boxes.append((x, y, w, h))
    return boxes


class Anonymizer:
    """Blurs faces (YuNet) and plate candidates in every frame, counting what it blurred."""

    def __init__(self, cfg: PrivacyConfig):
        if cfg.faces and not cfg.face_model:
            raise DrivewmError(
                "privacy.faces needs privacy.face_model (a YuNet ONNX file; OpenCV 5 bundles no face detector) or "
                "privacy.faces: false"
            )
        self.cfg = cfg
        self.faces = YuNetFaces(cfg.face_model, cfg.face_score) if cfg.faces else None
        self.blurred = {"faces": 0, "plates": 0}

    def __call__(self, image_rgb: np.ndarray) -> np.ndarray:
        faces = self.faces(image_rgb) if self.faces is not None else []
        plates = plate_candidates(image_rgb) if self.cfg.plates else []
        self.blurred["faces"] += len(faces)
        self.blurred["plates"] += len(plates)
        return blur_boxes(image_rgb, faces + plates, self.cfg.blur_kernel_frac)
