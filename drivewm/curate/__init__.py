"""Curation (issue 3): drive logs -> synchronized, filtered, captioned multi-view clip shards.

``curate(log_paths, out_dir, cfg, executor="local"|"ray", workers=1, ray_address=None)`` runs
the per-log stage (:mod:`drivewm.curate.stage`) on an executor and writes shards, manifest.jsonl,
report.json and contact_sheet.png (see ``drivewm/recipes/curate/README.md``).
"""

_EXPORTS = {
    "CurateConfig": "drivewm.curate.config",
    "load_curate_config": "drivewm.curate.config",
    "balanced_sample": "drivewm.curate.manifest",
    "curate": "drivewm.curate.pipeline",
}

__all__ = ["CurateConfig", "balanced_sample", "curate", "load_curate_config"]


def __getattr__(name: str):
    """Import the public names on first use: ``drivewm --help`` imports this package for its
    commands and must not pay for filterpy, scipy and OpenCV (PEP 562)."""
    if name in _EXPORTS:
        import importlib

        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
