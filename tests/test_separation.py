"""Separation and re-compaction: a granular point below its critical density is apart, stress free,
and keeps its volume at m / rho_c; compressed again, it carries stress once its free volume closes."""

import numpy as np
import pytest
from conftest import rectangle

import dolfin_mpm as dm
from dolfin_mpm.materials.separation import separate

SAND = {"E": 1e6, "nu": 0.3, "rho": 1500.0, "phi": 30.0, "gamma": 1e3}


def test_free_volume_opens_beyond_the_critical_volume_and_closes_first():
    V, free = np.array([1.0, 1.0, 0.9]), np.zeros(3)
    V, free = separate(V, free, np.array([1.5, 0.8, 1.05]), 1.0)
    assert np.allclose(V, [1.0, 0.8, 0.945]) and np.allclose(free, [0.5, 0.0, 0.0])
    V, free = separate(V, free, np.array([0.8, 1.0, 1.0]), 1.0)  # 1.5 * 0.8 = 1.2: still apart
    assert np.isclose(V[0], 1.0) and np.isclose(free[0], 0.2)
    V, free = separate(V, free, np.array([0.5, 1.0, 1.0]), 1.0)  # 1.2 * 0.5 = 0.6: back in contact
    assert np.isclose(V[0], 0.6) and free[0] == 0.0


def spreading_block(rho_c, rate=5.0):
    """A block of sand in free flight, spreading at ``rate`` [1/s] in x: it is pulled apart."""
    grid = dm.Grid(rectangle((0, 0), (1, 1), (20, 20)))
    sand = dm.DruckerPragerViscoplastic(**SAND, rho_c=rho_c)
    P = dm.seed(grid, sand, ppc=4, where=lambda x: (abs(x[0] - 0.5) < 0.1) & (abs(x[1] - 0.5) < 0.1))
    P.v[:, 0] = rate * (P.x[:, 0] - 0.5)
    return dm.Solver(grid, P, sand, dt=2e-4, flip=1.0)


def test_a_point_pulled_apart_keeps_its_volume_and_carries_no_stress_until_it_touches_again():
    solver = spreading_block(rho_c=1400.0)
    P, V_c = solver.particles, solver.particles.mass / 1400.0
    total0 = P.volume.sum()
    for _ in range(100):  # 0.02 s at 5/s: about 10 % wider
        solver.step()
    apart = P.state["free_volume"] > 0.0
    apart_share = apart.mean()
    assert apart_share > 0.5 and np.all(P.volume <= V_c * (1 + 1e-15))
    assert np.all(P.sigma[apart] == 0.0)
    # Volume is not lost: material and free volume follow the motion (a tenth wider, uniformly).
    assert (P.volume + P.state["free_volume"]).sum() == pytest.approx(1.1 * total0, rel=0.02)
    P.v[:, 0] *= -1.0  # pushed back together
    touching, carried = [], []
    for _ in range(100):
        solver.step()
        apart = P.state["free_volume"] > 0.0
        assert np.all(P.sigma[apart] == 0.0) and np.all(P.volume <= V_c * (1 + 1e-15))
        touching.append((~apart).mean())
        carried.append(np.abs(P.sigma[~apart]).max() if np.any(~apart) else 0.0)
    # Points come back into contact as their free volume closes, and carry stress again: the
    # impact of sand at 0.25 m/s, rho c v ~ 10 kPa, not a spike.
    assert max(touching) > 1.0 - apart_share + 0.1
    assert 1e3 < max(carried) < 5e4


def test_without_a_critical_density_the_volume_follows_the_flow():
    solver = spreading_block(rho_c=None)
    P, V0 = solver.particles, solver.particles.volume.copy()
    for _ in range(100):
        solver.step()
    assert "free_volume" not in P.state and (P.volume / V0).max() > 1.05


@pytest.mark.parametrize("rho_c", [0.0, -1.0, 1600.0, np.inf, np.nan])
def test_bad_critical_density(rho_c):
    with pytest.raises(ValueError, match=r"^rho_c must be in \(0, "):
        dm.DruckerPragerViscoplastic(**SAND, rho_c=rho_c)
