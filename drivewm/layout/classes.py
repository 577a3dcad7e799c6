"""The names a layout may use (box classes, road line kinds and paints) and the classes of label maps
(docs/DESIGN.md section 4).

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


#: Semantic classes of a per-pixel label map (id = index): what the simulator's renderer draws at each
#: pixel (drivewm.sim.render, ``--labels``) and what the layout renderer draws (drivewm.layout.render).
LABEL_CLASSES = (
    "sky",
    "road",
    "lane_paint",
    "sidewalk",
    "kerb",
    "terrain",
    "vehicle",
    "pedestrian",
    "building",
    "vegetation",
    "pole",
    "barrier",
    "sign",
)
LABEL_ID = {name: i for i, name in enumerate(LABEL_CLASSES)}
#: The label of a box whose category has none (not a layout class, e.g. a test marker).
UNLABELLED = 255
#: The label of each box class.
BOX_LABEL = {
    **dict.fromkeys(("car", "van", "truck", "bus", "motorcycle", "bicycle"), "vehicle"),
    "pedestrian": "pedestrian",
    "building": "building",
    "pole": "pole",
    "lamp": "pole",
    **dict.fromkeys(("trunk", "crown", "vegetation"), "vegetation"),
    "barrier": "barrier",
    "sign": "sign",
}


def label_id(box_class: str) -> int:
    """The label id (index into :data:`LABEL_CLASSES`) a box of ``box_class`` is drawn with;
    :data:`UNLABELLED` for a category that is not a layout class."""
    return LABEL_ID[BOX_LABEL[box_class]] if box_class in BOX_LABEL else UNLABELLED


def check_word(value: str, allowed: tuple[str, ...], field: str, where: str) -> str:
    """``value`` if it is one of ``allowed``, else a one-line DrivewmError naming ``where`` and ``field``."""
    if value not in allowed:
        raise DrivewmError(f"{where}: layout {field} {value!r} is not one of {list(allowed)}")
    return value
