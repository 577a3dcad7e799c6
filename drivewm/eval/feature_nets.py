"""The field's feature networks for FID and FVD, loaded from local TorchScript files (nothing downloads).

- Inception (FID): the TF-2015 Inception-v3 that pytorch-fid ports, as the TorchScript file
  ``inception-2015-12-05.pt`` that NVlabs' stylegan2-ada-pytorch / stylegan3 metrics load. Called
  ``net(x, return_features=True)`` with x (N, 3, 299, 299) float32 RGB in [0, 255]; returns the
  2048-d pool features (N, 2048).
- I3D (FVD): the Kinetics-400 I3D of Carreira & Zisserman 2017 as the TorchScript file
  ``i3d_torchscript.pt`` that StyleGAN-V and universome/fvd-comparison load. Called
  ``net(x, rescale=False, resize=False, return_features=True)`` with x (N, 3, T, 224, 224) float32
  RGB in [-1, 1]; returns the 400-d logits before the softmax (N, 400).

Frames are resized with OpenCV's area (down) / bilinear (up) filter; I3D clips are resized on the
short side to 224 and centre-cropped, as fvd-comparison's ``preprocess_single``.
A file that is not TorchScript, or a network that does not take these calls, is one DrivewmError line.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from drivewm.errors import DrivewmError

INCEPTION_SIZE_PX = 299
"""Input side of the FID Inception network."""
I3D_SIZE_PX = 224
"""Input side of the FVD I3D network."""


def load_torchscript(path: str | Path, what: str):
    """A TorchScript module from a local file, in eval mode on the CPU."""
    import torch

    path = Path(path)
    if not path.is_file():
        raise DrivewmError(f"{path}: no such {what} file")
    try:
        return torch.jit.load(str(path), map_location="cpu").eval()
    except (RuntimeError, ValueError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else exc.__class__.__name__
        raise DrivewmError(f"{path}: not a TorchScript {what} file (torch.jit.load: {first[:120]})") from None


def _resize(frame: np.ndarray, width: int, height: int) -> np.ndarray:
    down = width <= frame.shape[1] and height <= frame.shape[0]
    return cv2.resize(frame, (width, height), interpolation=cv2.INTER_AREA if down else cv2.INTER_LINEAR)


def _features(net, x, what: str, path: str, **kwargs) -> np.ndarray:
    import torch

    with torch.no_grad():
        try:
            out = net(torch.from_numpy(x), **kwargs)
        except RuntimeError as exc:
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else exc.__class__.__name__
            raise DrivewmError(f"{path}: the {what} network does not take {x.shape} input ({first[:120]})") from None
    if not isinstance(out, torch.Tensor) or out.ndim != 2 or out.shape[0] != x.shape[0]:
        raise DrivewmError(f"{path}: the {what} network must return features (N, D)")
    return out.double().numpy()


class InceptionFeatures:
    """FID features of frames: uint8 (N, H, W, 3) -> (N, D)."""

    def __init__(self, path: str | Path, batch: int = 32):
        self.path, self.batch = str(path), batch
        self.net = load_torchscript(path, "Inception")

    def __call__(self, frames: np.ndarray) -> np.ndarray:
        out = []
        for i in range(0, len(frames), self.batch):
            x = np.stack([_resize(f, INCEPTION_SIZE_PX, INCEPTION_SIZE_PX) for f in frames[i : i + self.batch]])
            x = np.ascontiguousarray(x.transpose(0, 3, 1, 2), dtype=np.float32)  # (N, 3, 299, 299) in [0, 255]
            out.append(_features(self.net, x, "Inception", self.path, return_features=True))
        return np.concatenate(out)


def i3d_clip(video: np.ndarray) -> np.ndarray:
    """Uint8 (T, H, W, 3) -> float32 (3, T, 224, 224) in [-1, 1]: short side to 224, centre crop."""
    T, H, W, _ = video.shape
    s = I3D_SIZE_PX / min(H, W)
    w, h = max(I3D_SIZE_PX, round(W * s)), max(I3D_SIZE_PX, round(H * s))
    x0, y0 = (w - I3D_SIZE_PX) // 2, (h - I3D_SIZE_PX) // 2
    frames = np.stack([_resize(f, w, h)[y0 : y0 + I3D_SIZE_PX, x0 : x0 + I3D_SIZE_PX] for f in video])
    return (frames.transpose(3, 0, 1, 2).astype(np.float32) / 127.5 - 1.0).copy()


class I3DFeatures:
    """FVD features of clips: a list of uint8 (T, H, W, 3) videos (equal T) -> (N, D)."""

    def __init__(self, path: str | Path, batch: int = 4):
        self.path, self.batch = str(path), batch
        self.net = load_torchscript(path, "I3D")

    def __call__(self, videos: list[np.ndarray]) -> np.ndarray:
        out = []
        for i in range(0, len(videos), self.batch):
            x = np.stack([i3d_clip(v) for v in videos[i : i + self.batch]])  # (B, 3, T, 224, 224)
            out.append(_features(self.net, x, "I3D", self.path, rescale=False, resize=False, return_features=True))
        return np.concatenate(out)
