"""Simulated multi-camera drive logs: traffic from highway-env or SUMO, a calibrated camera rig
rendered from the scene state, written as MCAP drive logs (docs/DESIGN.md section 4).

- :mod:`drivewm.sim.scene`: the scene-state stream (road map, ego pose, agent boxes);
- :mod:`drivewm.sim.source_highway`, :mod:`drivewm.sim.source_sumo`: the two sources;
- :mod:`drivewm.sim.render`: the renderer (ground texture + textured boxes, z-buffer, conditions);
- :mod:`drivewm.sim.simulate`: ``simulate`` / ``simulate_many``; :mod:`drivewm.sim.recipe`: dataset recipes.

The public names are imported on first use (:mod:`drivewm.lazy`), so ``drivewm --help`` stays fast.
"""

from drivewm.lazy import lazy_exports

_EXPORTS = {
    "SimConfig": "drivewm.sim.config",
    "simulate": "drivewm.sim.simulate",
    "simulate_many": "drivewm.sim.simulate",
}
__all__ = sorted(_EXPORTS)
__getattr__ = lazy_exports(__name__, _EXPORTS)
