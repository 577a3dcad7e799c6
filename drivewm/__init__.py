"""drivewm: multi-camera driving world models.

Stages (each a sub-package, each reading and writing the formats of docs/DESIGN.md section 4):
``sim`` -> ``logs`` (MCAP) -> ``curate`` -> ``clips`` -> ``tokenizer`` -> ``diffusion`` -> ``multiview`` -> ``eval``.
"""

__version__ = "0.1.0"
