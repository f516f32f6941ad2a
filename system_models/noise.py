"""Sensor noise (seeded, reproducible) and quantisation.

:class:`SampledNoise` is a piecewise-constant random signal: a new sample every
``sample_period`` [s] from ``start`` on, held until the next (as MSL's
``Modelica.Blocks.Noise.UniformNoise`` does).  Samples come from NumPy's PCG64 generator seeded
with ``seed``: the k-th sample is the same whatever the order or number of queries, the same seed
gives the same signal on every run and machine, another seed an independent one.  (It is not the
generator MSL uses, xorshift128+: a realisation of MSL's noise is not reproduced, only its
distribution.)

:func:`quantise` rounds to the nearest multiple of a resolution (a mid-tread quantiser: an
encoder of 2π/4096 rad per count, an ADC of V_ref/2^n per code); its error lies in
±resolution/2.  :class:`Sensor` is what a controller reads: the true value plus noise, quantised.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["SampledNoise", "quantise", "Sensor", "NOISE_KINDS"]

NOISE_KINDS = ("uniform", "normal")


class SampledNoise:
    """Piecewise-constant noise, one sample per period (module docstring).

    Parameters
    ----------
    kind : {"uniform", "normal"}
    sample_period : float
        Period between samples [s], > 0.
    seed : int
        Seed of the generator (>= 0).
    low, high : float
        Bounds of the uniform distribution [unit of the signal], low < high.
    std : float
        Standard deviation of the normal distribution [unit], >= 0 (mean 0).
    start : float
        Time of the first sample [s].
    """

    _CHUNK = 4096

    def __init__(self, kind: str = "uniform", sample_period: float = 1e-3, seed: int = 0,
                 low: float = -1.0, high: float = 1.0, std: float = 1.0, start: float = 0.0) -> None:
        if kind not in NOISE_KINDS:
            raise ValueError(f"noise.kind = {kind!r} is not allowed: must be one of "
                             f"{', '.join(NOISE_KINDS)}")
        if not (math.isfinite(sample_period) and sample_period > 0.0):
            raise ValueError(f"noise.sample_period = {sample_period!r} s is out of range: must "
                             "be a finite number > 0")
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise ValueError(f"noise.seed = {seed!r} is out of range: must be an integer >= 0")
        if kind == "uniform" and not (math.isfinite(low) and math.isfinite(high) and low < high):
            raise ValueError(f"noise.low, noise.high = {low!r}, {high!r}: must be finite with "
                             "low < high")
        if kind == "normal" and not (math.isfinite(std) and std >= 0.0):
            raise ValueError(f"noise.std = {std!r} is out of range: must be a finite number >= 0")
        self.kind, self.period, self.seed = kind, float(sample_period), seed
        self.low, self.high, self.std, self.start = float(low), float(high), float(std), float(start)
        self._rng = np.random.Generator(np.random.PCG64(seed))
        self._samples = np.empty(0)

    def sample(self, k: int) -> float:
        """The k-th sample (k >= 0)."""
        while k >= self._samples.size:
            n = self._CHUNK
            new = (self._rng.uniform(self.low, self.high, n) if self.kind == "uniform"
                   else self._rng.normal(0.0, self.std, n))
            self._samples = np.concatenate([self._samples, new])
        return float(self._samples[k])

    def __call__(self, t: float) -> float:
        """The noise at time ``t`` [s] (the sample of the period containing t; 0 before start)."""
        if t < self.start:
            return 0.0
        # the small guard puts a time that is a sample instant up to rounding into its period
        return self.sample(int(math.floor((t - self.start) / self.period + 1e-9)))


def quantise(x: float, resolution: float) -> float:
    """x rounded to the nearest multiple of ``resolution`` (> 0); 0 means no quantisation."""
    if resolution == 0.0:
        return x
    return resolution * math.floor(x / resolution + 0.5)


class Sensor:
    """A measurement: value + noise(t), quantised to ``resolution`` (0: not quantised).

    Parameters
    ----------
    noise : SampledNoise or None
        Additive noise (None: none).
    resolution : float
        Quantisation step [unit of the signal], >= 0.
    """

    def __init__(self, noise: SampledNoise | None = None, resolution: float = 0.0) -> None:
        if not (math.isfinite(resolution) and resolution >= 0.0):
            raise ValueError(f"sensor.resolution = {resolution!r} is out of range: must be a "
                             "finite number >= 0")
        self.noise, self.resolution = noise, float(resolution)

    def __call__(self, t: float, value: float) -> float:
        """The measured value at ``t`` [s] of the true ``value``."""
        v = value + (self.noise(t) if self.noise is not None else 0.0)
        return quantise(v, self.resolution)
