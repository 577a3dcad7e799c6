"""What every model family's generator is: a small protocol the generation stage calls.

A family plugs in with one class (registered by model type in drivewm.generate.registry) that loads
its model folder, turns a :class:`GenerateRequest` into samples, rolls a clip out, and writes what it
made. The conditioning inputs a family takes (prompts, a clip to continue, a rig and trajectory, a
layout) are built inside its generator, never inside the network's module.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar, Protocol

if TYPE_CHECKING:
    from drivewm.clips.format import Clip
    from drivewm.generate.config import GenerateConfig
    from drivewm.generate.writer import GeneratedSample


@dataclasses.dataclass
class GenerateRequest:
    """The inputs of one ``drivewm generate`` run (the settings are the :class:`GenerateConfig`)."""

    prompts: list[str]
    """Captions; each is sampled ``num_samples`` times."""
    condition_clip: Path | None = None
    """A clip whose first frames condition every sample (Video2World); None: everything generated."""
    layout: Path | None = None
    """A clip folder whose clips' layouts (boxes and road lines) are regenerated, each along its own ego
    path, in the prompts' conditions (drivewm.layout.sources); None: no layout."""
    scenario: str | None = None
    """A scenario name or simulate recipe YAML whose traffic is simulated without pixels and generated
    from its layout; None: none."""

    def given(self) -> list[str]:
        """Names of the optional inputs set (the fields after ``prompts`` that are not None)."""
        return [f.name for f in dataclasses.fields(self)[1:] if getattr(self, f.name) is not None]


class Generator(Protocol):
    """One model family's generation: ``from_pretrained``, then ``generate``, ``rollout`` and ``write``."""

    model_type: ClassVar[str]
    """The ``model_type`` of the model folders it loads (its key in drivewm.generate.registry.GENERATORS)."""
    inputs: ClassVar[tuple[str, ...]]
    """Optional :class:`GenerateRequest` fields it takes (the command refuses the others)."""

    @classmethod
    def from_pretrained(cls, folder: Path, device: str) -> Generator:
        """The generator of model folder ``folder`` on ``device`` (``auto``, ``cpu`` or ``cuda``)."""
        ...

    def generate(self, request: GenerateRequest, cfg: GenerateConfig) -> list[GeneratedSample]:
        """``cfg.num_samples`` samples per prompt of ``request``, drawn as ``cfg`` says."""
        ...

    def rollout(self, clip: Clip, cfg: GenerateConfig, prompt: str = "") -> GeneratedSample:
        """``clip`` continued for ``cfg.rollout.windows`` windows (DrivewmError where the family cannot)."""
        ...

    def write(self, samples: list[GeneratedSample], out_dir: Path, name: str = "generated") -> list[Path]:
        """Clip shards + manifest, videos and contact sheet of ``samples`` in ``out_dir``; the files written."""
        ...
