"""Clip shards (docs/DESIGN.md section 4): WebDataset tars of per-camera H.264 mp4, clip JSON, ego poses."""

from drivewm.clips.format import CLIP_FORMAT_VERSION, Clip, ClipMeta
from drivewm.clips.shards import ShardWriter, iter_clips, list_shards, read_manifest

__all__ = ["CLIP_FORMAT_VERSION", "Clip", "ClipMeta", "ShardWriter", "iter_clips", "list_shards", "read_manifest"]
