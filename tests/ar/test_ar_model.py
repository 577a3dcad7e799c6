"""The AR transformer: causal, incremental (KV cache) equal to a full pass, orders, padded captions."""

from __future__ import annotations

import torch
from ar_synthetic import tiny_condition, tiny_model

from drivewm.ar.config import ARConfig
from drivewm.ar.order import from_sequence, sequence_grid, to_sequence


def test_cached_steps_give_the_full_pass_logits():
    model, cond = tiny_model(), tiny_condition()
    inputs = model.inputs_of(torch.randint(0, 40, (2, 18), generator=torch.Generator().manual_seed(1)))
    full = model(inputs, cond)
    cache = model.new_cache(2, cond.text.shape[1], model.token_embed.weight)
    parts = [model(inputs[:, :7], cond, cache)] + [model(inputs[:, i : i + 1], cond, cache) for i in range(7, 18)]
    assert cache.video_length == 18
    torch.testing.assert_close(torch.cat(parts, dim=1), full, atol=1e-5, rtol=1e-5)


def test_a_position_sees_no_later_token():
    model, cond = tiny_model(), tiny_condition()
    tokens = torch.randint(0, 40, (2, 18), generator=torch.Generator().manual_seed(2))
    changed = tokens.clone()
    changed[:, 10] = (changed[:, 10] + 1) % 40
    a, b = model(model.inputs_of(tokens), cond), model(model.inputs_of(changed), cond)
    torch.testing.assert_close(a[:, :11], b[:, :11])  # the input at 11 is token 10
    assert (a[:, 11] - b[:, 11]).abs().max() > 1e-4


def test_padded_caption_tokens_are_not_read():
    model, cond = tiny_model(), tiny_condition()
    inputs = model.inputs_of(torch.randint(0, 40, (2, 18), generator=torch.Generator().manual_seed(3)))
    before = model(inputs, cond)
    cond.text[1, 2:] += 5.0  # the second caption's padding
    after = model(inputs, cond)
    torch.testing.assert_close(after[1], before[1])
    cond.text[1, 0] += 5.0
    assert (model(inputs, cond)[1] - before[1]).abs().max() > 1e-4


def test_block_order_visits_blocks_and_round_trips():
    cfg = ARConfig(grid_hw=[4, 4], order="block", block_size=2, max_frames=2)
    grid = torch.arange(2 * 16).view(2, 4, 4)
    seq = to_sequence(grid, cfg)
    assert seq[:4].tolist() == [0, 1, 4, 5] and seq[16:20].tolist() == [16, 17, 20, 21]
    assert torch.equal(from_sequence(seq, cfg), grid)
    positions = sequence_grid(cfg, 2)
    assert positions[2].tolist() == [0, 1, 0] and positions[16].tolist() == [1, 0, 0]
