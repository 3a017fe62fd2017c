"""Measurement noise on cumulative passing for synthetic sieve data.

- :class:`GaussianNoise`: y_k = P_k + sigma e_k, e_k independent N(0, 1).
- :class:`AR1Noise`: within each sample, along the sieves from coarse to fine,
  e_k = rho e_{k-1} + sqrt(1 - rho^2) u_k (stationary AR(1), marginal sd sigma), independent
  between samples: the correlated error of a sieve analysis (one mis-weighed fraction
  shifts every cumulative value below it).

The noisy values are kept as they come (they may leave [0, 1] or rise slightly between
sieves, as real data can); nothing is clipped.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from millflow.errors import InputError

__all__ = ["GaussianNoise", "AR1Noise", "make_noise"]


@dataclass(frozen=True)
class GaussianNoise:
    """Independent Gaussian noise of standard deviation ``sigma`` [-] on cumulative passing."""

    sigma: float = 0.01

    def __post_init__(self):
        if not (math.isfinite(self.sigma) and self.sigma > 0):
            raise InputError(f"noise.sigma = {self.sigma!r}: expected a finite number > 0")

    def sample(self, rng, n_samples: int, n_sieves: int) -> np.ndarray:
        """Noise (n_samples, n_sieves) drawn from ``rng``."""
        return self.sigma * rng.standard_normal((n_samples, n_sieves))


@dataclass(frozen=True)
class AR1Noise:
    """AR(1) noise along the sieves of a sample: marginal SD ``sigma`` [-], lag-1 correlation ``rho``."""

    sigma: float = 0.01
    rho: float = 0.5

    def __post_init__(self):
        if not (math.isfinite(self.sigma) and self.sigma > 0):
            raise InputError(f"noise.sigma = {self.sigma!r}: expected a finite number > 0")
        if not (math.isfinite(self.rho) and -1 < self.rho < 1):
            raise InputError(f"noise.rho = {self.rho!r}: expected a number in (-1, 1)")

    def sample(self, rng, n_samples: int, n_sieves: int) -> np.ndarray:
        """Noise (n_samples, n_sieves) drawn from ``rng``, correlated along each row."""
        u = rng.standard_normal((n_samples, n_sieves))
        e = np.empty_like(u)
        e[:, 0] = u[:, 0]
        c = math.sqrt(1.0 - self.rho ** 2)
        for k in range(1, n_sieves):
            e[:, k] = self.rho * e[:, k - 1] + c * u[:, k]
        return self.sigma * e


def make_noise(kind: str, sigma: float, rho: float | None = None):
    """The noise model of a config's ``[noise]`` table: kind "gaussian" or "ar1" (with ``rho``)."""
    if kind == "gaussian":
        if rho is not None:
            raise InputError("noise.rho is only for kind = 'ar1'")
        return GaussianNoise(sigma)
    if kind == "ar1":
        return AR1Noise(sigma, 0.5 if rho is None else rho)
    raise InputError(f"noise.kind = {kind!r}: expected 'gaussian' or 'ar1'")
