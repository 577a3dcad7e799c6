"""Simulated multi-camera drive logs: traffic from highway-env or SUMO, a calibrated camera rig
rendered from the scene state, written as MCAP drive logs (docs/DESIGN.md section 4).

- :mod:`drivewm.sim.scene`: the scene-state stream (road map, ego pose, agent boxes);
- :mod:`drivewm.sim.source_highway`, :mod:`drivewm.sim.source_sumo`: the two sources;
- :mod:`drivewm.sim.render`: the renderer (ground texture + textured boxes, z-buffer, conditions);
- :mod:`drivewm.sim.drives`: ``simulate`` / ``simulate_many``; :mod:`drivewm.sim.recipe`: dataset recipes.

The names are imported on first use (:mod:`drivewm.lazy`), so ``drivewm --help`` pays for no
simulator or OpenCV.
"""

from drivewm.lazy import lazy_exports

_EXPORTS = {
    "SimConfig": "drivewm.sim.config",
    "simulate": "drivewm.sim.drives",
    "simulate_many": "drivewm.sim.drives",
}

__all__ = ["SimConfig", "simulate", "simulate_many"]
__getattr__ = lazy_exports(__name__, _EXPORTS)
