"""Topic and frame names of drivewm's own drive logs (docs/DESIGN.md section 4).

Written logs use these; the reader uses them as the defaults for Foxglove files, and a topic map
(``drivewm/topicmaps/``) overrides them for fleet logs.
"""

from __future__ import annotations

#: Frame of the per-tick ego pose's parent (``T_world_from_ego`` maps ego into it).
WORLD_FRAME = "world"
#: The vehicle frame (ISO 8855: x forward, y left, z up, origin under the rear axle).
EGO_FRAME = "ego"

TF_TOPIC = "/tf"  # foxglove.FrameTransforms world -> ego, one per tick
TF_STATIC_TOPIC = "/tf_static"  # foxglove.FrameTransforms ego -> CAMERA (T_ego_from_cam)
SCENE_TOPIC = "/scene"  # JSON {"tags": {...}, "description": "..."}
AGENTS_TOPIC = "/agents"  # foxglove.SceneUpdate, one cube entity per agent
ROAD_TOPIC = "/road"  # foxglove.SceneUpdate, one line entity per road polyline or surface outline (optional, static)
STATIC_TOPIC = "/static"  # foxglove.SceneUpdate, one cube entity per static object (optional, logged once)
SCENE_SCHEMA_NAME = "drivewm.Scene"
#: Name of the MCAP metadata record holding the rig name and camera order.
METADATA_NAME = "drivewm"
#: Name of the MCAP metadata record of a log with label maps: ``classes``, the label ids' names, comma-separated.
LABELS_METADATA_NAME = "drivewm.labels"


def image_topic(camera: str) -> str:
    """``/CAMERA/image``: foxglove.CompressedImage with frame_id = camera name."""
    return f"/{camera}/image"


def calibration_topic(camera: str) -> str:
    """``/CAMERA/calibration``: foxglove.CameraCalibration with frame_id = camera name."""
    return f"/{camera}/calibration"


def labels_topic(camera: str) -> str:
    """``/CAMERA/labels``: foxglove.CompressedImage (grey PNG label map, drivewm.layout.labels) with
    frame_id = camera name and the timestamp of the camera's image it labels."""
    return f"/{camera}/labels"


def labels_camera(topic: str) -> str | None:
    """The camera of a ``/CAMERA/labels`` topic, else None."""
    parts = topic.split("/")
    return parts[1] if len(parts) == 3 and parts[0] == "" and parts[2] == "labels" and parts[1] else None
