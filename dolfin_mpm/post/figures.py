"""The figures of a run (PNG, headless): particles coloured by a field, energy and discharge curves."""

from pathlib import Path

import numpy as np

from dolfin_mpm.materials.tensor import invariants
from dolfin_mpm.post.plotting import figure

__all__ = ["field_unit", "field_values", "plot_curves", "plot_particles"]

#: The unit of each figure field (the names are those of the XDMF output); lengths, masses and
#: volumes per metre of depth in 2D.
_UNITS = {
    "speed": "m/s", "vx": "m/s", "vy": "m/s", "vz": "m/s", "p": "Pa", "q": "Pa", "eps_vp": "-",
    "eps_vp_rate": "1/s", "eps_vp_rate_nonlocal": "1/s", "nonlocal_correction": "-",
}  # fmt: skip


def field_unit(name: str, gdim: int) -> str:
    """The unit of the figure field ``name`` in a ``gdim``-dimensional run ("" if unknown)."""
    per_depth = {"mass": ("kg/m", "kg"), "volume": ("m²", "m³"), "free_volume": ("m²", "m³")}
    if name in per_depth:
        return per_depth[name][gdim - 2]
    return _UNITS.get(name, "")


def field_values(particles, name: str) -> np.ndarray:
    """A scalar per particle named ``name``, ``shape=(n,)``.

    ``speed``, ``p``, ``q``, ``mass``, ``volume``, a velocity component ``vx``/``vy``/``vz``,
    or a material state array.
    """
    P = particles
    if name == "speed":
        return np.linalg.norm(P.v, axis=1)
    if name in ("p", "q"):
        p, q = invariants(P.sigma)
        return p if name == "p" else q
    if name in ("mass", "volume"):
        return getattr(P, name)
    if name in ("vx", "vy", "vz"):
        return P.v[:, "xyz".index(name[1])]
    return P.state[name].reshape(len(P), -1)[:, 0] if name in P.state and len(P) else np.zeros(len(P))


def plot_particles(
    path: Path, x: np.ndarray, values: np.ndarray, field: str, t: float, bounds, unit: str = "", walls=()
) -> None:  # fmt: skip
    """Particles at time ``t`` [s] coloured by ``values`` (x–y plane; 3D runs are projected).

    Args:
        x: positions [m], ``shape=(n, 3)``; values: ``shape=(n,)``.
        bounds: ``(lower, upper)`` corners of the grid [m], fixing the axes between frames.
        unit: the unit of ``values`` for the colour bar.
        walls: segments ``shape=(2, 2)`` [m] drawn as walls (2D rigid walls where they are at ``t``).

    """
    lo, hi = np.asarray(bounds[0]), np.asarray(bounds[1])
    aspect = (hi[1] - lo[1]) / max(hi[0] - lo[0], 1e-300)
    width = 6.0
    height = min(max(width * aspect, 2.0), 9.0) + 0.8
    with figure(path, figsize=(width + 1.2, height)) as ax:
        size = max(0.5, min(20.0, 3e4 / max(len(x), 1)))
        sc = ax.scatter(x[:, 0], x[:, 1], c=values, s=size, cmap="viridis", linewidths=0)
        for segment in walls:
            ax.plot(segment[:, 0], segment[:, 1], "k-", lw=1.5)
        ax.figure.colorbar(sc, ax=ax, label=f"{field} [{unit}]" if unit else field)
        ax.set(
            xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), xlabel="x [m]", ylabel="y [m]",
            title=f"{field}, t = {t:.4g} s",
        )  # fmt: skip
        ax.set_aspect("equal")


def plot_curves(folder: Path, history: dict[str, np.ndarray], mass_unit: str, energy_unit: str) -> list[Path]:
    """Curves against time in ``folder``; returns the files written.

    ``energy.png``: the balance since the first row, ``kinetic + strain + (potential - initial)
    + dissipated + sunk + other = initial kinetic + strain``: the particles' energies, the strain
    energy the stress updates released (plastic dissipation), the energy carried into sinks and
    the rest, ``other``: the work of the walls and the damping and what the transfers lose.
    ``discharge.png`` (when anything was discharged): the mass in the sinks.
    """
    t = history["t"]
    written = [folder / "energy.png"]
    d, sunk = (history[k] - history[k][0] for k in ("dissipated", "sunk"))
    other = -(history["total"] - history["total"][0]) - d - sunk
    with figure(written[0], figsize=(6.5, 4)) as ax:
        ax.plot(t, history["kinetic"], label="kinetic")
        ax.plot(t, history["strain"], label="strain")
        ax.plot(t, history["potential"] - history["potential"][0], label="potential - initial")
        ax.plot(t, d, label="dissipated: plastic work")
        if np.any(sunk != 0.0):
            ax.plot(t, sunk, label="sunk (carried into sinks)")
        ax.plot(t, other, "k--", label="other: walls, damping, transfers")
        ax.set(
            xlabel="t [s]",
            ylabel=f"energy [{energy_unit}]",
            title="energy balance: the curves add up to the initial kinetic + strain",
        )
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    if np.any(history["discharged"] > 0.0):
        written.append(folder / "discharge.png")
        with figure(written[1], figsize=(6.5, 4)) as ax:
            ax.plot(t, history["discharged"])
            ax.set(xlabel="t [s]", ylabel=f"discharged mass [{mass_unit}]")
            ax.grid(alpha=0.3)
    return written
