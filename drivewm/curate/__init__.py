"""Curation: drive logs -> synchronized, filtered, captioned multi-view clip shards.

``curate(log_paths, out_dir, cfg, executor="local"|"ray", workers=1, ray_address=None)`` runs
the per-log stage (:mod:`drivewm.curate.stage`) on an executor and writes shards, manifest.jsonl,
report.json and contact_sheet.png (see ``drivewm/recipes/curate/README.md``).

The public names are imported on first use (:mod:`drivewm.lazy`): ``drivewm --help`` imports this
package for its commands and must not pay for filterpy, scipy and OpenCV.
"""

from drivewm.lazy import lazy_exports

_EXPORTS = {
    "CurateConfig": "drivewm.curate.config",
    "load_curate_config": "drivewm.curate.config",
    "balanced_sample": "drivewm.curate.manifest",
    "curate": "drivewm.curate.pipeline",
}

__all__ = ["CurateConfig", "balanced_sample", "curate", "load_curate_config"]
__getattr__ = lazy_exports(__name__, _EXPORTS)
