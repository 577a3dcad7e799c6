"""The valid runs of synchronized ticks: clips never cross a time gap.

Inside a run, shot boundaries cut segments and clips are windows of ``clip_frames`` consecutive
ticks inside one segment (drivewm.curate.windows, which finds them while the log streams).
"""

from __future__ import annotations

import numpy as np


def valid_runs(valid: np.ndarray) -> list[tuple[int, int]]:
    """[start, end) index ranges of consecutive True values."""
    padded = np.concatenate([[False], np.asarray(valid, dtype=bool), [False]])
    edges = np.flatnonzero(np.diff(padded.astype(np.int8)))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2])]
