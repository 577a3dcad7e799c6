"""The geometric-consistency benchmark (docs/DESIGN.md stage 4): TSE, CSE, pose success, trajectory errors, adherence.

``evaluate(location, rig=None, out_dir=...)`` scores clip shards, per-camera mp4 folders or a grid mp4;
the pieces (matching, epipolar, consistency, sfm, trajectory, adherence) are usable alone.
"""

from __future__ import annotations


def evaluate(*args, **kwargs):
    """See :func:`drivewm.eval.suite.evaluate` (imported lazily: it pulls in pycolmap and matplotlib)."""
    from drivewm.eval.suite import evaluate as _evaluate

    return _evaluate(*args, **kwargs)


__all__ = ["evaluate"]
