"""The geometric-consistency benchmark (docs/DESIGN.md stage 4): TSE, CSE, pose success, trajectory errors, adherence.

``evaluate(location, rig=None, out_dir=...)`` scores clip shards, per-camera mp4 folders or a grid video;
the pieces (matching, epipolar, consistency, sfm, trajectory, adherence) are usable alone.
``evaluate`` is imported on first use (:mod:`drivewm.lazy`: it pulls in pycolmap and matplotlib).
"""

from drivewm.lazy import lazy_exports

_EXPORTS = {"evaluate": "drivewm.eval.suite"}
__all__ = ["evaluate"]
__getattr__ = lazy_exports(__name__, _EXPORTS)
