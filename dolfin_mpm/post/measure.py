"""Profiles from particles and their measures: binned sums, widths of peaks and of jumps."""

import numpy as np

__all__ = ["bin_sums", "fwhm", "jump_width", "rise_width"]


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


def jump_width(x: np.ndarray, f: np.ndarray) -> tuple[float, float]:
    """10-90 % width and place of the steepest jump of ``f(x)``, in the unit of ``x``.

    The jump is the rise (or fall) of ``f`` between the nearest points on either side of its
    steepest slope where the slope has fallen to a tenth of that slope: the band, apart from
    the gentler flow on either side of it. Its width is the distance over which ``f`` goes
    from 10 % to 90 % of the way across it (``f`` made monotone over the jump first, so that
    noise cannot fold it back). For ``tanh(x / w)`` it reads 1.99 w (the full 10-90 % width is
    2.20 w); a jump that never flattens reads as wide as the profile.
    """
    if len(x) != len(f) or len(x) < 3 or np.any(np.diff(x) <= 0.0):
        raise ValueError("x must increase and have the length of f (at least 3 points)")
    slope = np.gradient(f, x)
    k = int(np.argmax(np.abs(slope)))
    if slope[k] == 0.0:
        raise ValueError("f is constant: no jump to measure")
    steep = np.abs(slope) > 0.1 * abs(slope[k])
    lo, hi = k, k
    while lo > 0 and steep[lo - 1]:
        lo -= 1
    while hi < len(x) - 1 and steep[hi + 1]:
        hi += 1
    lo, hi = max(lo - 1, 0), min(hi + 1, len(x) - 1)  # the flat points that bound it
    xs, fs = x[lo : hi + 1], np.sign(slope[k]) * f[lo : hi + 1]
    fs = np.maximum.accumulate(fs)
    a, b = fs[0] + 0.1 * (fs[-1] - fs[0]), fs[0] + 0.9 * (fs[-1] - fs[0])
    return float(np.interp(b, fs, xs) - np.interp(a, fs, xs)), float(x[k])
