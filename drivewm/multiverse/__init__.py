"""Multiverse: several futures from one moment of a drive, simulated, rendered in every camera, scored
and ranked (docs/DESIGN.md, section "Multiverse").

- :mod:`drivewm.multiverse.plans`: what the ego does in each future;
- :mod:`drivewm.multiverse.branch`: the futures' traffic, from :mod:`~drivewm.multiverse.simulated` (a forked
  simulator) or :mod:`~drivewm.multiverse.replay` (a replayed log);
- :mod:`drivewm.multiverse.cameras`: each future as a drive log with cameras (``--renderer``);
- :mod:`drivewm.multiverse.scores`, :mod:`drivewm.multiverse.ranking`: scores and the ranking rule;
- :mod:`drivewm.multiverse.report`, :mod:`drivewm.multiverse.recording`: report.html and the Rerun recording;
- :mod:`drivewm.multiverse.run`: ``run_multiverse``, the one place that joins them.
"""

from drivewm.lazy import lazy_exports

_EXPORTS = {"MultiverseConfig": "drivewm.multiverse.config", "run_multiverse": "drivewm.multiverse.run"}

__all__ = ["MultiverseConfig", "run_multiverse"]
__getattr__ = lazy_exports(__name__, _EXPORTS)
