"""Profiles from particles and their measures: binned sums, widths of peaks and of jumps."""

import numpy as np

__all__ = ["bin_sums", "fwhm", "rise_width"]


def bin_sums(coord: np.ndarray, edges: np.ndarray, *values: np.ndarray) -> np.ndarray:
    """Point count and sums of each of ``values`` over the bins ``edges`` of ``coord``.

    Points beyond the outer edges count in the end bins. ``shape=(1 + len(values), len(edges) - 1)``.
    """
    n = len(edges) - 1
    bins = np.clip(np.digitize(coord, edges) - 1, 0, n - 1)
    return np.array([np.bincount(bins, v, minlength=n) for v in (None, *values)], dtype=np.float64)


def fwhm(y: np.ndarray, f: np.ndarray) -> float:
    """Full width at half maximum of the highest peak of ``f(y)`` (linear interpolation).

    ``y`` increasing, ``f`` sampled on it; the result has the unit of ``y``.
    """
    k = int(np.argmax(f))
    half = 0.5 * f[k]
    lo = k
    while lo > 0 and f[lo - 1] > half:
        lo -= 1
    hi = k
    while hi < len(f) - 1 and f[hi + 1] > half:
        hi += 1
    left = y[lo] if lo == 0 else y[lo - 1] + (half - f[lo - 1]) / (f[lo] - f[lo - 1]) * (y[lo] - y[lo - 1])
    right = y[hi] if hi == len(f) - 1 else y[hi] + (f[hi] - half) / (f[hi] - f[hi + 1]) * (y[hi + 1] - y[hi])
    return float(right - left)


def rise_width(y: np.ndarray, f: np.ndarray) -> float:
    """Distance over which ``f(y)`` rises from 10 % to 90 % of the way from ``f[0]`` to its maximum.

    The profile is replaced by its running maximum first, so noise cannot fold it back;
    the result has the unit of ``y``.
    """
    if len(y) != len(f) or len(y) < 2 or np.any(np.diff(y) <= 0.0):
        raise ValueError("y must increase and have the length of f (at least 2 points)")
    f = np.maximum.accumulate(f)
    if not f[-1] > f[0]:
        raise ValueError("f does not rise: no width to measure")
    lo, hi = f[0] + 0.1 * (f[-1] - f[0]), f[0] + 0.9 * (f[-1] - f[0])
    return float(np.interp(hi, f, y) - np.interp(lo, f, y))
