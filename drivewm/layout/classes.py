"""The names a layout may use: box classes, road line kinds and paints (docs/DESIGN.md section 4).

A layout names each box's class and each line's kind and paint by these words; anything else is
refused (:meth:`drivewm.layout.clip_layout.ClipLayout.validate`), so a renderer or a model never
meets a class it has no colour or embedding for. A log whose categories differ maps them onto
these with a topic map's ``layout.classes`` (:mod:`drivewm.logs.topicmap`).
"""

from __future__ import annotations

from drivewm.errors import DrivewmError

#: Road users: the classes that move.
ROAD_USERS = ("car", "van", "truck", "bus", "motorcycle", "bicycle", "pedestrian")
#: Static objects. The simulator draws a tree as a ``trunk`` box under a ``crown`` box and a street
#: lamp as a ``pole`` with a ``lamp`` head (drivewm/sim/props.py); a log with whole trees says ``vegetation``.
STATIC_OBJECTS = ("building", "pole", "lamp", "trunk", "crown", "vegetation", "barrier", "sign")
BOX_CLASSES = ROAD_USERS + STATIC_OBJECTS

#: Road polylines: lane centre lines, painted (or unpainted) lane borders, kerbs, and the closed
#: outlines of the paved polygons whose union is the road surface.
LINE_KINDS = ("lane_center", "lane_boundary", "road_edge", "road_surface")
#: How a line is painted; "" where paint does not apply (centre lines, surfaces, edges of unknown paint).
PAINTS = ("", "solid", "dashed", "none")


def check_word(value: str, allowed: tuple[str, ...], field: str, where: str) -> str:
    """``value`` if it is one of ``allowed``, else a one-line DrivewmError naming ``where`` and ``field``."""
    if value not in allowed:
        raise DrivewmError(f"{where}: layout {field} {value!r} is not one of {list(allowed)}")
    return value
