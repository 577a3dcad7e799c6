"""Token caches: exact FSQ indices from the latent cache, and the inputs ``drivewm ar`` refuses."""

from __future__ import annotations

import pytest
import torch
from ar_synthetic import make_token_cache, make_tokenizer

from drivewm.ar.tokens import TokenDataset
from drivewm.cli import main


@pytest.fixture(scope="module")
def fsq_data(tmp_path_factory):
    root = tmp_path_factory.mktemp("ar_tokens")
    tok = make_tokenizer(root / "tok_fsq")
    cache, grids = make_token_cache(root / "clips", tok)
    return root, tok, cache, grids


def test_indices_from_the_cached_fsq_codes_are_exact(fsq_data):
    _, _, cache, grids = fsq_data
    data = TokenDataset(cache)
    assert len(data) == len(grids) and data.vocab_size == 1000 and data.grid_hw == (2, 3)
    for i, grid in enumerate(grids):
        sample = data[i]
        assert sample.tokens.dtype == torch.long and torch.equal(sample.tokens, grid)
        assert sample.ego.shape == (3, 3) and sample.rays.shape == (6, 6)
    held, kept = (
        TokenDataset(cache, split="holdout", holdout_percent=50),
        TokenDataset(cache, split="train", holdout_percent=50),
    )
    assert len(held) + len(kept) == len(grids) and len(held) > 0 and len(kept) > 0


def _run(argv, capsys) -> tuple[int, str]:
    with pytest.raises(SystemExit) as exc:
        raise SystemExit(main(argv))
    return exc.value.code, capsys.readouterr().err.strip()


def _train_argv(root, tok, out, *sets):
    argv = ["ar", "train", "--data", str(root / "clips"), "--tokenizer", str(tok), "--out", str(out)]
    for s in ("train.steps=1", "model.hidden_dim=16", "model.num_heads=2", "model.depth=1", *sets):
        argv += ["--set", s]
    return argv


def test_a_continuous_tokenizer_is_refused(fsq_data, tmp_path, capsys):
    root, _, _, _ = fsq_data
    cont = make_tokenizer(tmp_path / "tok_cont", fsq=False)
    code, err = _run(_train_argv(root, cont, tmp_path / "out"), capsys)
    assert code == 2 and err.count("\n") == 0 and "continuous tokenizer" in err
    assert not (tmp_path / "out").exists()


def test_a_cache_from_another_tokenizer_is_refused(fsq_data, tmp_path, capsys):
    root, _, cache, _ = fsq_data
    other = make_tokenizer(tmp_path / "tok_fsq", seed=1)  # the cache's name, other weights and statistics
    with torch.no_grad():
        from drivewm.tokenizer.model import Tokenizer

        tok = Tokenizer.from_pretrained(other)
        tok.latent_std.fill_(2.0)
        tok.save_pretrained(other)
    code, err = _run(_train_argv(root, other, tmp_path / "out", f"data.latents={cache.name}"), capsys)
    assert code == 2 and err.count("\n") == 0 and "another tokenizer" in err


def test_a_context_longer_than_the_models_is_refused(fsq_data, tmp_path, capsys):
    root, tok, _, _ = fsq_data
    code, err = _run(_train_argv(root, tok, tmp_path / "out", "model.max_frames=2"), capsys)
    assert code == 2 and err.count("\n") == 0 and "longer than the model's context of 2" in err
