"""Drucker–Prager matched to Mohr–Coulomb in plane strain: the match, the return and its tangent."""

import numpy as np
import pytest

from dolfin_mpm.materials import DruckerPragerViscoplastic, MohrCoulombDruckerPrager
from dolfin_mpm.materials.tensor import from_mandel, invariants, to_mandel

ELASTIC = {"E": 10e6, "nu": 0.3, "rho": 2000.0}
RNG = np.random.default_rng(11)
PSI = [None, 0.0, 12.0]  # associated, isochoric, in between


def material(psi, phi=30.0, c=10e3):
    return MohrCoulombDruckerPrager(**ELASTIC, phi=phi, c=c, psi=psi)


def around_apex(mat, n=400):
    """Random stresses with mean pressures from beyond the apex to well inside the cone, and
    random strain increments (Mandel)."""
    a = mat.tension_limit
    sigma = from_mandel(RNG.normal(0.0, 0.5 * a, (n, 6)))
    sigma -= RNG.uniform(-2.5 * a, 2.0 * a, n)[:, None, None] * np.eye(3)
    return sigma, RNG.normal(0.0, 0.5 * a / mat.E, (n, 6))


def step(mat, sigma, deps):
    return mat.small_strain_update(sigma, from_mandel(deps), {"eps_p": np.zeros(len(sigma))})


@pytest.mark.parametrize("psi", PSI)
def test_plane_strain_flow_on_the_cone_is_mohr_coulomb(psi):
    """In-plane principal stresses on the Mohr–Coulomb line, sigma_zz from the plane-strain flow
    condition (de_zz^p = 0, found by bisection): the stress is on the cone and flows with
    Mohr–Coulomb's dilatancy, -(de_1 + de_3) / (de_1 - de_3) = sin(psi)."""
    phi, c, mat = 30.0, 10e3, material(psi)
    sphi, cphi = np.sin(np.radians(phi)), np.cos(np.radians(phi))
    spsi = np.sin(np.radians(phi if psi is None else psi))
    for s in (-0.5 * c, 0.0, 3.0 * c, 40.0 * c):  # centre of Mohr's circle, compression positive
        t = s * sphi + c * cphi
        s1, s3 = -(s - t), -(s + t)  # tension positive, s1 > s3

        def flow(sz, s1=s1, s3=s3):
            sig = np.diag([s1, s3, sz])
            p, q = -np.trace(sig) / 3.0, invariants(sig[None])[1][0]
            return 1.5 * (sz + p) / q + mat.M_g / 3.0, p, q  # dg/dsigma_zz

        lo, hi = s3, s1  # flow(s3) < 0 < flow(s1)
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if flow(mid)[0] < 0.0 else (lo, mid)
        _, p, q = flow(lo)
        assert q == pytest.approx(mat.M * (p + mat.tension_limit), rel=1e-10)
        n1 = 1.5 * (s1 + p) / q + mat.M_g / 3.0
        n3 = 1.5 * (s3 + p) / q + mat.M_g / 3.0
        assert -(n1 + n3) / (n1 - n3) == pytest.approx(-spsi, rel=1e-10, abs=1e-12)


def test_associated_slope_is_the_classical_plane_strain_match():
    t = np.tan(np.radians(30.0))
    mat = material(None)
    assert mat.M == pytest.approx(3.0 * np.sqrt(3.0) * t / np.sqrt(9.0 + 12.0 * t * t), rel=1e-14)
    assert mat.M_g == pytest.approx(mat.M, rel=1e-14)
    assert material(0.0).M == pytest.approx(np.sqrt(3.0) * 0.5, rel=1e-14)


@pytest.mark.parametrize("psi", PSI)
def test_return_lands_on_the_cone_or_its_apex(psi):
    mat = material(psi)
    sigma, deps = around_apex(mat)
    trial = mat.trial(sigma, from_mandel(deps), 1.0)
    de = mat.increment(trial, {}, 1.0)
    sig, _, new = step(mat, sigma, deps)
    p, q = invariants(sig)
    a = mat.tension_limit
    apex = mat.at_apex(trial)
    cone = (de > 0.0) & ~apex
    assert apex.sum() > 20 and cone.sum() > 20 and (de == 0).sum() > 20
    assert np.all(np.isfinite(de)) and np.all(de >= 0.0)
    np.testing.assert_allclose(sig[apex], np.broadcast_to(a * np.eye(3), sig[apex].shape), rtol=1e-12)
    np.testing.assert_allclose(de[apex], trial.q[apex] / (2.0 * mat.G), rtol=1e-15)
    np.testing.assert_allclose(q[cone], mat.M * (p[cone] + a), rtol=1e-9)
    np.testing.assert_allclose(q[cone], trial.q[cone] - 2.0 * mat.G * de[cone], rtol=1e-9, atol=1e-9 * a)
    np.testing.assert_allclose(
        p[cone] - trial.p[cone], (2.0 / 3.0) * mat.K * mat.M_g * de[cone], rtol=1e-9, atol=1e-9 * a
    )
    assert np.all(q <= mat.M * (p + a) * (1 + 1e-12) + 1e-9 * a)
    assert np.all(new["eps_p"] >= 0.0) and np.all(new["eps_p"][de == 0] == 0.0)
    # The state keeps the conventional measure, 2/3 de; at the apex q_trial / 3G.
    np.testing.assert_allclose(new["eps_p"], (2.0 / 3.0) * de, rtol=1e-15)
    np.testing.assert_allclose(new["eps_p"][apex], trial.q[apex] / (3.0 * mat.G), rtol=1e-15)


@pytest.mark.parametrize("psi", PSI)
def test_tangent_matches_finite_differences_at_and_near_the_apex(psi):
    mat = material(psi)
    sigma, deps = around_apex(mat)
    _, D, _ = step(mat, sigma, deps)
    h = 1e-10
    D_fd = np.empty_like(D)
    for k in range(6):
        e = np.zeros(6)
        e[k] = h
        D_fd[:, :, k] = (
            to_mandel(step(mat, sigma, deps + e)[0]) - to_mandel(step(mat, sigma, deps - e)[0])
        ) / (2 * h)
    # Points within a finite-difference step of a boundary (elastic/cone/apex) have one-sided tangents.
    regime = [_regime(mat, sigma, deps + s) for s in (-1e-8, 0.0, 1e-8)]
    smooth = (regime[0] == regime[1]) & (regime[1] == regime[2])
    apex = regime[1] == 2
    assert smooth.sum() > 0.9 * len(sigma) and (smooth & apex).sum() > 20
    np.testing.assert_allclose(D[smooth], D_fd[smooth], atol=1e-6 * (3 * mat.K + 2 * mat.G))
    assert np.all(D[apex] == 0.0)
    near = smooth & (regime[1] == 1) & (invariants(step(mat, sigma, deps)[0])[1] < 0.05 * mat.tension_limit)
    assert near.sum() > 0  # cone points next to the apex are in the check


def _regime(mat, sigma, deps):
    """0 elastic, 1 cone, 2 apex."""
    trial = mat.trial(sigma, from_mandel(deps), 1.0)
    return np.where(mat.at_apex(trial), 2, np.where(mat.increment(trial, {}, 1.0) > 0.0, 1, 0))


def test_isochoric_flow_is_the_rate_independent_paper_model_with_slope_m():
    """psi = 0 is DruckerPragerViscoplastic(gamma=inf) with the friction angle whose m equals M and
    the cohesion that keeps the apex: same stresses and tangents, apex included."""
    mat = material(0.0)
    m = mat.M  # m(phi') = 18 s / (9 - s^2) = M  =>  M s^2 + 18 s - 9 M = 0
    s = (-18.0 + np.sqrt(324.0 + 36.0 * m * m)) / (2.0 * m)
    phi_p = np.degrees(np.arcsin(s))
    paper = DruckerPragerViscoplastic(
        **ELASTIC, phi=phi_p, gamma=np.inf, c=mat.tension_limit * np.tan(np.radians(phi_p))
    )
    assert paper.m == pytest.approx(mat.M, rel=1e-14)
    sigma, deps = around_apex(mat)
    sig, D, _ = step(mat, sigma, deps)
    state_p = {k: np.zeros(len(sigma)) for k in paper.state_fields()}
    sig_p, D_p, _ = paper.small_strain_update(sigma, from_mandel(deps), state_p)
    scale = mat.tension_limit
    np.testing.assert_allclose(sig, sig_p, atol=1e-9 * scale)
    np.testing.assert_allclose(D, D_p, atol=1e-9 * (3 * mat.K + 2 * mat.G))


@pytest.mark.parametrize(
    "kwargs, name",
    [({"phi": 0.0}, "phi"), ({"phi": 30.0, "c": -1.0}, "c"), ({"phi": 30.0, "psi": 31.0}, "psi"),
     ({"phi": 30.0, "psi": -1.0}, "psi")],
)  # fmt: skip
def test_bad_parameters(kwargs, name):
    with pytest.raises(ValueError, match=rf"^{name} must be in"):
        MohrCoulombDruckerPrager(**ELASTIC, **kwargs)


def plane_strain_flow_tangent(mat, m, M_g, p=5e4):
    """Consistent tangent (plane components xx, yy, sqrt2 xy) of a small step of plane-strain flow
    from a point on the cone ``q = m (p + c cot phi)`` whose flow has ``de_zz^p = 0``."""
    a = mat.tension_limit
    q = m * (p + a)
    d = -M_g * q / 3.0  # s_zz = 2 d / 3 = -(2/9) M_g q makes dg/dsigma_zz vanish
    t = np.sqrt(q * q / 3.0 - d * d / 3.0)
    sigma = np.diag([t - d / 3.0 - p, -t - d / 3.0 - p, 2.0 * d / 3.0 - p])[None]
    assert invariants(sigma)[1][0] == pytest.approx(q, rel=1e-12)
    deps = np.zeros((1, 6))
    deps[0, [0, 1]] = 1e-9 * np.array([1.0, -1.0])  # loading: shear in the flow's own axes
    trial = mat.trial(sigma, from_mandel(deps), 1.0)
    inc = mat.increment(trial, {}, 1.0)
    D = mat.tangent(trial, inc, 1.0)
    assert 0.0 < inc[0] and not mat.at_apex(trial)[0]  # a plastic step on the cone
    return D[0][np.ix_([0, 1, 5], [0, 1, 5])]


def uniqueness_and_ellipticity(D, G):
    """Min eigenvalue of sym(D) / G and min over directions of det(acoustic tensor) / G^2."""
    second_order_work = np.linalg.eigvalsh(0.5 * (D + D.T)).min() / G
    dets = []
    for angle in np.linspace(0.0, np.pi, 721):
        n1, n2 = np.cos(angle), np.sin(angle)
        # Mandel plane strain of grad u = v x n is N v
        N = np.array([[n1, 0.0], [0.0, n2], [n2 / np.sqrt(2), n1 / np.sqrt(2)]])
        dets.append(np.linalg.det(N.T @ D @ N))
    return second_order_work, min(dets) / G**2


def test_non_associated_flow_loses_uniqueness_and_ellipticity_the_associated_cone_does_not():
    """Why Newton cannot find a collapse load with g = q: a flowing point's tangent has an
    indefinite symmetric part (negative second-order work) and a negative acoustic determinant
    (a band can form) in plane strain; with associated flow both are zero at worst."""
    associated, isochoric = material(None), material(0.0)
    paper = DruckerPragerViscoplastic(**ELASTIC, phi=30.0, gamma=np.inf, c=10e3)
    G = associated.G
    D = plane_strain_flow_tangent(associated, associated.M, associated.M_g)
    w, det = uniqueness_and_ellipticity(D, G)
    assert w > -1e-6 and det > -1e-6
    w, det = uniqueness_and_ellipticity(plane_strain_flow_tangent(isochoric, isochoric.M, 0.0), G)
    assert w < -0.2 and det < -0.1
    w, det = uniqueness_and_ellipticity(plane_strain_flow_tangent(paper, paper.m, 0.0), G)
    assert w < -0.3 and det < -0.15


def test_mpm_update_is_the_small_strain_step_without_spin():
    mat = material(12.0)
    sigma, deps = around_apex(mat)
    dt = 1e-3
    state = {"eps_p": np.full(len(sigma), 0.01)}
    sig_fe, _, new = mat.small_strain_update(sigma, from_mandel(deps), state)
    sig = mat.update(sigma, from_mandel(deps) / dt, dt, state)
    np.testing.assert_allclose(sig, sig_fe, rtol=1e-12, atol=1e-9 * mat.tension_limit)
    np.testing.assert_allclose(state["eps_p"], new["eps_p"], rtol=1e-12)
    assert np.any(new["eps_p"] > 0.01)
