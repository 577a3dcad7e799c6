import numpy as np

from drivewm.curate.split import clip_windows, split_segment, valid_runs
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
    far = synchronize({"A": t20, "B": t20 + 25 * MS}, ["A", "B"], period_ns=100 * MS, tolerance_ns=20 * MS)
    assert not far.valid.any()  # B's frames fall halfway (25 ms) between A's: never within 20 ms


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
