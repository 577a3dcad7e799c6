"""``--device`` reaches every command that runs a diffusion network: with ``--device cpu`` every
tensor an operator reads or makes and every parameter/buffer of every module called is on the CPU;
``--device cuda`` on a machine without CUDA is a one-line error, never a silent CPU run."""

from __future__ import annotations

import collections
from pathlib import Path

import pytest
import torch
from synthetic_latents import make_synthetic_latent_cache
from torch.utils._python_dispatch import TorchDispatchMode
from torch.utils._pytree import tree_leaves

from drivewm.cli import main

TINY_T2W = [
    "--set",
    "model.hidden_dim=32",
    "--set",
    "model.depth=1",
    "--set",
    "model.num_heads=2",
    "--set",
    "text.dim=16",
    "--set",
    "train.steps=2",
    "--set",
    "train.batch_size=2",
    "--set",
    "sample_steps=1",
]


class DeviceRecorder(TorchDispatchMode):
    """Counts the device of every tensor each aten operator reads or returns, and (through a global
    module forward pre-hook) of every parameter and buffer of every module that is called."""

    def __init__(self):
        super().__init__()
        self.devices: collections.Counter[str] = collections.Counter()

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        out = func(*args, **(kwargs or {}))
        for t in tree_leaves((args, kwargs, out)):
            if isinstance(t, torch.Tensor):
                self.devices[t.device.type] += 1
        return out

    def _module_hook(self, module: torch.nn.Module, args) -> None:
        for t in [*module.parameters(recurse=False), *module.buffers(recurse=False), *tree_leaves(args)]:
            if isinstance(t, torch.Tensor):
                self.devices[f"{t.device.type} (module {type(module).__name__})"] += 1

    def __enter__(self):
        self._handle = torch.nn.modules.module.register_module_forward_pre_hook(self._module_hook)
        return super().__enter__()

    def __exit__(self, *exc):
        self._handle.remove()
        return super().__exit__(*exc)


def elsewhere(rec: DeviceRecorder, device: str) -> dict[str, int]:
    """The recorded devices other than ``device`` (with counts)."""
    return {d: n for d, n in rec.devices.items() if d.split(" ")[0] != device}


def test_the_recorder_sees_tensors_and_modules_on_another_device():
    layer = torch.nn.Linear(2, 2, device="meta")
    with DeviceRecorder() as rec:
        torch.ones(3).add_(1)
        layer(torch.ones(1, 2, device="meta"))
    assert rec.devices["cpu"] >= 2 and elsewhere(rec, "cpu") == {
        "meta": rec.devices["meta"],
        "meta (module Linear)": 3,  # weight, bias and the input
    }


@pytest.fixture(scope="module")
def t2w_cache(tmp_path_factory) -> Path:
    return make_synthetic_latent_cache(tmp_path_factory.mktemp("dev") / "lat", clips_per_condition=2)


def _commands(tmp: Path, t2w_cache: Path, mv_parent_dir: Path, mv_latents: Path, mv_tok: Path, clip: Path, device):
    """Every network-running command of the diffusion stages, with ``--device device``."""
    dev = ["--device", device]
    return {
        "pretrain": ["pretrain", "--data", t2w_cache, "--out", tmp / "t2w", *dev, *TINY_T2W],
        "generate t2w": ["generate", "--model", tmp / "t2w", "--prompt", "snow", "--steps", "1", "--out", tmp / "g1"],
        "posttrain": [
            "posttrain",
            "--init",
            mv_parent_dir,
            "--data",
            mv_latents,
            "--rig",
            "front3",
            "--out",
            tmp / "mv",
            *dev,
            *["--set", "train.steps=2", "--set", "sample_steps=1"],
        ],
        "generate multiview": [
            *["generate", "--model", mv_tok, "--prompt", "night", "--condition-clip", clip],
            *["--steps", "1", "--trajectory-guidance", "2", "--out", tmp / "g2"],
        ],
        "rollout": [
            *["rollout", "--model", mv_tok, "--clip", clip, "--windows", "1", "--steps", "1"],
            *["--out", tmp / "roll"],
        ],
    }


def test_every_command_keeps_every_tensor_on_the_cpu(
    t2w_cache, mv_parent_dir, mv_latents, mv_with_tokenizer, sim_clip_dir, tmp_path
):
    commands = _commands(tmp_path, t2w_cache, mv_parent_dir, mv_latents, mv_with_tokenizer, sim_clip_dir, "cpu")
    for name, argv in commands.items():
        argv = [str(a) for a in argv] + ([] if "--device" in map(str, argv) else ["--device", "cpu"])
        with DeviceRecorder() as rec:
            assert main(argv) == 0, name
        assert rec.devices["cpu"] > 1000, f"{name}: the recorder saw too little work ({dict(rec.devices)})"
        assert not elsewhere(rec, "cpu"), f"{name}: tensors off the CPU: {elsewhere(rec, 'cpu')}"


@pytest.mark.skipif(torch.cuda.is_available(), reason="checks the error on machines without CUDA")
def test_cuda_without_cuda_is_a_one_line_error(
    t2w_cache, mv_parent_dir, mv_latents, mv_with_tokenizer, sim_clip_dir, tmp_path, capsys
):
    commands = _commands(tmp_path, t2w_cache, mv_parent_dir, mv_latents, mv_with_tokenizer, sim_clip_dir, "cuda")
    commands["generate t2w"][2] = mv_parent_dir  # a Text2World folder that exists
    for name, argv in commands.items():
        argv = [str(a) for a in argv] + ([] if "--device" in map(str, argv) else ["--device", "cuda"])
        code = main(argv)
        err = capsys.readouterr().err
        assert code == 2 and "CUDA is not available" in err and err.count("\n") == 1, (name, err)
