"""Which held-out pairs the transfer benchmark scores."""

from __future__ import annotations

from drivewm.transfer.benchmark import spread_over_drives


def test_a_subset_of_pairs_spans_every_drive_even_where_a_clip_was_dropped() -> None:
    # three drives of five clips; curation dropped drive b's first clip (bad exposure at night)
    ids = [f"{d}-s{n}-h-t{t:06d}" for d, n in (("a", 1), ("b", 2), ("c", 3)) for t in range(0, 340, 68)]
    ids.remove("b-s2-h-t000000")
    order = spread_over_drives(ids[::-1])
    assert order[:3] == ["a-s1-h-t000000", "b-s2-h-t000068", "c-s3-h-t000000"]
    assert order[3:6] == ["a-s1-h-t000068", "b-s2-h-t000136", "c-s3-h-t000068"]
    assert sorted(order) == sorted(ids)  # nothing lost, nothing twice
    # evenly spaced over the sorted ids (the rule before) took drive a's last clip and skipped drive b
    before = [sorted(ids)[int(k * len(ids) / 3)] for k in range(3)]
    assert [i.split("-")[0] for i in before] == ["a", "a", "c"]
