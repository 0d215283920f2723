"""The figures of a run (PNG, headless): particles coloured by a field, energy and discharge curves."""

from pathlib import Path

import numpy as np

from dolfin_mpm.materials.tensor import invariants
from dolfin_mpm.post.plotting import figure

__all__ = ["field_values", "plot_curves", "plot_particles"]


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


def plot_particles(path: Path, x: np.ndarray, values: np.ndarray, field: str, t: float, bounds) -> None:
    """Particles at time ``t`` [s] coloured by ``values`` (x–y plane; 3D runs are projected).

    Args:
        x: positions [m], ``shape=(n, 3)``; values: ``shape=(n,)``.
        bounds: ``(lower, upper)`` corners of the grid [m], fixing the axes between frames.

    """
    lo, hi = np.asarray(bounds[0]), np.asarray(bounds[1])
    aspect = (hi[1] - lo[1]) / max(hi[0] - lo[0], 1e-300)
    width = 6.0
    height = min(max(width * aspect, 2.0), 9.0) + 0.8
    with figure(path, figsize=(width + 1.2, height)) as ax:
        size = max(0.5, min(20.0, 3e4 / max(len(x), 1)))
        sc = ax.scatter(x[:, 0], x[:, 1], c=values, s=size, cmap="viridis", linewidths=0)
        ax.figure.colorbar(sc, ax=ax, label=field)
        ax.set(
            xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), xlabel="x [m]", ylabel="y [m]", title=f"t = {t:.4g} s"
        )
        ax.set_aspect("equal")


def plot_curves(folder: Path, history: dict[str, np.ndarray], mass_unit: str, energy_unit: str) -> list[Path]:
    """Curves against time in ``folder``; returns the files written.

    ``energy.png``: kinetic, strain, potential change and total change; ``discharge.png`` (when
    anything was discharged): the mass in the sinks.
    """
    t = history["t"]
    written = [folder / "energy.png"]
    with figure(written[0], figsize=(6.5, 4)) as ax:
        ax.plot(t, history["kinetic"], label="kinetic")
        ax.plot(t, history["strain"], label="strain")
        ax.plot(t, history["potential"] - history["potential"][0], label="potential - initial")
        ax.plot(t, history["total"] - history["total"][0], "k--", label="total - initial")
        ax.set(xlabel="t [s]", ylabel=f"energy [{energy_unit}]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    if np.any(history["discharged"] > 0.0):
        written.append(folder / "discharge.png")
        with figure(written[1], figsize=(6.5, 4)) as ax:
            ax.plot(t, history["discharged"])
            ax.set(xlabel="t [s]", ylabel=f"discharged mass [{mass_unit}]")
            ax.grid(alpha=0.3)
    return written
