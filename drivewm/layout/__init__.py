"""Scenario layouts: a clip's road, lanes and objects, in its first frame's ego frame (docs/DESIGN.md section 4).

- :mod:`drivewm.layout.classes`: the box classes, line kinds and paints a layout may name;
- :mod:`drivewm.layout.clip_layout`: :class:`ClipLayout`, its validation and the ``KEY.layout.npz`` member;
- :mod:`drivewm.layout.build`: a layout from world-frame objects and ego poses (a curated log's clip);
- :mod:`drivewm.layout.recording`: a layout from a simulated drive without pixels.

The names are imported on first use (:mod:`drivewm.lazy`).
"""

from drivewm.lazy import lazy_exports

_EXPORTS = {
    "ClipLayout": "drivewm.layout.clip_layout",
    "layout_from_npz": "drivewm.layout.clip_layout",
    "layout_to_npz": "drivewm.layout.clip_layout",
    "layout_from_world": "drivewm.layout.build",
    "layout_from_log": "drivewm.layout.build",
    "layout_from_recording": "drivewm.layout.recording",
}

__all__ = list(_EXPORTS)
__getattr__ = lazy_exports(__name__, _EXPORTS)
