"""The training task shared by the stages that post-train a network built around a DiT
(multi-view post-training, weather/time-of-day transfer): a ``bundle`` whose ``net`` is the
trained module and whose ``save_pretrained`` writes its model folder."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

from drivewm.train.loop import TrainTask


class BundleTask(TrainTask):
    """drivewm.train.loop.TrainTask around ``bundle.net`` (whose ``dit.blocks`` the loop wraps)
    trained on ``dataset``; subclasses give the loss, the sample grid and :meth:`new_bundle`."""

    def __init__(self, cfg: Any, dataset: Any, bundle: Any):
        self.cfg = cfg
        self.dataset = dataset
        self.bundle = bundle
        self.model = bundle.net.train()

    def blocks(self) -> list[torch.nn.Module]:
        return list(self.bundle.net.dit.blocks)

    def num_samples(self) -> int:
        return len(self.dataset)

    def new_bundle(self) -> Any:
        """A freshly built bundle of the same configuration (weights drawn, then replaced)."""
        raise NotImplementedError

    def ema_bundle(self, ema_state: dict[str, torch.Tensor]) -> Any:
        """A bundle holding the EMA weights, built without touching the run's RNG."""
        with torch.random.fork_rng():  # building the networks draws weights: keep the run's RNG untouched
            bundle = self.new_bundle()
        bundle.net.load_state_dict(ema_state)
        return bundle

    def save_model(self, ema_state: dict[str, torch.Tensor], out_dir: Path) -> None:
        self.ema_bundle(ema_state).save_pretrained(out_dir, ema_state)
