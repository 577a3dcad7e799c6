"""Curation (issue 3): drive logs -> synchronized, filtered, captioned multi-view clip shards.

``curate(log_paths, out_dir, cfg, executor="local"|"ray", workers=1, ray_address=None)`` runs
the per-log stage (:mod:`drivewm.curate.stage`) on an executor and writes shards, manifest.jsonl,
report.json and contact_sheet.png (see ``datasets/curate/README.md``).
"""

from drivewm.curate.config import CurateConfig, load_curate_config
from drivewm.curate.manifest import balanced_sample
from drivewm.curate.pipeline import curate

__all__ = ["CurateConfig", "balanced_sample", "curate", "load_curate_config"]
