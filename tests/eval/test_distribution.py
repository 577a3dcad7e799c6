"""FID / FVD: pytorch-fid's Fréchet formula, bootstrap intervals with counts, local TorchScript feature networks."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from scipy import linalg

from drivewm.cli import main
from drivewm.clips.video import encode_mp4
from drivewm.errors import DrivewmError
from drivewm.eval.feature_nets import I3DFeatures, InceptionFeatures
from drivewm.eval.frechet import feature_stats, frechet_distance, frechet_with_interval


class TinyInception(torch.nn.Module):
    """The call of the FID Inception TorchScript: ``net(x (N, 3, 299, 299) in [0, 255], return_features=True)``."""

    def __init__(self):
        super().__init__()
        self.proj = torch.nn.Linear(3 * 4 * 4, 8)

    def forward(self, x: torch.Tensor, return_features: bool = False) -> torch.Tensor:
        pooled = torch.nn.functional.adaptive_avg_pool2d(x / 255.0, 4).flatten(1)  # (N, 48)
        out = self.proj(pooled)  # (N, 8)
        return out if return_features else out.softmax(1)


class TinyI3D(torch.nn.Module):
    """The call of the FVD I3D TorchScript: ``net(x (N, 3, T, 224, 224) in [-1, 1], rescale=False, resize=False,
    return_features=True)``."""

    def __init__(self):
        super().__init__()
        self.proj = torch.nn.Linear(3 * 2 * 2 * 2, 6)

    def forward(
        self, x: torch.Tensor, rescale: bool = False, resize: bool = False, return_features: bool = False
    ) -> torch.Tensor:
        pooled = torch.nn.functional.adaptive_avg_pool3d(x, 2).flatten(1)  # (N, 24)
        return self.proj(pooled)  # (N, 6)


@pytest.fixture(scope="module")
def nets(tmp_path_factory) -> dict[str, str]:
    torch.manual_seed(0)
    folder = tmp_path_factory.mktemp("nets")
    paths = {"inception": folder / "inception-2015-12-05.pt", "i3d": folder / "i3d_torchscript.pt"}
    torch.jit.script(TinyInception().eval()).save(str(paths["inception"]))
    torch.jit.script(TinyI3D().eval()).save(str(paths["i3d"]))
    torch.save(TinyInception().state_dict(), folder / "state_dict.pth")  # the wrong format: not TorchScript
    paths["state_dict"] = folder / "state_dict.pth"
    return {k: str(v) for k, v in paths.items()}


def _reference_fd(a: np.ndarray, b: np.ndarray, eps: float = 1e-6) -> float:
    """pytorch-fid 0.3.0's calculate_frechet_distance written out here, on features a, b."""
    mu1, mu2, s1, s2 = a.mean(0), b.mean(0), np.cov(a, rowvar=False), np.cov(b, rowvar=False)
    covmean = linalg.sqrtm(s1 @ s2)
    if not np.isfinite(covmean).all():
        covmean = linalg.sqrtm((s1 + eps * np.eye(len(s1))) @ (s2 + eps * np.eye(len(s2))))
    covmean = covmean.real
    return float((mu1 - mu2) @ (mu1 - mu2) + np.trace(s1) + np.trace(s2) - 2 * np.trace(covmean))


def test_frechet_equals_pytorch_fid_formula_and_closed_forms():
    rng = np.random.default_rng(0)
    a, b = rng.normal(0, 1, (400, 16)), rng.normal(0.3, 1.5, (300, 16)) @ rng.normal(0, 1, (16, 16))
    assert frechet_distance(*feature_stats(a), *feature_stats(b)) == pytest.approx(_reference_fd(a, b), rel=1e-9)
    # Fewer samples than dimensions: singular covariances.
    few_a, few_b = rng.normal(0, 1, (10, 32)), rng.normal(1, 1, (12, 32))
    assert frechet_distance(*feature_stats(few_a), *feature_stats(few_b)) == pytest.approx(
        _reference_fd(few_a, few_b), rel=1e-6
    )
    # Commuting (diagonal) covariances: |mu1 - mu2|^2 + sum (sqrt(v1) - sqrt(v2))^2 exactly.
    v1, v2 = np.array([1.0, 4.0, 9.0]), np.array([4.0, 1.0, 0.25])
    expected = 3 * 0.5**2 + np.sum((np.sqrt(v1) - np.sqrt(v2)) ** 2)
    assert frechet_distance(np.zeros(3), np.diag(v1), np.full(3, 0.5), np.diag(v2)) == pytest.approx(expected)


def test_bootstrap_interval_and_counts_separate_near_and_far_sets():
    rng = np.random.default_rng(1)
    real = rng.normal(0, 1, (300, 4))
    near = frechet_with_interval(rng.normal(0, 1, (200, 4)), real, bootstrap=40)
    far = frechet_with_interval(rng.normal(0.8, 1, (200, 4)), real, bootstrap=40)
    assert near.low <= near.value <= near.high and far.low <= far.value <= far.high
    assert near.high < far.low  # the intervals do not overlap
    assert far.value == pytest.approx(4 * 0.8**2, rel=0.25)
    assert (near.num_generated, near.num_real) == (200, 300) and "n=200 generated, 300 real" in near.text()


def test_feature_networks_load_from_local_torchscript_and_refuse_other_files(nets, tmp_path):
    rng = np.random.default_rng(2)
    frames = rng.integers(0, 256, (5, 48, 80, 3), dtype=np.uint8)
    feats = InceptionFeatures(nets["inception"], batch=2)(frames)
    assert feats.shape == (5, 8) and np.all(np.isfinite(feats))
    assert not np.allclose(feats[0], feats[1])  # different frames, different features
    clip = I3DFeatures(nets["i3d"])([frames[:4], frames[1:5]])
    assert clip.shape == (2, 6)
    junk = tmp_path / "junk.pt"
    junk.write_bytes(b"not a network")
    for path in (nets["state_dict"], junk):
        with pytest.raises(DrivewmError, match="not a TorchScript Inception file"):
            InceptionFeatures(path)
    with pytest.raises(DrivewmError, match="does not take"):  # an Inception file given as I3D
        I3DFeatures(nets["inception"])([frames[:4]])


def _clip_folders(root, clips: int, shift: int, T: int = 6):
    """``clips`` folders of front3 CAMERA.mp4 (80x48, 5:3 like the rig): textures drifting sideways."""
    rng = np.random.default_rng(shift)
    for k in range(clips):
        for cam in ("CAM_FRONT_LEFT", "CAM_FRONT", "CAM_FRONT_RIGHT"):
            tex = rng.integers(0, 256, (48, 200, 3), dtype=np.uint8) // (1 + shift)
            video = np.stack([tex[:, 2 * t : 2 * t + 80] for t in range(T)])
            (root / f"clip{k}").mkdir(parents=True, exist_ok=True)
            (root / f"clip{k}" / f"{cam}.mp4").write_bytes(encode_mp4(video, 10.0))


def test_cli_distribution_per_view_and_all_views_with_counts(nets, tmp_path, capsys):
    _clip_folders(tmp_path / "gen", 3, shift=1)
    _clip_folders(tmp_path / "real", 3, shift=0)
    args = ["eval", "distribution", str(tmp_path / "gen"), "--real", str(tmp_path / "real"), "--rig", "front3"]
    nets_args = ["--inception", nets["inception"], "--i3d", nets["i3d"], "--fvd-frames", "4", "--bootstrap", "10"]
    assert main([*args, *nets_args, "--frames", "1:6", "--out", str(tmp_path / "d")]) == 0
    out = capsys.readouterr().out
    m = json.loads((tmp_path / "d" / "distribution.json").read_text())
    assert set(m["fid"]) == {"CAM_FRONT_LEFT", "CAM_FRONT", "CAM_FRONT_RIGHT", "all"}
    assert m["fid"]["CAM_FRONT"]["num_generated"] == 3 * 5 and m["fid"]["CAM_FRONT"]["num_real"] == 3 * 6
    assert m["fid"]["all"]["num_generated"] == 45 and m["fvd"]["all"]["num_generated"] == 9
    assert m["fid"]["all"]["value"] > 0 and m["fid"]["all"]["low"] <= m["fid"]["all"]["high"]
    assert "n=45 generated, 54 real" in out and "| FVD | all |" in out
    # The same clips as both sets: FID of the pooled views ~0 beside the darker generated set.
    assert main(["eval", "distribution", str(tmp_path / "real"), "--real", str(tmp_path / "real"), "--rig",
                 "front3", "--inception", nets["inception"], "--out", str(tmp_path / "same")]) == 0  # fmt: skip
    same = json.loads((tmp_path / "same" / "distribution.json").read_text())
    assert abs(same["fid"]["all"]["value"]) < 1e-6 < m["fid"]["all"]["value"]
    capsys.readouterr()
    bad = [*args, "--inception", nets["state_dict"], "--out", str(tmp_path / "bad")]
    assert main(bad) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and "not a TorchScript Inception file" in err[0]
