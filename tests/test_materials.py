"""Material drivers without a grid: the hypo-elastic law and its objective integration."""

import numpy as np
import pytest

from dolfin_mpm.materials import LinearElastic
from dolfin_mpm.tensor import invariants, jaumann_rotate, jaumann_rotation, rotate, split_velocity_gradient


def simple_shear(material, gamma_end, steps, gamma_rate=1.0):
    """Drive one point through simple shear v_x = gamma_rate * y; return gamma and stresses."""
    dt = gamma_end / gamma_rate / steps
    L = np.zeros((1, 2, 2))
    L[0, 0, 1] = gamma_rate
    d, W = split_velocity_gradient(L)
    sigma = np.zeros((1, 3, 3))
    out = [sigma[0].copy()]
    for _ in range(steps):
        sigma = material.update(sigma, d, W, dt, {})
        out.append(sigma[0].copy())
    return np.linspace(0.0, gamma_end, steps + 1), np.array(out)


def test_jaumann_simple_shear_matches_analytic_solution():
    mat = LinearElastic(E=1e6, nu=0.3, rho=1500.0)
    G = mat.G
    gamma, s = simple_shear(mat, 2 * np.pi, 2000)
    assert np.max(np.abs(s[:, 0, 1] - G * np.sin(gamma))) < 0.01 * G
    assert np.max(np.abs(s[:, 0, 0] - G * (1 - np.cos(gamma)))) < 0.01 * G
    assert np.max(np.abs(s[:, 1, 1] + G * (1 - np.cos(gamma)))) < 0.01 * G
    assert np.max(np.abs(s[:, 2, 2])) < 1e-9 * G  # no out-of-plane stress in simple shear
    # The update converges at second order in dt.
    errors = [
        np.abs(simple_shear(mat, 2 * np.pi, n)[1][-1, 0, 1] - G * np.sin(2 * np.pi)) for n in (200, 400, 800)
    ]
    rate = np.polyfit(np.log([200, 400, 800]), np.log(errors), 1)[0]
    assert rate < -1.8


def test_rotation_is_orthogonal_and_objective():
    rng = np.random.default_rng(0)
    L = rng.normal(size=(50, 3, 3))
    _, W = split_velocity_gradient(L)
    Q = jaumann_rotation(W, 0.7)
    assert np.allclose(Q @ np.swapaxes(Q, 1, 2), np.eye(3), atol=1e-14)
    assert np.allclose(np.linalg.det(Q), 1.0)
    # A pure spin leaves the invariants of any stress unchanged.
    mat = LinearElastic(E=10.0, nu=0.25, rho=1.0)
    S = rng.normal(size=(50, 3, 3))
    S = S + np.swapaxes(S, 1, 2)
    S2 = mat.update(S.copy(), np.zeros_like(W), W, 0.7, {})
    for a, b in zip(invariants(S), invariants(S2)):
        assert np.allclose(a, b, rtol=1e-12)


@pytest.mark.parametrize("gdim", [2, 3])
def test_jaumann_rotate_equals_the_general_product(gdim):
    # 2D: the planar shortcut; it must reproduce the general product exactly.
    rng = np.random.default_rng(1)
    _, W = split_velocity_gradient(rng.normal(size=(40, gdim, gdim)))
    S = rng.normal(size=(40, 3, 3))
    S = S + np.swapaxes(S, 1, 2)
    assert np.array_equal(jaumann_rotate(S, W, 0.3), rotate(S, jaumann_rotation(W, 0.3)))


def test_elastic_uniaxial_strain_and_energy():
    mat = LinearElastic(E=2e5, nu=0.2, rho=1.0)
    d = np.zeros((1, 3, 3))
    d[0, 0, 0] = 1e-3
    s = mat.update(np.zeros((1, 3, 3)), d, np.zeros((1, 3, 3)), 1.0, {})
    M = mat.K + 4 * mat.G / 3
    assert s[0, 0, 0] == pytest.approx(M * 1e-3)
    assert s[0, 1, 1] == pytest.approx((mat.K - 2 * mat.G / 3) * 1e-3)
    assert mat.strain_energy_density(s)[0] == pytest.approx(0.5 * M * 1e-6)
    assert mat.p_wave_speed() == pytest.approx(np.sqrt(M))


@pytest.mark.parametrize(
    "kwargs, name",
    [({"E": 0.0}, "E"), ({"E": -1.0}, "E"), ({"nu": 0.5}, "nu"), ({"nu": -1.0}, "nu"),
     ({"rho": 0.0}, "rho"), ({"E": float("nan")}, "E")],
)  # fmt: skip
def test_bad_elastic_parameters(kwargs, name):
    args = {"E": 1e6, "nu": 0.3, "rho": 1500.0} | kwargs
    with pytest.raises(ValueError, match=rf"^{name} must be in"):
        LinearElastic(**args)
