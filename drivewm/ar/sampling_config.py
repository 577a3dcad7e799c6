"""How an autoregressive model draws each token (no torch here: ``drivewm generate``'s config holds it)."""

from __future__ import annotations

import dataclasses

from drivewm.config import above, at_least, in_range


@dataclasses.dataclass
class TokenSampling:
    """How the next token is drawn from the logits (drivewm.ar.sampling)."""

    temperature: float = 1.0
    """Logits are divided by this (0 < t; lower is greedier)."""
    top_k: int = 0
    """Keep the k most likely tokens (0: all)."""
    top_p: float = 1.0
    """Keep the smallest set of most likely tokens whose probability reaches p (1: all; Holtzman et al. 2020)."""

    def validate(self) -> None:
        above(self, 0, "temperature")
        at_least(self, 0, "top_k")
        in_range(self, "top_p", 0, 1)
