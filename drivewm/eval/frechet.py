"""The Fréchet distance between two feature sets (FID, FVD) with its sample count and a bootstrap interval.

FID (Heusel et al. 2017, eq. 6) and FVD (Unterthiner et al. 2018, sec. 3) are the same formula on
different features: d^2 = |mu_1 - mu_2|^2 + Tr(C_1 + C_2 - 2 sqrt(C_1 C_2)). :func:`frechet_distance`
follows pytorch-fid's ``calculate_frechet_distance`` (pytorch_fid/fid_score.py, v0.3.0) step for step:
``scipy.linalg.sqrtm`` of the product, ``eps`` added to both diagonals when that square root is not
finite, the imaginary part dropped when its diagonal is within 1e-3 of zero. Both figures move with
the number of samples (the estimate is biased, Chong & Forsyth 2020), so every figure carries its
counts and a bootstrap interval.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
from scipy import linalg

from drivewm.errors import DrivewmError


def feature_stats(features: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean (D,) and covariance (D, D) of features (N, D), as pytorch-fid computes them
    (``np.mean(axis=0)``, ``np.cov(rowvar=False)``: unbiased, N - 1)."""
    features = np.asarray(features, dtype=np.float64)
    return np.mean(features, axis=0), np.atleast_2d(np.cov(features, rowvar=False))


def frechet_distance(mu1: np.ndarray, sigma1: np.ndarray, mu2: np.ndarray, sigma2: np.ndarray, eps=1e-6) -> float:
    """Squared Fréchet distance of N(mu1, sigma1) and N(mu2, sigma2), pytorch-fid's formula."""
    mu1, mu2 = np.atleast_1d(mu1), np.atleast_1d(mu2)
    sigma1, sigma2 = np.atleast_2d(sigma1), np.atleast_2d(sigma2)
    if mu1.shape != mu2.shape or sigma1.shape != sigma2.shape:
        raise DrivewmError(f"Fréchet distance: feature sizes differ ({mu1.shape} against {mu2.shape})")
    diff = mu1 - mu2
    with warnings.catch_warnings():  # pytorch-fid's disp=False: a singular product is handled below, not printed
        warnings.simplefilter("ignore", linalg.LinAlgWarning)
        covmean = linalg.sqrtm(sigma1.dot(sigma2))
        if not np.isfinite(covmean).all():  # a nearly singular product: offset both diagonals (pytorch-fid)
            offset = np.eye(sigma1.shape[0]) * eps
            covmean = linalg.sqrtm((sigma1 + offset).dot(sigma2 + offset))
    if np.iscomplexobj(covmean):
        if not np.allclose(np.diagonal(covmean).imag, 0, atol=1e-3):
            raise DrivewmError(f"Fréchet distance: imaginary component {np.max(np.abs(covmean.imag)):.3g}")
        covmean = covmean.real
    return float(diff.dot(diff) + np.trace(sigma1) + np.trace(sigma2) - 2 * np.trace(covmean))


@dataclasses.dataclass
class DistributionFigure:
    """One distribution metric with what it rests on."""

    value: float
    """The Fréchet distance of all samples."""
    low: float
    """Bootstrap interval, lower end (percentile)."""
    high: float
    """Bootstrap interval, upper end (percentile)."""
    num_generated: int
    """Generated samples (frames for FID, clips for FVD)."""
    num_real: int
    """Real samples."""
    bootstrap: int
    """Bootstrap resamples the interval rests on."""
    confidence: float
    """Interval coverage (e.g. 0.95)."""

    def text(self) -> str:
        pct = round(100 * self.confidence)
        return (
            f"{self.value:.2f} [{pct}%: {self.low:.2f}, {self.high:.2f}] "
            f"(n={self.num_generated} generated, {self.num_real} real)"
        )


def frechet_with_interval(
    generated: np.ndarray, real: np.ndarray, bootstrap: int = 50, confidence: float = 0.95, seed: int = 0
) -> DistributionFigure:
    """Fréchet distance of features (N, D) and (M, D) with a percentile bootstrap interval: both sets
    resampled with replacement ``bootstrap`` times (Efron & Tibshirani 1993, ch. 13)."""
    if len(generated) < 2 or len(real) < 2:
        raise DrivewmError(
            f"Fréchet distance: needs at least 2 samples per set, got {len(generated)} generated, {len(real)} real"
        )
    value = frechet_distance(*feature_stats(generated), *feature_stats(real))
    rng = np.random.default_rng(seed)
    draws = [
        frechet_distance(
            *feature_stats(generated[rng.integers(0, len(generated), len(generated))]),
            *feature_stats(real[rng.integers(0, len(real), len(real))]),
        )
        for _ in range(bootstrap)
    ]
    tail = 100 * (1 - confidence) / 2
    low, high = np.percentile(draws, [tail, 100 - tail]) if draws else (np.nan, np.nan)
    return DistributionFigure(value, float(low), float(high), len(generated), len(real), bootstrap, confidence)
