"""Near-duplicate clips across the dataset, by cosine similarity of a tiny clip embedding.

The embedding: for every camera, the first, middle and last frame as 16x9 grey thumbnails
(INTER_AREA, from the filters' 160 px wide grey thumbnails), each centred to zero mean (so a
global brightness change does not hide a duplicate), concatenated over cameras and frames and
L2-normalised: 432 numbers per camera. Two clips of the
same place at the same moment (a log curated twice, overlapping clips, a re-recorded drive)
come out above 0.98; different moments of a drive differ in layout and fall well below.
"""

from __future__ import annotations

import cv2
import numpy as np

THUMB_WH = (16, 9)


def key_frames(T: int) -> list[int]:
    """The frames of a T-frame clip that the embedding looks at: first, middle, last."""
    return [0, T // 2, T - 1]


def grey_embedding(grey: np.ndarray) -> np.ndarray:
    """(V, 3, h, 160) uint8 grey analysis thumbnails of each camera's :func:`key_frames`
    (drivewm.curate.images.analysis_grey, made once per frame while streaming) -> (V * 3 * 144,)
    float32 unit vector."""
    thumbs = [
        cv2.resize(g, THUMB_WH, interpolation=cv2.INTER_AREA).astype(np.float32)
        for g in grey.reshape(-1, *grey.shape[2:])
    ]
    vec = np.concatenate([(t - t.mean()).ravel() for t in thumbs])
    return (vec / max(float(np.linalg.norm(vec)), 1e-6)).astype(np.float32)


def near_duplicates(
    embeddings: np.ndarray, threshold: float, kept: np.ndarray | None = None
) -> list[tuple[int, int, float]]:
    """Greedy dedup in order: returns (index, index of the earlier kept clip it duplicates, cosine).

    ``embeddings`` (N, D) unit rows in a deterministic order; ``kept`` (M, D) rows already kept
    elsewhere (reported with index -1 - m). Clips of different sizes/camera counts never match.
    """
    pool: list[np.ndarray] = [] if kept is None else list(kept)
    origin: list[int] = [] if kept is None else [-1 - m for m in range(len(kept))]
    dups = []
    for i, e in enumerate(embeddings):
        same = [j for j, p in enumerate(pool) if p.shape == e.shape]
        sims = np.array([float(pool[j] @ e) for j in same])
        if len(sims) and sims.max() >= threshold:
            j = same[int(sims.argmax())]
            dups.append((i, origin[j], float(sims.max())))
            continue
        pool.append(e)
        origin.append(i)
    return dups
