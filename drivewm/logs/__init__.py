"""Drive logs: the in-memory :class:`DriveLog` and MCAP read/write (docs/DESIGN.md section 4).

- :mod:`drivewm.logs.writer`: ``LogWriter`` / ``write_log`` (Foxglove SDK, protobuf, atomic);
- :mod:`drivewm.logs.reader`: ``read_log`` (Foxglove protobuf or JSON, ROS 2 through a topic map);
- :mod:`drivewm.logs.topicmap`: topic maps (``drivewm/topicmaps/*.yaml``);
- :mod:`drivewm.logs.viewer`: a Rerun recording of a log (``drivewm view``).

Heavy modules (the Foxglove SDK, mcap decoders, rerun) load only when used, and the public names
below on first use (:mod:`drivewm.lazy`), so ``drivewm --help`` stays fast.
"""

from drivewm.lazy import lazy_exports

_EXPORTS = {name: "drivewm.logs.types" for name in ("AgentBox", "DriveLog", "ImageFrame", "RoadLine", "SceneInfo")}
__all__ = sorted(_EXPORTS)
__getattr__ = lazy_exports(__name__, _EXPORTS)
