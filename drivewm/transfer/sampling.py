"""The cost of a transfer in network evaluations, the unit the benchmark compares methods at.

Transfer and its SDEdit baseline both sample with drivewm.diffusion.sampling.sample (from pure noise,
or from the source noised to ``start_sigma``: Meng et al. 2022, arXiv 2108.01073, sec. 3); the
Karras schedule then runs from the start down to 0, so N steps cost the same from any start.
"""

from __future__ import annotations


def network_evaluations(steps: int, guidance: float, sampler: str) -> int:
    """Denoiser calls of one sample: Euler N, Heun 2N - 1 (no correction on the last step), x2 with CFG."""
    calls = steps if sampler == "euler" else 2 * steps - 1
    return calls * (1 if guidance == 1.0 else 2)
