"""Which torch device a command runs on: ``--device auto|cpu|cuda`` resolved in one place."""

from __future__ import annotations

import torch

from drivewm.errors import DrivewmError


def resolve_device(device: str | torch.device) -> torch.device:
    """``auto`` (CUDA when available), ``cpu`` or ``cuda[:i]`` -> a torch device; CUDA asked for on a
    machine without it is a DrivewmError rather than a silent CPU run."""
    if str(device) == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        device = torch.device(device)
    except RuntimeError:
        raise DrivewmError(f"device {device!r}: expected auto, cpu or cuda") from None
    if device.type == "cuda" and not torch.cuda.is_available():
        raise DrivewmError(f"device {device}: CUDA is not available on this machine (use --device cpu or auto)")
    if device.type not in ("cpu", "cuda"):
        raise DrivewmError(f"device {device}: expected auto, cpu or cuda")
    return device
