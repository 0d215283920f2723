"""Material drivers without a grid: the hypo-elastic law and its objective integration."""

import numpy as np
import pytest

from dolfin_mpm.materials import LinearElastic
from dolfin_mpm.materials.tensor import invariants


def simple_shear(material, gamma_end, steps, gamma_rate=1.0):
    """Drive one point through simple shear v_x = gamma_rate * y; return gamma and stresses."""
    dt = gamma_end / gamma_rate / steps
    L = np.zeros((1, 2, 2))
    L[0, 0, 1] = gamma_rate
    sigma = np.zeros((1, 3, 3))
    out = [sigma[0].copy()]
    for _ in range(steps):
        sigma = material.update(sigma, L, dt, {})
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


def reference_update(mat, sigma, L, dt):
    """The Hughes–Winget update by dense linear algebra: Q = (I - A)^-1 (I + A), A = dt W / 2."""
    g = L.shape[1]
    L3 = np.zeros((len(L), 3, 3))
    L3[:, :g, :g] = L  # plane strain in 2D
    d, W = 0.5 * (L3 + np.swapaxes(L3, 1, 2)), 0.5 * (L3 - np.swapaxes(L3, 1, 2))
    eye = np.broadcast_to(np.eye(3), W.shape)
    Q = np.linalg.solve(eye - 0.5 * dt * W, eye + 0.5 * dt * W)
    tr = np.trace(d, axis1=1, axis2=2)[:, None, None]
    return Q @ sigma @ np.swapaxes(Q, 1, 2) + dt * ((mat.K - 2 * mat.G / 3) * tr * eye + 2 * mat.G * d)


@pytest.mark.parametrize("gdim", [2, 3])
def test_update_equals_the_rotation_by_dense_algebra(gdim):
    rng = np.random.default_rng(1)
    mat = LinearElastic(E=10.0, nu=0.25, rho=1.0)
    L = rng.normal(size=(40, gdim, gdim))
    S = rng.normal(size=(40, 3, 3))
    S = S + np.swapaxes(S, 1, 2)
    for dt in (1e-3, 0.7, 30.0):  # up to rotations by nearly pi
        new = mat.update(S, L, dt, {})
        assert np.allclose(new, reference_update(mat, S, L, dt), rtol=1e-13, atol=1e-13 * np.abs(S).max())
        assert np.array_equal(new, np.swapaxes(new, 1, 2))  # exactly symmetric


def test_rotation_is_objective():
    # A pure spin leaves the invariants of any stress unchanged, for any size of dt W.
    rng = np.random.default_rng(0)
    W = rng.normal(size=(50, 3, 3))
    W = W - np.swapaxes(W, 1, 2)
    mat = LinearElastic(E=10.0, nu=0.25, rho=1.0)
    S = rng.normal(size=(50, 3, 3))
    S = S + np.swapaxes(S, 1, 2)
    S2 = mat.update(S.copy(), W, 0.7, {})
    for a, b in zip(invariants(S), invariants(S2)):
        assert np.allclose(a, b, rtol=1e-12)
    assert np.allclose(np.linalg.eigvalsh(S2), np.linalg.eigvalsh(S), atol=1e-12 * np.abs(S).max())


def test_trial_splits_the_update():
    rng = np.random.default_rng(2)
    mat = LinearElastic(E=10.0, nu=0.25, rho=1.0)
    L = rng.normal(size=(30, 3, 3))
    S = rng.normal(size=(30, 3, 3))
    S = S + np.swapaxes(S, 1, 2)
    trial = mat.trial(S, L, 0.1)
    p, s, q = trial.p, trial.s, trial.q
    new = mat.update(S, L, 0.1, {})
    p_ref, q_ref = invariants(new)
    assert np.allclose(p, p_ref, rtol=1e-14, atol=1e-14) and np.allclose(q, q_ref, rtol=1e-13)
    assert np.allclose(np.moveaxis(s, -1, 0) - p[:, None, None] * np.eye(3), new, atol=1e-14)
    assert np.allclose(s[0, 0] + s[1, 1] + s[2, 2], 0.0, atol=1e-14)


def test_elastic_uniaxial_strain_and_energy():
    mat = LinearElastic(E=2e5, nu=0.2, rho=1.0)
    d = np.zeros((1, 3, 3))
    d[0, 0, 0] = 1e-3
    s = mat.update(np.zeros((1, 3, 3)), d, 1.0, {})
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
