"""Profile measurements against closed forms."""

import numpy as np
import pytest

from dolfin_mpm.post.measure import bin_sums, fwhm, jump_width, rise_width


def test_fwhm_of_a_gaussian():
    y = np.linspace(-5.0, 5.0, 2001)
    sigma = 0.7
    g = np.exp(-0.5 * ((y - 1.0) / sigma) ** 2)
    assert abs(fwhm(y, g) - 2.0 * sigma * np.sqrt(2.0 * np.log(2.0))) < 1e-4
    # On a background of 0.3 the half maximum is 0.65, where g = 0.35.
    assert abs(fwhm(y, 0.3 + g) - 2.0 * sigma * np.sqrt(2.0 * np.log(1.0 / 0.35))) < 1e-4


def test_rise_width_of_a_ramp_with_noise():
    y = np.linspace(0.0, 1.0, 1001)
    f = np.clip((y - 0.2) / 0.5, 0.0, 1.0)  # rises over 0.2 .. 0.7
    assert abs(rise_width(y, f) - 0.8 * 0.5) < 1e-9
    dip = f.copy()
    dip[600] -= 0.3  # a dip on the way up does not fold the profile back
    assert abs(rise_width(y, dip) - 0.8 * 0.5) < 1e-9


def test_bin_sums_counts_and_sums_with_outliers_in_the_end_bins():
    coord = np.array([-1.0, 0.1, 0.2, 0.6, 0.9, 2.0])
    values = np.arange(6.0)
    count, total = bin_sums(coord, np.array([0.0, 0.5, 1.0]), values)
    assert np.array_equal(count, [3, 3]) and np.array_equal(total, [0 + 1 + 2, 3 + 4 + 5])


@pytest.mark.parametrize("w", [0.001, 0.003])
def test_jump_width_of_a_step_on_a_gentle_flow(w):
    """A tanh step of width w on a linear background reads 1.99 w at its place, whatever the background."""
    x = np.linspace(0.0, 0.1, 2001)
    width, at = jump_width(x, 0.2 + 1.0 * x + 0.4 * np.tanh((x - 0.04) / w))
    assert width == pytest.approx(1.99 * w, rel=0.03)
    assert at == pytest.approx(0.04, abs=x[1])
    # Falling instead of rising, and on a coarse sampling: the same width to the sampling.
    coarse = x[::40]
    width, _ = jump_width(coarse, 1.0 - np.tanh((coarse - 0.04) / w))
    assert width == pytest.approx(1.99 * w, abs=coarse[1])


def test_jump_width_refuses_what_has_no_jump():
    with pytest.raises(ValueError, match="constant"):
        jump_width(np.linspace(0.0, 1.0, 5), np.ones(5))
    with pytest.raises(ValueError, match="increase"):
        jump_width(np.array([0.0, 2.0, 1.0]), np.zeros(3))
