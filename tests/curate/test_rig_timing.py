"""Real rigs' clocks: a clock jumping forward by an hour, a clock jumping back (recorder time still
moving on), a camera whose rate wanders. Each is curated without mixing time bases, and the
report says why ticks were lost."""

from pathlib import Path

import cv2
import numpy as np
import pytest

from drivewm.clips import iter_clips
from drivewm.curate import curate, load_curate_config
from drivewm.geometry import T_from_xyz_yaw, load_rig
from drivewm.logs.types import SceneInfo
from drivewm.logs.writer import LogWriter

pytestmark = pytest.mark.slow  # writes and curates three logs (~30 s on the shared 2-core machine)

T0 = 1_700_000_000_000_000_000
MS = 1_000_000
RIG = load_rig("front3")


def _jpeg(i: int, v: int, seed: int) -> bytes:
    """Frame i of camera v: a sharp pattern (one per log ``seed``) that slides 2 px per frame."""
    W, H = RIG.cameras[0].width, RIG.cameras[0].height
    rng = np.random.default_rng([seed, v])
    base = cv2.resize(rng.integers(0, 256, (H // 6, W // 3, 3), dtype=np.uint8), (W * 2, H), cv2.INTER_CUBIC)
    img = np.ascontiguousarray(base[:, (2 * i) % W :][:, :W])
    return cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 92])[1].tobytes()


def write_timed_log(path: Path, stamps: dict[str, list[int]], pose_stamps: list[int], seed: int) -> Path:
    """A front3 log whose message stamps are given (camera -> per-frame stamps, in recording order)
    while the recorder's log time moves on by 100 ms per frame; the ego moves at 8 m/s in stamp time."""
    scene = SceneInfo({"weather": "clear", "time_of_day": "day", "source": "synthetic"}, "clock test")
    with LogWriter(path, RIG, scene) as w:
        for i in range(max(len(pose_stamps), *map(len, stamps.values()))):
            if i < len(pose_stamps):
                t = pose_stamps[i]
                w.write_pose(t, T_from_xyz_yaw(8.0 * (t - T0) / 1e9, 0.0, 0.0, 0.0), log_time_ns=T0 + i * 100 * MS)
            for v, cam in enumerate(RIG.names):
                if i < len(stamps[cam]):
                    w.write_encoded_image(
                        cam, stamps[cam][i], _jpeg(i, v, seed), "jpeg", log_time_ns=T0 + i * 100 * MS + 1
                    )
    return path


@pytest.fixture(scope="module")
def curated(tmp_path_factory):
    root = tmp_path_factory.mktemp("clocks")
    n = np.arange(80)
    forward = [T0 + int(i) * 100 * MS + (3600_000 + 37) * MS * (i >= 40) for i in n]  # +1 h and a new phase at frame 40
    back = [T0 + int(i) * 100 * MS - 4000 * MS * (i >= 60) for i in np.arange(120)]  # back 4 s at frame 60
    rng = np.random.default_rng(0)
    jittered = T0 + np.arange(40) * 100 * MS + rng.integers(-15, 16, 40) * MS  # 10 Hz +-15 ms: 7.7-14 Hz
    wander = jittered.tolist() + [T0 + 4000 * MS + int(i) * 50 * MS for i in range(80)]  # then 20 Hz
    steady = [T0 + int(i) * 100 * MS for i in n]
    logs = [
        write_timed_log(root / "forward.mcap", {c: forward for c in RIG.names}, forward, seed=1),
        write_timed_log(root / "back.mcap", {c: back for c in RIG.names}, back, seed=2),
        write_timed_log(
            root / "wander.mcap",
            {"CAM_FRONT_LEFT": steady, "CAM_FRONT": steady, "CAM_FRONT_RIGHT": wander},
            steady,
            seed=3,
        ),
    ]
    cfg = load_curate_config("test")
    report = curate(logs, root / "out", cfg, progress=False)
    return report, {c.key: c for c in iter_clips(root / "out")}


def test_a_clock_jumping_forward_an_hour_restarts_the_ticks(curated):
    report, clips = curated
    log = report["logs"]["forward"]
    assert log["status"] == "ok" and log["sync"]["ticks"] == 81  # 40 + 1 separator + 40, not 36,000
    assert log["kept"] == 4  # two clips on each side of the jump
    assert any("gap(s) longer than max_gap_ms" in w for w in log["warnings"])
    for clip in (c for k, c in clips.items() if k.startswith("forward")):
        t = np.array(clip.meta.timestamps_ns)
        assert np.all(np.diff(t) == 100 * MS)  # never across the jump


def test_a_clock_jumping_back_never_mixes_time_bases(curated):
    report, clips = curated
    log = report["logs"]["back"]
    assert log["status"] == "ok" and log["kept"] == 2  # 0-2 s and 6-8 s: the repeated 2-6 s is invalid
    (why,) = [w for w in log["warnings"] if "CAM_FRONT:" in w and "jump back" in w]
    assert "-3.900 s" in why and "40 frames dropped" in why
    starts = sorted(c.meta.timestamps_ns[0] - T0 for k, c in clips.items() if k.startswith("back"))
    assert starts == [0, 6000 * MS]
    for clip in (c for k, c in clips.items() if k.startswith("back")):
        t = np.array(clip.meta.timestamps_ns) - T0
        assert np.all(np.diff(t) == 100 * MS) and (t.max() < 2000 * MS or t.min() >= 6000 * MS)
        frame = clip.video("CAM_FRONT")[0]
        i = t[0] // (100 * MS) + (40 if t[0] >= 6000 * MS else 0)  # recording index of that stamp
        src = cv2.imdecode(np.frombuffer(_jpeg(int(i), 1, 2), np.uint8), cv2.IMREAD_COLOR)[..., ::-1]
        assert 10 * np.log10(255**2 / np.mean((frame.astype(float) - src) ** 2)) > 30  # the frame of that epoch


def test_a_wandering_frame_rate_is_reported_and_resampled_within_tolerance(curated):
    report, clips = curated
    log = report["logs"]["wander"]
    (why,) = [w for w in log["warnings"] if w.startswith("CAM_FRONT_RIGHT: variable frame rate")]
    st = log["sync"]["cameras"]["CAM_FRONT_RIGHT"]
    assert st["rate_p5_hz"] < 9.0 and st["rate_p95_hz"] == pytest.approx(20.0) and st["rate_hz"] == pytest.approx(20.0)
    assert log["kept"] == 4 and st["missing_ticks"] == 0, log  # nearest frames stay within the tolerance
    for clip in (c for k, c in clips.items() if k.startswith("wander")):
        right = np.array(clip.meta.camera_times_ns("CAM_FRONT_RIGHT"))
        assert np.abs(right - np.array(clip.meta.timestamps_ns)).max() <= 25 * MS
