"""The shared simulated test data curates to the same bytes as before the streaming reader:
the simulator's logs and every shard member (mp4, ego poses, clip JSON) against fingerprints
taken at commit c5bca50 (tests/curate/golden_clips.py, data/shared_clips_golden.json)."""

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from golden_clips import GOLDEN, fingerprints  # noqa: E402


def test_shared_logs_and_clips_are_byte_identical_to_the_reference(sim_log_dir, sim_clip_dir):
    want = json.loads(GOLDEN.read_text())
    got = fingerprints(sim_log_dir, sim_clip_dir)
    assert sorted(got) == sorted(want), "different logs, shards or shard members"
    assert len([k for k in want if k.endswith(".mp4")]) == 72  # 4 drives x 3 clips x 6 cameras
    assert len([k for k in want if k.endswith(".layout.npz")]) == 12  # one layout per clip
    changed = sorted(k for k in want if got[k] != want[k])
    assert not changed, f"{len(changed)} of {len(want)} files changed, e.g. {changed[:4]}"
