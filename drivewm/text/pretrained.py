"""Pretrained text encoders (T5 family, sentence-transformers / any HF encoder) from a LOCAL folder.

Nothing is downloaded: the folder must hold a Hugging Face model and its tokenizer (what
``save_pretrained`` writes). T5 runs its encoder stack only (as Cosmos does with T5-XXL); other
models use their last hidden state. Padding positions are zeroed and masked. ``transformers`` (the
optional ``peers`` extra) is imported when an encoder loads, so drivewm runs without it.
"""

from __future__ import annotations

import pickle
from pathlib import Path

import torch

from drivewm.errors import DrivewmError
from drivewm.text.encoder import TextEncoder


def check_encoder_folder(path: Path) -> None:
    """A local Hugging Face folder with config.json and safetensors weights; pickled weights
    (``pytorch_model.bin``, ``*.pt``) are refused before anything is loaded, since unpickling runs code."""
    if not (path / "config.json").is_file():
        raise DrivewmError(
            f"{path}: not a local Hugging Face model folder (no config.json); text encoders are never downloaded"
        )
    if not any(path.glob("*.safetensors")):
        pickled = sorted(p.name for p in path.iterdir() if p.suffix in (".bin", ".pt", ".pth", ".pkl", ".ckpt"))
        why = f" (only pickled {pickled}, never loaded: unpickling can run code)" if pickled else ""
        raise DrivewmError(f"{path}: no *.safetensors weights{why}")


class PretrainedTextEncoder(TextEncoder):
    """Token embeddings of a local Hugging Face encoder, (B, L, hidden) float32 + mask (B, L)."""

    def __init__(self, path: str | Path, kind: str = "t5", max_length: int = 32, cache_size: int = 4096):
        super().__init__(max_length, cache_size)
        self.path = Path(path)
        check_encoder_folder(self.path)
        from transformers import AutoModel, AutoTokenizer, T5EncoderModel

        try:
            self.tokenizer = AutoTokenizer.from_pretrained(self.path, local_files_only=True)
            loader = T5EncoderModel if kind == "t5" else AutoModel
            self.model = loader.from_pretrained(self.path, local_files_only=True, use_safetensors=True).eval()
        except (OSError, ValueError, KeyError, RuntimeError, TypeError, pickle.UnpicklingError) as exc:
            raise DrivewmError(
                f"{self.path}: cannot load {kind} text encoder ({exc.__class__.__name__}: {str(exc)[:200]})"
            ) from None
        for p in self.model.parameters():
            p.requires_grad_(False)

    @property
    def dim(self) -> int:
        cfg = self.model.config
        return int(getattr(cfg, "d_model", None) or cfg.hidden_size)

    @torch.no_grad()
    def encode_uncached(self, captions: list[str]) -> tuple[torch.Tensor, torch.Tensor]:
        batch = self.tokenizer(
            captions, padding="max_length", truncation=True, max_length=self.max_length, return_tensors="pt"
        )
        hidden = self.model(input_ids=batch["input_ids"], attention_mask=batch["attention_mask"]).last_hidden_state
        mask = batch["attention_mask"].bool()
        return (hidden.float() * mask[..., None]).cpu(), mask.cpu()
