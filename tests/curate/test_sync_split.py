import numpy as np
from batch_split import clip_windows, split_segment

from drivewm.curate.split import valid_runs
from drivewm.curate.sync import synchronize

MS = 1_000_000


def test_sync_handles_drops_duplicates_late_start_and_skew():
    t = np.arange(50) * 100 * MS
    cams = {
        "A": t,
        "B": np.delete(t + 7 * MS, [10, 11]),  # drops two frames, 7 ms late
        "C": np.sort(np.concatenate([t[5:], t[[20, 21]]])) - 12 * MS,  # starts late, duplicates two stamps
    }
    table = synchronize(cams, ["A", "B", "C"], period_ns=100 * MS, tolerance_ns=25 * MS)
    assert table.tick_ns[0] == 5 * 100 * MS  # grid starts once every camera runs
    assert table.stats["C"]["duplicate_timestamps"] == 2
    assert table.stats["C"]["late_start_ns"] == 500 * MS - 12 * MS
    assert not table.valid[[5, 6]].any() and table.valid[7:].all() and table.valid[:5].all()
    assert table.worst_skew_ns == 12 * MS
    # every chosen frame is within tolerance, and no frame is used twice
    for v in range(3):
        idx = table.frame_index[table.valid, v]
        assert len(set(idx)) == len(idx)


def test_sync_resamples_20fps_to_10fps_and_rejects_far_frames():
    t20 = np.arange(40) * 50 * MS
    table = synchronize({"A": t20, "B": t20 + 3 * MS}, ["A", "B"], period_ns=100 * MS, tolerance_ns=25 * MS)
    assert len(table.tick_ns) == 20 and table.valid.all()
    assert (np.diff(table.frame_index[:, 0]) == 2).all()
    far = synchronize({"A": t20, "B": t20 + 25 * MS}, ["A", "B"], 100 * MS, 20 * MS, per_camera_offsets=False)
    assert not far.valid.any()  # B's frames fall halfway (25 ms) between A's: never within 20 ms of a tick


def test_sync_applies_the_tolerance_around_each_cameras_exposure_offset():
    """A staggered rig (B 40 ms and C 80 ms after A, beyond the 25 ms tolerance) with 3 ms jitter and
    a drop: every camera is matched at its own offset and keeps its own timestamps."""
    rng = np.random.default_rng(0)
    t = np.arange(60) * 100 * MS
    cams = {
        "A": t,
        "B": t + 40 * MS + rng.integers(-3 * MS, 3 * MS, 60),
        "C": np.delete(t + 80 * MS, [30]),
    }
    table = synchronize(cams, ["A", "B", "C"], 100 * MS, 25 * MS)
    assert table.offsets_ns["A"] == 0 and abs(table.offsets_ns["B"] - 40 * MS) <= 1 * MS
    # 80 ms after a tick is 20 ms before the next: C's frame nearest in time to each tick is the earlier sweep's
    assert table.offsets_ns["C"] == -20 * MS and table.stats["C"]["exposure_offset_ns"] == -20 * MS
    assert table.tick_ns[0] == 100 * MS and len(table.tick_ns) == 59  # C's first frame belongs to tick 1
    assert np.flatnonzero(~table.valid).tolist() == [30]  # C's dropped frame at 3.08 s, tick 3.1 s
    ok = table.valid
    np.testing.assert_array_equal(table.frame_ns[ok, 0], table.tick_ns[ok])
    np.testing.assert_array_equal(table.frame_ns[ok, 1], cams["B"][1:][ok])
    np.testing.assert_array_equal(table.frame_ns[ok, 2], table.tick_ns[ok] - 20 * MS)
    true_skew = np.abs(cams["B"][1:] - table.tick_ns)[ok].max()  # the true one, offsets included
    assert table.worst_skew_ns == true_skew and 37 * MS <= true_skew <= 43 * MS
    plain = synchronize(cams, ["A", "B", "C"], 100 * MS, 25 * MS, per_camera_offsets=False)
    assert not plain.valid.any()


def test_no_offset_for_a_camera_at_another_rate():
    t = np.arange(100) * 100 * MS
    table = synchronize({"A": t, "B": np.arange(120) * 83 * MS + 7 * MS}, ["A", "B"], 100 * MS, 25 * MS)
    assert table.offsets_ns["B"] == 0  # 12 Hz against 10 Hz: no steady phase, nearest frame per tick


def test_split_never_crosses_gaps_or_cuts():
    valid = np.ones(60, dtype=bool)
    valid[20] = False
    runs = valid_runs(valid)
    assert runs == [(0, 20), (21, 60)]
    segments = [s for a, b in runs for s in split_segment(a, b, [40])]
    assert segments == [(0, 20), (21, 40), (40, 60)]
    windows = clip_windows(segments, clip_frames=9, stride_frames=5)
    assert windows == [(0, 9), (5, 14), (10, 19), (21, 30), (26, 35), (31, 40), (40, 49), (45, 54), (50, 59)]
    for a, b in windows:
        assert valid[a:b].all() and not (a < 40 < b)
