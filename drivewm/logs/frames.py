"""A small TF tree: transforms between named frames, static or time-stamped, as read from a log.

Edges are stored as written (``T_parent_from_child`` per stamp) and walked in either direction,
so a ROS chain such as base_link -> camera_link -> camera_optical_frame resolves to one
``T_ego_from_cam``.
"""

from __future__ import annotations

import bisect
import collections

import numpy as np

from drivewm.geometry import invert_T


class FrameGraph:
    """Transforms between frames: ``add`` edges, then ask for static or per-tick transforms."""

    def __init__(self) -> None:
        self._edges: dict[tuple[str, str], list[tuple[int, np.ndarray]]] = {}

    def add(self, parent: str, child: str, timestamp_ns: int, T_parent_from_child: np.ndarray) -> None:
        samples = self._edges.setdefault((parent, child), [])
        samples.append((int(timestamp_ns), T_parent_from_child))
        if len(samples) > 1 and samples[-2][0] > samples[-1][0]:
            samples.sort(key=lambda s: s[0])  # rare: messages out of stamp order

    def frames(self) -> list[str]:
        """Every frame named by an edge, sorted."""
        return sorted({f for edge in self._edges for f in edge})

    def path(self, a: str, b: str) -> list[tuple[str, str, bool]] | None:
        """Edges from frame a to frame b as (parent, child, forward); None if not connected."""
        links = collections.defaultdict(list)
        for parent, child in self._edges:
            links[parent].append((child, (parent, child, True)))
            links[child].append((parent, (parent, child, False)))
        previous: dict[str, tuple[str, tuple[str, str, bool]] | None] = {a: None}
        queue = collections.deque([a])
        while queue:
            frame = queue.popleft()
            if frame == b:
                return self._unwind(previous, b)
            for nxt, edge in links[frame]:
                if nxt not in previous:
                    previous[nxt] = (frame, edge)
                    queue.append(nxt)
        return None

    @staticmethod
    def _unwind(previous: dict, b: str) -> list[tuple[str, str, bool]]:
        edges, frame = [], b
        while previous[frame] is not None:
            frame, edge = previous[frame]
            edges.append(edge)
        return edges[::-1]

    def _value(self, edge: tuple[str, str, bool], timestamp_ns: int | None) -> np.ndarray:
        """T along the walk direction: the latest sample at or before the time (or the first)."""
        parent, child, forward = edge
        samples = self._edges[(parent, child)]
        i = 0 if timestamp_ns is None else max(bisect.bisect_right(samples, timestamp_ns, key=lambda s: s[0]) - 1, 0)
        T = samples[i][1]
        return T if forward else invert_T(T)

    def static_transform(self, a: str, b: str) -> np.ndarray | None:
        """T_a_from_b from the first sample of every edge on the path (identity if a == b)."""
        edges = self.path(a, b)
        if edges is None:
            return None
        T = np.eye(4)
        for edge in edges:
            T = T @ self._value(edge, None)
        return T

    def series(self, a: str, b: str) -> list[tuple[int, np.ndarray]]:
        """T_a_from_b per stamp of the busiest edge on the path (others sample-and-hold)."""
        edges = self.path(a, b)
        if not edges:
            return []
        busiest = max(edges, key=lambda e: len(self._edges[e[:2]]))
        out = []
        for ts, _ in self._edges[busiest[:2]]:
            T = np.eye(4)
            for edge in edges:
                T = T @ self._value(edge, ts)
            out.append((ts, T))
        return out
