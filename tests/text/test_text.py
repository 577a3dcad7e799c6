"""Text encoders: the built-in hashed encoder and a local tiny T5 loaded from a folder."""

from __future__ import annotations

import pytest
import torch

from drivewm.config import from_dict
from drivewm.errors import DrivewmError
from drivewm.text import TextConfig, build_text_encoder


def test_hashed_encoder_is_deterministic_masked_and_separates_conditions():
    enc = build_text_encoder(TextConfig(dim=64, max_length=8))
    emb, mask = enc.encode(["Snow, day, highway", "clear day highway", ""])
    assert emb.shape == (3, 8, 64) and mask.dtype == torch.bool
    assert mask.sum(1).tolist() == [3, 3, 0]
    again = build_text_encoder(TextConfig(dim=64, max_length=8)).encode(["snow day highway"])[
        0
    ]  # fresh encoder, case folded
    assert torch.equal(again[0], emb[0])
    # Different words give nearly orthogonal vectors; the shared words ("day", "highway") agree.
    snow, clear = emb[0, 0], emb[1, 0]
    assert abs(torch.cosine_similarity(snow, clear, dim=0)) < 0.4
    assert torch.cosine_similarity(emb[0, 1], emb[1, 1], dim=0) > 0.95
    assert torch.equal(emb[2], torch.zeros(8, 64))


def test_condition_words_embed_as_the_caption_word_the_models_were_trained_on():
    """The benchmark's "snowfall" / "foggy" / "nighttime" prompts reach a model trained on template captions
    ("snow", "fog", "night") as those words; the captions' own words keep the vectors they always had."""
    from drivewm.text.conditions import caption_conditions
    from drivewm.text.hashed import HashedWordEncoder

    enc = HashedWordEncoder(dim=64, max_length=8)
    for prompt, trained in [
        ("snowfall on a two-lane road", "snow on a two-lane road"),
        ("a snowy road through fields", "a snow road through fields"),
        ("foggy morning on a city street", "fog day on a city street"),
        ("nighttime highway with headlights", "night highway with headlights"),
    ]:
        assert caption_conditions(prompt) == caption_conditions(trained)  # what the eval checks the sample for
        assert torch.equal(enc.encode([prompt])[0], enc.encode([trained])[0]), prompt
    emb = enc.encode(["snow tram"])[0][0]
    for j, word in enumerate(["snow", "tram"]):
        assert torch.equal(emb[j], enc.word_vector(word) + enc.positions[j])  # the vectors models trained on
    assert abs(torch.cosine_similarity(enc.word_vector("snow"), enc.word_vector("fog"), dim=0)) < 0.4


def test_cache_returns_same_tensors_and_is_bounded():
    enc = build_text_encoder(TextConfig(dim=16, max_length=4, cache_size=2))
    a = enc.encode(["a b", "c"])[0]
    enc.encode(["d"])
    assert len(enc._cache) == 2 and torch.equal(enc.encode(["a b"])[0][0], a[0])


@pytest.fixture(scope="module")
def tiny_t5(tmp_path_factory):
    """A randomly initialised 2-layer T5 and a word-level tokenizer saved with save_pretrained."""
    from tokenizers import Tokenizer, models, pre_tokenizers
    from transformers import PreTrainedTokenizerFast, T5Config, T5EncoderModel

    words = ["<pad>", "</s>", "<unk>", "snow", "clear", "day", "night", "highway", "rain"]
    tok = Tokenizer(models.WordLevel({w: i for i, w in enumerate(words)}, unk_token="<unk>"))
    tok.pre_tokenizer = pre_tokenizers.Whitespace()
    fast = PreTrainedTokenizerFast(tokenizer_object=tok, pad_token="<pad>", eos_token="</s>", unk_token="<unk>")
    torch.manual_seed(0)
    model = T5EncoderModel(
        T5Config(vocab_size=len(words), d_model=32, d_kv=8, d_ff=64, num_layers=2, num_heads=4)
    ).eval()
    path = tmp_path_factory.mktemp("t5")
    model.save_pretrained(path)
    fast.save_pretrained(path)
    return path, model, fast


def test_t5_loads_from_local_folder_and_matches_the_model(tiny_t5):
    path, model, fast = tiny_t5
    enc = build_text_encoder(from_dict(TextConfig, {"kind": "t5", "path": str(path), "max_length": 6}))
    emb, mask = enc.encode(["snow day highway", "clear night"])
    assert enc.dim == 32 and emb.shape == (2, 6, 32)
    assert mask.sum(1).tolist() == [3, 2]
    ids = fast(["snow day highway"], return_tensors="pt")["input_ids"]
    with torch.no_grad():
        ref = model(input_ids=ids).last_hidden_state[0]
    assert torch.allclose(emb[0, :3], ref, atol=1e-5)
    assert torch.equal(emb[1, 2:], torch.zeros(4, 32))  # padding zeroed


def test_bad_text_configs_are_refused(tmp_path):
    with pytest.raises(DrivewmError, match="needs path"):
        build_text_encoder(TextConfig(kind="t5"))
    with pytest.raises(DrivewmError, match="not a local Hugging Face model folder"):
        build_text_encoder(TextConfig(kind="t5", path=str(tmp_path)))
    with pytest.raises(DrivewmError, match="kind"):
        from_dict(TextConfig, {"kind": "clip"})


def test_hf_encoder_folder_like_sentence_transformers_loads(tmp_path):
    """A sentence-transformers model folder holds a plain HF encoder at its root: kind 'hf' loads it."""
    from tokenizers import Tokenizer, models, pre_tokenizers
    from transformers import BertConfig, BertModel, PreTrainedTokenizerFast

    vocab = {w: i for i, w in enumerate(["[PAD]", "[UNK]", "snow", "fog", "night"])}
    tok = Tokenizer(models.WordLevel(vocab, unk_token="[UNK]"))
    tok.pre_tokenizer = pre_tokenizers.Whitespace()
    PreTrainedTokenizerFast(tokenizer_object=tok, pad_token="[PAD]", unk_token="[UNK]").save_pretrained(tmp_path)
    BertModel(
        BertConfig(vocab_size=5, hidden_size=24, num_hidden_layers=1, num_attention_heads=2, intermediate_size=32)
    ).save_pretrained(tmp_path)
    (tmp_path / "modules.json").write_text("[]")  # what marks a sentence-transformers folder; ignored here
    enc = build_text_encoder(TextConfig(kind="hf", path=str(tmp_path), max_length=4))
    emb, mask = enc.encode(["snow fog", "night"])
    assert enc.dim == 24 and emb.shape == (2, 4, 24) and mask.sum(1).tolist() == [2, 1]
    assert not torch.allclose(emb[0, 0], emb[1, 0])
