"""Filling a region with material points, k per cell, with mass and volume from the density."""

from collections.abc import Callable

import numpy as np

from dolfin_mpm.core import compat
from dolfin_mpm.core.grid import Grid
from dolfin_mpm.core.locate import locate
from dolfin_mpm.core.particles import Particles
from dolfin_mpm.materials.base import Material

__all__ = ["geostatic_stress", "reference_points", "seed"]


def reference_points(tdim: int, ppc: int) -> np.ndarray:
    """Equal-volume particle positions in the reference simplex, ``shape=(ppc, tdim)``.

    Triangles take ``ppc = n^2``: the centroids of the ``n``-fold uniform subdivision.
    Tetrahedra take ``ppc = 8^l`` or ``4 * 8^l``: ``l`` uniform (Bey) refinements, then the
    centroid or the four points of the degree-2 equal-weight rule in each child. Each point
    stands for ``1/ppc`` of the cell, and the set integrates linear functions exactly.
    """
    if tdim == 2:
        n = round(np.sqrt(ppc))
        if ppc < 1 or n * n != ppc:
            raise ValueError(f"ppc must be a square number (1, 4, 9, ...) on triangles, got {ppc}")
        i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
        up = (i + j <= n - 1).ravel()
        down = (i + j <= n - 2).ravel()
        i, j = i.ravel(), j.ravel()
        pts = [np.c_[3 * i[up] + 1, 3 * j[up] + 1], np.c_[3 * i[down] + 2, 3 * j[down] + 2]]
        return np.concatenate(pts) / (3.0 * n)
    if tdim == 3:
        level, inner = 0, ppc
        while inner > 4 and inner % 8 == 0:
            inner //= 8
            level += 1
        if ppc < 1 or inner not in (1, 4):
            raise ValueError(f"ppc must be 8^l or 4*8^l (1, 4, 8, 32, 64, ...) on tetrahedra, got {ppc}")
        tets = np.array([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]])
        for _ in range(level):
            tets = _bey_refine(tets)
        if inner == 1:
            lam = np.full((1, 4), 0.25)
        else:
            a, b = 0.5854101966249685, 0.1381966011250105
            lam = np.full((4, 4), b) + np.eye(4) * (a - b)
        return np.einsum("qv,tvd->tqd", lam, tets).reshape(-1, 3)
    raise ValueError(f"tdim must be 2 or 3, got {tdim}")


def _bey_refine(tets: np.ndarray) -> np.ndarray:
    """Split each tetrahedron (``(t, 4, 3)``) into 8 of equal volume."""
    x0, x1, x2, x3 = (tets[:, i] for i in range(4))
    m01, m02, m03 = (x0 + x1) / 2, (x0 + x2) / 2, (x0 + x3) / 2
    m12, m13, m23 = (x1 + x2) / 2, (x1 + x3) / 2, (x2 + x3) / 2
    children = [
        (x0, m01, m02, m03), (m01, x1, m12, m13), (m02, m12, x2, m23), (m03, m13, m23, x3),
        (m01, m02, m03, m13), (m01, m02, m12, m13), (m02, m03, m13, m23), (m02, m12, m13, m23),
    ]  # fmt: skip
    return np.stack([np.stack(c, axis=1) for c in children], axis=1).reshape(-1, 4, 3)


def seed(
    grid: Grid,
    material: Material,
    ppc: int = 4,
    where: Callable[[np.ndarray], np.ndarray] | None = None,
    body=None,
    material_index: int = 0,
    velocity=None,
    cells: np.ndarray | None = None,
) -> Particles:
    """Material points filling a body, ``ppc`` per cell, mass ``rho * volume``.

    Args:
        grid: background grid the particles must lie in.
        material: supplies the density and the names of the state arrays.
        ppc: particles per cell (see :func:`reference_points` for allowed values).
        where: keep particles whose position satisfies ``where(x)``, ``x.shape=(3, n)``.
        body: a separate DOLFINx mesh of the body to fill; default: the grid's own mesh.
        material_index: index of ``material`` in the solver's material list.
        velocity: initial velocity [m/s], ``shape=(gdim,)``.
        cells: seed only these of the body mesh's owned cells, a mask ``shape=(num_owned_cells,)``
            (a physical group of a mesh file, say); with ``where``, both must hold.

    Raises:
        ValueError: bad ``ppc``, or particles outside the grid.

    """
    if not isinstance(ppc, (int, np.integer)) or ppc < 1:
        raise ValueError(f"ppc must be an integer >= 1, got {ppc!r}")
    msh = grid.mesh if body is None else body
    tdim, gdim = msh.topology.dim, msh.geometry.dim
    if gdim != grid.gdim:
        raise ValueError(f"body: geometric dimension {gdim} differs from the grid's {grid.gdim}")
    ref = reference_points(tdim, ppc)
    num_owned = msh.topology.index_map(tdim).size_local
    X = msh.geometry.x[compat.geometry_dofmap(msh)[:num_owned]]  # (cells, tdim+1, 3)
    J = X[:, 1:, :] - X[:, :1, :]  # rows: edge vectors
    x = (X[:, None, 0, :] + np.einsum("qk,ckd->cqd", ref, J)).reshape(-1, 3)
    if gdim == 2:
        cell_volume = 0.5 * np.abs(np.linalg.det(J[:, :, :2]))
    else:
        cell_volume = np.abs(np.linalg.det(J)) / 6.0
    volume = np.repeat(cell_volume / ppc, ppc)
    keep = np.ones(len(x), dtype=bool)
    if cells is not None:
        if np.shape(cells) != (num_owned,):
            raise ValueError(f"cells: a mask of the {num_owned} owned cells, got shape {np.shape(cells)}")
        keep = np.repeat(np.asarray(cells, dtype=bool), len(ref))
    if where is not None:
        keep &= np.asarray(where(x.T), dtype=bool)
    if cells is not None or where is not None:
        x, volume = x[keep], volume[keep]

    cells, _ = locate(grid, x, np.full(x.shape[0], -1, dtype=np.int32))
    outside = np.flatnonzero(cells < 0)
    if outside.size:
        raise ValueError(
            f"body: {outside.size} particles seeded outside the grid, first at x = {x[outside[0]]}"
        )
    n = x.shape[0]
    v = np.zeros((n, gdim)) if velocity is None else np.tile(np.asarray(velocity, float), (n, 1))
    particles = Particles(x, v, material.rho * volume, volume, material=np.full(n, material_index))
    particles.ensure_state(material.state_fields())
    particles.cell = cells
    return particles


def geostatic_stress(
    x: np.ndarray, rho: float, g: float, surface: float, K0: float, gdim: int = 2
) -> np.ndarray:
    """At-rest stress of a layer under gravity along the last axis (y in 2D, z in 3D).

    ``sigma_v = -rho g (surface - x_v)`` vertically and ``K0 sigma_v`` across (and out of
    plane in 2D), compression negative.

    Args:
        x: positions [m], ``shape=(n, 3)``.
        rho: density [kg/m^3]; g: gravity [m/s^2]; surface: height of the free surface [m].
        K0: at-rest earth pressure ratio (``nu / (1 - nu)`` for an elastic layer).
        gdim: geometric dimension (2 or 3).

    Returns:
        The stress [Pa], ``shape=(n, 3, 3)``.

    """
    vertical = gdim - 1
    sigma_v = -rho * g * (surface - x[:, vertical])
    sigma = np.zeros((x.shape[0], 3, 3))
    for i in range(3):
        sigma[:, i, i] = sigma_v if i == vertical else K0 * sigma_v
    return sigma
