"""Drive logs: the in-memory :class:`DriveLog` and MCAP read/write (DESIGN.md section 4)."""

from drivewm.logs.types import AgentBox, DriveLog, ImageFrame, SceneInfo

__all__ = ["AgentBox", "DriveLog", "ImageFrame", "SceneInfo"]
