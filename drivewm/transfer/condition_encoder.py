"""The target condition as structured fields: weather and time of day -> a global embedding.

GAIA-2 (arXiv 2503.20523 sec. 3) conditions on weather and time of day as categorical inputs
beside the text; here each is a learned embedding (index 0 = not given: the unconditional branch
of classifier-free guidance), summed and passed through an MLP whose last layer starts at zero, and
the result is added to the DiT's timestep embedding (``extra_global_cond``), so a fresh model
ignores it.
"""

from __future__ import annotations

import torch
from torch import nn

from drivewm.logs.types import TIMES_OF_DAY, WEATHERS


def condition_indices(weather: str | None, time_of_day: str | None) -> tuple[int, int]:
    """(weather index, time-of-day index): 1 + position in WEATHERS / TIMES_OF_DAY, 0 = not given."""
    w = WEATHERS.index(weather) + 1 if weather in WEATHERS else 0
    t = TIMES_OF_DAY.index(time_of_day) + 1 if time_of_day in TIMES_OF_DAY else 0
    return w, t


class ConditionEncoder(nn.Module):
    """``forward(weather (B,) long, time_of_day (B,) long) -> (B, D)`` added to the timestep embedding."""

    def __init__(self, hidden_dim: int, width: int):
        super().__init__()
        self.weather = nn.Embedding(len(WEATHERS) + 1, width)  # row 0: no weather given
        self.time_of_day = nn.Embedding(len(TIMES_OF_DAY) + 1, width)  # row 0: no time given
        self.mlp = nn.Sequential(nn.SiLU(), nn.Linear(width, hidden_dim), nn.SiLU(), nn.Linear(hidden_dim, hidden_dim))
        nn.init.zeros_(self.mlp[-1].weight)
        nn.init.zeros_(self.mlp[-1].bias)

    def forward(self, weather: torch.Tensor, time_of_day: torch.Tensor) -> torch.Tensor:
        return self.mlp(self.weather(weather) + self.time_of_day(time_of_day))  # (B, D)
