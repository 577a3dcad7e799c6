"""Simulated multi-camera drive logs: traffic from highway-env or SUMO, a calibrated camera rig
rendered from the scene state, written as MCAP drive logs (docs/DESIGN.md section 4).

- :mod:`drivewm.sim.scene`: the scene-state stream (road map, ego pose, agent boxes);
- :mod:`drivewm.sim.source_highway`, :mod:`drivewm.sim.source_sumo`: the two sources;
- :mod:`drivewm.sim.render`: the renderer (ground texture + textured boxes, z-buffer, conditions);
- :mod:`drivewm.sim.simulate`: ``simulate`` / ``simulate_many``; :mod:`drivewm.sim.recipe`: dataset recipes.

The names are imported here, not lazily (:mod:`drivewm.lazy`): the function ``simulate`` shares its
name with the module ``drivewm.sim.simulate``, which would replace a lazily bound name on import.
"""

from drivewm.sim.config import SimConfig
from drivewm.sim.simulate import simulate, simulate_many

__all__ = ["SimConfig", "simulate", "simulate_many"]
