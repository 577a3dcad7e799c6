"""Session fixtures with simulated data, shared by every stage's tests.

Simulating and curating take tens of seconds, so the results are cached on disk under
``.pytest_cache/drivewm-data/<hash>``, keyed by the source of the stages that make them
(sim, logs, curate) and their recipes: any change there rebuilds the data. A file lock makes
concurrent pytest processes build it once.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import platform
from pathlib import Path

import pytest

os.environ.setdefault("RAY_AUTH_MODE", "disabled")
os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
os.environ.setdefault("SDL_VIDEODRIVER", "offscreen")

#: x86-64: the vector instruction sets the tests' numerics run on, set before numpy and torch load (also for the
#: processes the tests start). NumPy's sin/cos/exp (AVX-512 vs AVX2 code paths) and ATen's and oneDNN's kernels
#: give results that differ in the last bits between CPUs, so the simulator's poses (~1e-15 m apart) and a few
#: training steps' weights differ between an AVX-512 machine and an AVX2 one, while the byte-for-byte references
#: (tests/test_outputs_unchanged.py, tests/curate/test_golden.py) are recorded on AVX2 paths. Users' runs keep
#: their machine's fastest paths: outputs are bit-identical on one kind of CPU, within rounding across kinds.
PINNED_ISA = {
    "NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512_ICL AVX512_SPR",
    "ATEN_CPU_CAPABILITY": "avx2",
    "ONEDNN_MAX_CPU_ISA": "AVX2",
    "OPENBLAS_CORETYPE": "Haswell",
}
if platform.machine().lower() in ("x86_64", "amd64"):
    for _name, _value in PINNED_ISA.items():
        os.environ.setdefault(_name, _value)

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = (REPO / ".." / "shared" / "data").resolve()

#: The drives of the shared simulated dataset: (name, SimConfig fields).
SIM_DRIVES = {
    "highway_clear": dict(source="highway", scenario="highway", weather="clear", time_of_day="day", seed=1),
    "highway_snow": dict(source="highway", scenario="highway", weather="snow", time_of_day="day", seed=2),
    "roundabout_clear": dict(source="highway", scenario="roundabout", weather="clear", time_of_day="day", seed=3),
    "sumo_grid_night": dict(source="sumo", scenario="grid", weather="clear", time_of_day="night", seed=4),
}
SIM_COMMON = dict(rig="nuscenes6", duration_s=6.0, fps=10.0)


#: What each cached data set is made from: a change in any of these files rebuilds it.
LOG_SOURCES = ("drivewm/sim", "drivewm/logs", "drivewm/geometry.py", "drivewm/rigs")
CLIP_SOURCES = (*LOG_SOURCES, "drivewm/curate", "drivewm/clips", "drivewm/recipes/curate")


def _source_hash(*parts: str) -> str:
    digest = hashlib.sha256(repr(sorted((k, os.environ.get(k)) for k in PINNED_ISA)).encode())  # data built pinned
    for part in parts:
        root = REPO / part
        for path in sorted(root.rglob("*")) if root.is_dir() else [root]:
            if path.is_file() and path.suffix in {".py", ".yaml", ".yml"}:
                digest.update(str(path.relative_to(REPO)).encode())
                digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def _cached(name: str, sources: tuple[str, ...], build) -> Path:
    """Build ``name`` once per source version into the cache (atomically, under a lock)."""
    root = Path(os.environ.get("DRIVEWM_TEST_CACHE", REPO / ".pytest_cache" / "drivewm-data"))
    target = root / f"{name}-{_source_hash(*sources)}"
    root.mkdir(parents=True, exist_ok=True)
    with open(root / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (target / ".done").is_file():
            from drivewm.atomic import atomic_path

            with atomic_path(target) as tmp:
                tmp.mkdir()
                build(tmp)
                (tmp / ".done").write_text("ok\n")
    return target


def _build_logs(out: Path) -> None:
    from drivewm.sim import SimConfig, simulate

    for name, fields in SIM_DRIVES.items():
        simulate(SimConfig(**SIM_COMMON, **fields), out / f"{name}.mcap")


def _build_clips(out: Path, log_dir: Path) -> None:
    from drivewm.curate import curate, load_curate_config

    cfg = load_curate_config("test")
    curate(sorted(log_dir.glob("*.mcap")), out, cfg, executor="local", workers=1)


@pytest.fixture(autouse=True, scope="module")
def _one_torch_thread():
    """One intra-op thread per test process: CI's 2 cores also run the torchrun and process-pool
    workers some tests start, and oversubscribed torch threads run many times slower."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The real data folder beside the checkout (../shared/data)."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real test data not found at {SHARED_DATA}")
    return SHARED_DATA


def sim_logs() -> Path:
    """Four simulated nuscenes6 drives (320x192, 10 fps, 6 s): highway clear/snow, roundabout, SUMO grid at night."""
    return _cached("logs", LOG_SOURCES, _build_logs)


def sim_clips() -> Path:
    """:func:`sim_logs` curated with the ``test`` recipe (drivewm/recipes/curate/test.yaml: 17-frame clips, 10 fps)."""
    logs = sim_logs()
    return _cached("clips", CLIP_SOURCES, lambda out: _build_clips(out, logs))


@pytest.fixture(scope="session")
def sim_log_dir() -> Path:
    """:func:`sim_logs`, built once per source version."""
    return sim_logs()


@pytest.fixture(scope="session")
def sim_clip_dir(sim_log_dir: Path) -> Path:
    """:func:`sim_clips`, built once per source version."""
    return sim_clips()


@pytest.fixture(scope="session")
def dashcam_clips(shared_data, tmp_path_factory) -> Path:
    """The shared real dashcam drive through ``import-video`` (no ego poses: 320x192, one CAM_FRONT)
    and curation with the ``test`` recipe: 5 clips of 17 frames whose ego motion is unknown."""
    from drivewm.curate import curate, load_curate_config
    from drivewm.curate.import_video import import_videos

    root = tmp_path_factory.mktemp("dashcam")
    (root / "cam.yaml").write_text(
        "name: dashcam\ncameras:\n"
        "  - {name: CAM_FRONT, width: 320, height: 192, hfov_deg: 60, xyz: [1.7, 0.0, 1.4], yaw_deg: 0}\n"
    )
    video = shared_data / "video/dashcam_highway/solidWhiteRight.mp4"
    logs = import_videos([video], root / "cam.yaml", root / "logs").logs
    curate(logs, root / "clips", load_curate_config("test"), progress=False)
    return root / "clips"


@pytest.fixture
def fake_shipped_weights(tmp_path, monkeypatch) -> Path:
    """drivewm/weights/ replaced by folders that only look shipped (multiview, tokenizer): for
    tests of how ``shipped:KIND`` is resolved, not of the weights."""
    from drivewm import model_folders
    from drivewm.train.checkpoint import WEIGHTS_NAME

    root = tmp_path / "fake_weights"
    for kind in ("multiview", "tokenizer"):
        (root / kind).mkdir(parents=True)
        (root / kind / WEIGHTS_NAME).write_bytes(b"weights")
    monkeypatch.setattr(model_folders, "WEIGHTS_DIR", root)
    return root


@pytest.fixture(scope="session")
def layout_model(tmp_path_factory) -> dict[str, Path]:
    """Untrained multi-view models (tokens) of CAM_FRONT at 80x48, 17 frames, with a real debug tokenizer:
    ``tokens`` trained with layout tokens, ``none`` without a layout."""
    import dataclasses

    import torch

    from drivewm.diffusion.dit_config import DiTConfig
    from drivewm.diffusion.text2world import LatentInfo, Text2World, Text2WorldConfig
    from drivewm.geometry import load_rig
    from drivewm.multiview.config import MultiViewConfig
    from drivewm.multiview.init import from_text2world
    from drivewm.tokenizer import Tokenizer, preset

    root = tmp_path_factory.mktemp("layout_mv")
    torch.manual_seed(0)
    tok = Tokenizer(preset("debug"))
    tok.save_pretrained(root / "tok")
    latent = LatentInfo([16, 5, 6, 10], tok.latent_mean.tolist(), tok.latent_std.tolist(), 10.0, str(root / "tok"), {})
    dit = DiTConfig(in_channels=16, hidden_dim=32, depth=1, num_heads=2, adaln_lora_dim=8)
    models = {}
    for layout in ("tokens", "none"):
        mv = from_text2world(Text2World(Text2WorldConfig(dit), latent), MultiViewConfig(layout=layout))
        mv.latent = dataclasses.replace(mv.latent, rig=load_rig("nuscenes6").subset(["CAM_FRONT"]).to_dict())
        mv.save_pretrained(root / layout)
        models[layout] = root / layout
    return models
