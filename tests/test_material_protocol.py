"""One protocol for every material: trial -> increment -> stress -> record, one meaning of de."""

import subprocess
import sys

import numpy as np
import pytest

from dolfin_mpm.materials import (
    DruckerPragerViscoplastic,
    LinearElastic,
    Material,
    MohrCoulombDruckerPrager,
    RadialReturn,
    VonMises,
)
from dolfin_mpm.materials.tensor import from_mandel, invariants, particle_first

ELASTIC = {"E": 10e6, "nu": 0.3, "rho": 2000.0}
MATERIALS = {
    "elastic": LinearElastic(**ELASTIC),
    "DP Perzyna N=1": DruckerPragerViscoplastic(**ELASTIC, phi=30.0, gamma=0.05),
    "DP Perzyna N=0.7, cohesive": DruckerPragerViscoplastic(**ELASTIC, phi=30.0, gamma=0.05, N=0.7, c=10e3),
    "DP rate-independent": DruckerPragerViscoplastic(**ELASTIC, phi=30.0, gamma=np.inf),
    "von Mises, hardening": VonMises(**ELASTIC, sigma_y=30e3, H=2e6),
    "MC-DP associated": MohrCoulombDruckerPrager(**ELASTIC, phi=30.0, c=10e3),
    "MC-DP isochoric": MohrCoulombDruckerPrager(**ELASTIC, phi=30.0, c=10e3, psi=0.0),
    "MC-DP psi=12": MohrCoulombDruckerPrager(**ELASTIC, phi=30.0, c=10e3, psi=12.0),
}
PLASTIC = [name for name, mat in MATERIALS.items() if mat.plastic]
DT = 1e-3


def sample(mat, n=600, seed=5):
    """Stresses from tension beyond the apex to deep compression, velocity gradients (2D and 3D
    halves) over ``DT`` and a state with something accumulated."""
    rng = np.random.default_rng(seed)
    sigma = from_mandel(rng.normal(0.0, 20e3, (n, 6)))
    sigma -= rng.uniform(-30e3, 60e3, n)[:, None, None] * np.eye(3)
    L = rng.normal(0.0, 2e-3 / DT, (n, 3, 3))
    L[: n // 2, 2, :] = L[: n // 2, :, 2] = 0.0  # plane strain
    state = {k: rng.uniform(0.0, 0.02, n) for k in mat.state_fields()}
    return sigma, L, state


def copy(state):
    return {k: v.copy() for k, v in state.items()}


def parts(mat, sigma, L, dt, state):
    """The four parts in order, on a copy of ``state``: stress, increment, trial, new state."""
    state = copy(state)
    trial = mat.trial(sigma, L, dt)
    de = mat.increment(trial, state, dt)
    new_sigma = mat.stress(trial, de)
    mat.record(state, de, None, dt)
    return new_sigma, de, trial, state


@pytest.mark.parametrize("name", MATERIALS)
def test_update_is_the_four_parts(name):
    mat = MATERIALS[name]
    assert isinstance(mat, Material)
    sigma, L, state = sample(mat)
    ref_sigma, de, _, ref_state = parts(mat, sigma, L, DT, state)
    new_state = copy(state)
    assert np.array_equal(mat.update(sigma, L, DT, new_state), ref_sigma)
    assert new_state.keys() == ref_state.keys() == mat.state_fields().keys()
    for k in new_state:
        assert np.array_equal(new_state[k], ref_state[k]), k
    # A non-local increment equal to the local one changes nothing, in the stress nor the state.
    # (A trial gives one stress: each call takes a fresh one.)
    assert np.array_equal(mat.stress(mat.trial(sigma, L, DT), de, de), ref_sigma)
    assert np.array_equal(mat.stress(mat.trial(sigma, L, DT), de), ref_sigma)
    twice = copy(state)
    mat.record(twice, de, de, DT)
    for k in twice:
        assert np.array_equal(twice[k], ref_state[k]), k


@pytest.mark.parametrize("name", MATERIALS)
def test_small_strain_update_is_the_four_parts_and_the_tangent(name):
    mat = MATERIALS[name]
    sigma, L, state = sample(mat, seed=6)
    deps = L * DT
    before = copy(state)
    sig, D, new = mat.small_strain_update(sigma, deps, state, dt=DT)
    ref_sigma, de, trial, ref_state = parts(mat, sigma, deps / DT, DT, state)
    assert np.array_equal(sig, ref_sigma)
    assert np.array_equal(D, mat.tangent(trial, de, DT)) and D.shape == (len(sigma), 6, 6)
    for k in state:
        assert np.array_equal(new[k], ref_state[k]) and np.array_equal(state[k], before[k]), k


@pytest.mark.parametrize("name", PLASTIC)
def test_one_meaning_of_the_increment(name):
    """de is the paper's norm sqrt(3/2 de_p:de_p) of the deviatoric plastic strain, so that
    q = q_trial - 2 G de; q_trial / 2G at an apex."""
    mat = MATERIALS[name]
    assert isinstance(mat, RadialReturn)
    sigma, L, state = sample(mat)
    sig, de, trial, new = parts(mat, sigma, L, DT, state)
    assert de.shape == (len(sigma),)
    assert np.all(np.isfinite(de)) and np.all(de >= 0.0)
    apex = mat.at_apex(trial) if hasattr(mat, "at_apex") else np.zeros(len(de), dtype=bool)
    assert apex.dtype == bool and apex.shape == de.shape
    plastic = (de > 0.0) & ~apex
    assert plastic.sum() > 20 and (de == 0.0).sum() > 20
    if hasattr(mat, "at_apex"):
        assert apex.sum() > 20
        np.testing.assert_allclose(de[apex], trial.q[apex] / (2.0 * mat.G), rtol=1e-14)
    scale = np.abs(sigma).max()
    q = invariants(sig)[1]
    np.testing.assert_allclose(
        q[~apex], trial.q[~apex] - 2.0 * mat.G * de[~apex], rtol=1e-10, atol=1e-12 * scale
    )
    assert np.all(q[apex] == 0.0)
    # The deviatoric plastic strain itself: s_trial - s = 2 G de_p (the elastic part of the
    # step is in the trial), everywhere, apex included.
    s_end = sig + (-np.trace(sig, axis1=1, axis2=2) / 3.0)[:, None, None] * np.eye(3)
    de_p = (particle_first(trial.s) - s_end) / (2.0 * mat.G)
    norm = np.sqrt(1.5 * (de_p * de_p).sum(axis=(1, 2)))
    np.testing.assert_allclose(norm, de, rtol=1e-9, atol=1e-12 * scale / mat.G)
    # The state accumulates it: the paper's norm (DP's eps_vp) or the conventional one,
    # sqrt(2/3 de_p:de_p) (eps_p of von Mises and the Mohr-Coulomb cone).
    k, factor = ("eps_vp", 1.0) if "eps_vp" in new else ("eps_p", 2.0 / 3.0)
    np.testing.assert_allclose(new[k] - state[k], factor * norm, rtol=1e-9, atol=1e-12 * scale / mat.G)
    # And it is the return's: the end state of the flowing points obeys the material's law.
    p = -np.trace(sig, axis1=1, axis2=2) / 3.0
    law, value = flow_law(mat, p[plastic], q[plastic], de[plastic], state, plastic)
    np.testing.assert_allclose(law, value, rtol=1e-9)


def flow_law(mat, p, q, de, state, where):
    """Both sides of the material's flow law at end states ``(p, q)`` with increments ``de``."""
    if isinstance(mat, VonMises):  # on the hardened surface, hardening in the conventional measure
        return q, mat.sigma_y + mat.H * (state["eps_p"][where] + (2.0 / 3.0) * de)
    y = (mat.M if isinstance(mat, MohrCoulombDruckerPrager) else mat.m) * (p + mat.tension_limit)
    if isinstance(mat, MohrCoulombDruckerPrager) or np.isinf(mat.gamma):  # on the cone
        return q, y
    return de, DT * 1.5 * mat.gamma * ((q - y) / y) ** mat.N  # Perzyna, backward Euler


@pytest.mark.parametrize("name", PLASTIC)
def test_the_larger_increment_applies_and_q_stays_non_negative(name):
    mat = MATERIALS[name]
    sigma, L, state = sample(mat, seed=8)
    trial = mat.trial(sigma, L, DT)
    de = mat.increment(trial, state, DT)
    rng = np.random.default_rng(9)
    de_bar = rng.uniform(0.0, 2.0, len(de)) * trial.q / (2.0 * mat.G)  # up to twice what q_trial allows
    q = invariants(mat.stress(trial, de, de_bar))[1]
    expected = np.maximum(trial.q - 2.0 * mat.G * np.maximum(de, de_bar), 0.0)
    np.testing.assert_allclose(q, expected, rtol=1e-10, atol=1e-9 * np.abs(sigma).max())
    assert np.all(q >= 0.0)


@pytest.mark.parametrize("name", ["MC-DP associated", "MC-DP psi=12"])
def test_dilatant_pressure_moves_with_the_applied_increment(name):
    mat = MATERIALS[name]
    sigma, L, state = sample(mat, seed=10)
    trial = mat.trial(sigma, L, DT)
    de = mat.increment(trial, state, DT)
    de_bar = 0.5 * de[::-1]
    sig = mat.stress(trial, de, de_bar)
    p = -np.trace(sig, axis1=1, axis2=2) / 3.0
    apex = mat.at_apex(trial)
    d = np.minimum(np.maximum(de, de_bar), trial.q / (2.0 * mat.G))
    np.testing.assert_allclose(
        p[~apex], trial.p[~apex] + (2.0 / 3.0) * mat.K * mat.M_g * d[~apex], rtol=1e-12, atol=1e-9
    )
    np.testing.assert_allclose(p[apex], -mat.tension_limit, rtol=1e-12)


def test_elastic_increment_is_zero_and_its_tangent_the_stiffness():
    mat = MATERIALS["elastic"]
    sigma, L, _ = sample(mat)
    trial = mat.trial(sigma, L, DT)
    assert np.array_equal(mat.increment(trial, {}, DT), np.zeros(len(sigma)))
    D = mat.tangent(trial, np.zeros(len(sigma)), DT)
    plastic = MATERIALS["von Mises, hardening"]
    assert np.allclose(D, plastic.tangent(trial, np.zeros(len(sigma)), DT), rtol=1e-14, atol=1e-14 * mat.E)
    assert not mat.plastic


def test_materials_import_without_dolfinx_petsc_or_mpi():
    code = (
        "import sys; import dolfin_mpm; before = set(sys.modules)\n"
        "import dolfin_mpm.materials, dolfin_mpm.params\n"
        "heavy = ('dolfinx', 'petsc4py', 'mpi4py', 'ufl', 'basix')\n"
        "new = [m for m in set(sys.modules) - before if m.split('.')[0] in heavy]\n"
        # The PyPI wheels' loader (imported by the package, on purpose, before anything else)
        # orders mpi4py first; dolfinx and petsc4py must not be there at all.
        "allowed = ('mpi4py',) if 'dolfinx_solver' in sys.modules else ()\n"
        "new += [m for m in sys.modules if m.split('.')[0] in heavy and m.split('.')[0] not in allowed]\n"
        "print(sorted({m.split('.')[0] for m in new}))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout
