"""Manifest helpers: filtering and balanced sampling over ``manifest.jsonl`` rows."""

from __future__ import annotations

import random
from collections import defaultdict


def tag_of(row: dict, by: str) -> str:
    """A row's value for ``by``: a scene tag (weather, time_of_day, ...) or a top-level field."""
    return str(row.get("tags", {}).get(by, row.get(by, "unknown")))


def balanced_sample(rows: list[dict], by: str = "weather", n: int = 0, seed: int = 0) -> list[dict]:
    """Up to ``n`` rows with the values of ``by`` as equally represented as the data allows.

    Round-robin over the groups (sorted by value), each group shuffled with ``seed``; a group that
    runs out leaves its share to the others. ``n`` <= 0 means as many as the smallest group allows
    for every group (groups x smallest size).
    """
    groups: dict[str, list[dict]] = defaultdict(list)
    for row in rows:
        groups[tag_of(row, by)].append(row)
    rng = random.Random(seed)
    queues = []
    for value in sorted(groups):
        members = list(groups[value])
        rng.shuffle(members)
        queues.append(members)
    if n <= 0:
        n = min(len(q) for q in queues) * len(queues) if queues else 0
    out: list[dict] = []
    while len(out) < n and any(queues):
        for q in queues:
            if q and len(out) < n:
                out.append(q.pop())
    return out
