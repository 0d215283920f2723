"""Rigid walls as geometry: where they act, their friction, their impenetrability, bad input."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest
from conftest import rectangle

import dolfin_mpm as dm
from dolfin_mpm.core.walls import stop_at_walls

G = 9.81


@pytest.mark.parametrize(
    "segment, mu, match",
    [
        ([(0.0, 0.0), (0.0, 0.0)], 0.0, r"^floor: segment is degenerate"),
        ([(0.0, 0.0), (np.nan, 1.0)], 0.0, r"^floor: points must be a segment .* of finite coordinates"),
        (
            [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0)],
            0.0,
            r"^floor: a wall in 2D is a segment of two points, got 3",
        ),
        ([(0.0, 0.0, 0.0), (1.0, 0.0, 0.0)], 0.0, r"^floor: a wall in 3D is a facet of three or more points"),
        (
            [(0, 0, 0), (1, 0, 0), (2, 0, 0)],
            0.0,
            r"^floor: facet is degenerate \(no area: its points on a line",
        ),
        (
            [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0.01)],
            0.0,
            r"^floor: facet is not flat: point .* lies 0.0025 m off the plane",
        ),
        (
            [(0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0)],
            0.0,
            r"^floor: facet is degenerate .* not in order round",
        ),
        (
            [(0, 0, 0), (2, 0, 0), (1, 0.5, 0), (1, 2, 0)],
            0.0,
            r"^floor: facet is not convex, or its points are not",
        ),
        (
            [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 0, 0)],
            0.0,
            r"^floor: facet is degenerate \(its corners 3 and 0 coincide",
        ),
        ([(0, 0, 0), (1, 0, 0), (1, 1, 0)], 0.0, None),  # a triangle is a facet
        ([(0.0, 0.0), (1.0, 0.0)], -0.1, r"^floor: mu must be in \[0, inf\], got -0.1"),
        ([(0.0, 0.0), (1.0, 0.0)], np.nan, r"^floor: mu must be in \[0, inf\], got nan"),
    ],
)
def test_bad_wall_is_named(segment, mu, match):
    if match is None:
        assert np.allclose(dm.RigidWall(segment, mu, "floor").normal, [0.0, 0.0, -1.0])  # away from z > 0
        return
    with pytest.raises(ValueError, match=match):
        dm.RigidWall(segment, mu, "floor")


def test_wall_outside_the_mesh_or_with_material_behind_it_is_refused():
    grid = dm.Grid(rectangle((0, 0), (1, 1), (4, 4)))
    mat = dm.LinearElastic(E=1e4, nu=0.3, rho=1000.0)
    P = dm.seed(grid, mat, ppc=1, where=lambda x: x[1] < 0.5)
    with pytest.raises(ValueError, match=r"^floor: segment point \[1.5, 0.0\] lies outside the mesh"):
        dm.Solver(grid, P, mat, bcs=[dm.RigidWall([(0.0, 0.0), (1.5, 0.0)], name="floor")])
    # Walked the wrong way, the floor has the material behind it.
    with pytest.raises(ValueError, match=r"^floor: \d+ particles start behind the wall .* on the left of"):
        dm.Solver(grid, P, mat, bcs=[dm.RigidWall([(1.0, 0.0), (0.0, 0.0)], name="floor")])


@pytest.mark.parametrize(
    "x_e, diagonal", [(0.5, "right"), (0.53, "right"), (0.5, "crossed"), (0.515, "crossed")]
)
def test_a_plate_carries_the_weight_over_it_wherever_its_edge_falls(x_e, diagonal):
    """An elastic layer at rest on two plates that meet at x_e, on a node or between nodes.

    Each plate carries the weight of the material over it, to within the particles' spacing:
    the wall ends where its geometry ends (a wall of nodes would end at the nodes, up to h/2 off).
    """
    h, thickness = 0.05, 0.1
    grid = dm.Grid(rectangle((0, -0.1), (1, 0.2), (20, 6), diagonal))
    mat = dm.LinearElastic(E=1e6, nu=0.3, rho=1000.0)
    P = dm.seed(grid, mat, ppc=4, where=lambda x: (x[1] > 0) & (x[1] < thickness))
    P.sigma = dm.geostatic_stress(P.x, mat.rho, G, thickness, 0.3 / 0.7)
    left, right = (
        dm.RigidWall([(0, 0), (x_e, 0)], name="left"),
        dm.RigidWall([(x_e, 0), (1, 0)], name="right"),
    )
    sides = dm.SlipBC(
        grid.nodes_where(lambda x: np.isclose(x[0], 0.0) | np.isclose(x[0], 1.0)), normal=(1, 0)
    )
    solver = dm.Solver(grid, P, mat, bcs=[left, right, sides], gravity=(0, -G), damping=0.3)
    solver.run(0.1, progress=False)

    carried = [solver.reaction(wall)[1] for wall in (left, right)]  # the plates' forces on the layer
    weight = solver.total_mass() * G
    assert sum(carried) == pytest.approx(weight, rel=1e-3)  # at rest: the plates carry it all
    spacing = h / 3  # of the particles' columns: 4 per triangle
    assert abs(carried[0] / weight - x_e) < spacing
    assert abs(carried[1] / weight - (1 - x_e)) < spacing


@pytest.mark.parametrize("diagonal", ["right", "crossed"])
def test_block_sliding_down_an_inclined_wall_decelerates_at_g_sin_minus_mu_cos(diagonal):
    """A wall at 17 degrees on a structured mesh: no mesh line follows it."""
    theta, mu = np.radians(17.0), 0.5
    grid = dm.Grid(rectangle((0, 0), (1.0, 0.6), (40, 24), diagonal))
    a = np.array([0.0, 0.45])
    down, up = np.array([np.cos(theta), -np.sin(theta)]), np.array([np.sin(theta), np.cos(theta)])
    slope = dm.RigidWall([a, a + down / np.cos(theta)], mu=mu, name="slope")
    mat = dm.LinearElastic(E=1e6, nu=0.3, rho=1000.0)
    thickness = 0.08

    def local(x):  # along and across the slope, x.shape=(3, n)
        d = x[:2].T - a
        return d @ down, d @ up

    def block(x):
        s, t = local(x)
        return (s > 0.1) & (s < 0.35) & (t > 0) & (t < thickness)

    P = dm.seed(grid, mat, ppc=4, where=block, velocity=tuple(down))  # 1 m/s down the slope
    t = local(P.x.T)[1]
    P.sigma[:, :2, :2] = (-mat.rho * G * np.cos(theta) * (thickness - t))[:, None, None] * np.outer(up, up)
    solver = dm.Solver(grid, P, mat, bcs=[slope], gravity=(0, -G), flip=0.0)
    m = solver.total_mass()
    times, speeds = [], []
    while solver.time < 0.2:
        solver.step()
        times.append(solver.time)
        speeds.append(solver.total_momentum() @ down / m)
    times, speeds = np.array(times), np.array(speeds)
    late = times > 0.02  # after the first contact waves
    deceleration = np.polyfit(times[late], speeds[late], 1)[0]
    assert deceleration == pytest.approx(G * (np.sin(theta) - mu * np.cos(theta)), rel=0.01)
    assert solver.comm.allreduce(solver.state.wall_stops) == 0  # the grid alone held the block


def test_a_move_across_a_wall_stops_on_it_and_a_move_past_its_end_does_not():
    wall = dm.RigidWall([(0.0, 0.0), (1.0, 0.0)], name="floor")
    x = np.array([[0.5, 0.01, 0.0], [1.2, 0.01, 0.0], [0.5, 0.5, 0.0]])
    dx = np.array([[0.1, -0.03], [0.0, -0.03], [0.0, -0.03]])
    v = np.array([[1.0, -3.0], [0.0, -3.0], [0.0, -3.0]])
    assert stop_at_walls([wall], x, dx, v, time=0.0, dt=0.01) == 1
    assert np.allclose(dx[0], [0.1, -0.01]) and np.allclose(v[0], [1.0, 0.0])  # on the wall, sliding
    assert np.array_equal(dx[1:], [[0.0, -0.03], [0.0, -0.03]]) and np.array_equal(v[1:], [[0, -3], [0, -3]])


def test_no_particle_crosses_a_wall_of_the_silo():
    """The local silo at h = 10 mm to t = 0.25 s: no particle's move in any step crosses a wall."""
    spec = importlib.util.spec_from_file_location(
        "demo_silo", Path(__file__).parents[1] / "demos" / "demo_silo.py"
    )
    demo = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(demo)
    solver, gate = demo.build(h=0.01, radius=0.0)
    solver.time = -20 * solver.dt
    solver.run(0.0, progress=False)
    solver.bcs = [bc for bc in solver.bcs if bc is not gate]
    walls, crossings = solver.bcs, []

    class Moves:  # each step's moves, from the positions of the particles by id
        last = np.full((solver.num_particles(), 2), np.nan)

        def write(self, s):
            P = s.particles
            before = self.last[P.id]
            known = ~np.isnan(before[:, 0])
            x0, x1 = before[known], P.x[known, :2]
            count = 0
            for w in walls:
                phi0, phi1 = w.distance(x0), w.distance(x1)
                cross = (phi0 >= 0.0) & (phi1 < 0.0)
                at = x0[cross] + (phi0[cross] / (phi0[cross] - phi1[cross]))[:, None] * (x1 - x0)[cross]
                count += int(np.sum(w.over(at)))
            crossings.append(count)
            self.last[:] = np.nan
            self.last[P.id] = P.x[:, :2]

    solver.run(0.25, output=Moves(), output_interval=solver.dt, progress=False)
    assert len(crossings) > 2000 and solver.comm.allreduce(sum(crossings)) == 0
    assert solver.comm.allreduce(solver.sinks["discharged"].mass) > 10.0  # it flowed


# -- scenario files ------------------------------------------------------------------------------
SILO = Path(__file__).parents[1] / "demos" / "silo.toml"


@pytest.mark.parametrize(
    "override, match",
    [
        (
            "walls.bottom_left.segment=[[0.0, 0.0], [0.0, 0.0]]",
            r"walls.bottom_left.segment: segment is degenerate",
        ),
        ("walls.bottom_left.segment=[[0.0, 0.0]]", r"walls.bottom_left.segment: must be two points"),
        (
            "walls.bottom_left.segment=[[0.0, 0.0], [0.05, nan]]",
            r"walls.bottom_left.segment: points must be",
        ),
        (
            "walls.gate.type='velocity'",
            r"walls.gate.type: a wall given as a segment is 'slip' or 'frictional'",
        ),
        ("walls.gate.normal=[0.0, 1.0]", r"walls.gate.normal: unknown key"),
        ("walls.gate.friction_angle=90.0", r"walls.gate.friction_angle: must be in \[0, 90\) degrees"),
    ],
)
def test_scenario_rigid_wall_errors_name_their_path(override, match):
    from dolfin_mpm.app import scenario

    with pytest.raises(scenario.ScenarioError, match=match):
        scenario.load(SILO, [override])


@pytest.mark.parametrize(
    "override, match",
    [
        (
            "walls.left.segment=[[0.0, 0.5], [0.0, 0.0]]",
            r"walls.left.segment: segment point \[0.0, 0.5\] lies outside",
        ),
        (
            "walls.bottom_left.segment=[[0.05, 0.0], [0.0, 0.0]]",
            r"walls.bottom_left.segment: \d+ particles start behind",
        ),
    ],
)
def test_scenario_rigid_wall_errors_the_mesh_reveals_name_their_path(override, match):
    from dolfin_mpm.app import scenario

    with pytest.raises(scenario.ScenarioError, match=match):
        scenario.build(scenario.load(SILO, [override]))


def test_scenario_polygon_wall_is_a_chain_of_segments(tmp_path):
    from dolfin_mpm.app import scenario

    text = SILO.read_text()
    start, end = text.index("[walls.left]"), text.index("[walls.bottom_right]")
    polygon = '[walls.left]\ntype = "frictional"\npolygon = [[0.0, 0.31], [0.0, 0.0], [0.05, 0.0]]\n'
    (tmp_path / "s.toml").write_text(text[:start] + polygon + "friction_angle = 20.0\n\n" + text[end:])
    sim = scenario.build(scenario.load(tmp_path / "s.toml"))
    left = sim.walls["left"]
    assert [w.name for w in left] == ["walls.left.polygon"] * 2
    assert np.array_equal(left[1].points, [[0.0, 0.0], [0.05, 0.0]]) and left[1].mu == pytest.approx(
        np.tan(np.radians(20))
    )
    assert sum(isinstance(bc, dm.RigidWall) for bc in sim.solver.bcs) == 5


def test_a_rough_moving_wall_carries_the_block_on_it_at_its_speed():
    """A rough floor moving sideways at 0.5 m/s under a block at rest: the block sticks to it."""
    grid = dm.Grid(rectangle((0, 0), (1.0, 0.3), (40, 12)))
    mat = dm.LinearElastic(E=1e6, nu=0.3, rho=1000.0)
    P = dm.seed(grid, mat, ppc=4, where=lambda x: (x[0] > 0.2) & (x[0] < 0.4) & (x[1] > 0.1) & (x[1] < 0.15))
    floor = dm.RigidWall([(0.0, 0.1), (0.9, 0.1)], np.inf, "belt", velocity=(0.5, 0.0))
    solver = dm.Solver(grid, P, mat, bcs=[floor], gravity=(0, -G), flip=0.0)
    x0 = solver.comm.allreduce(float(P.x[:, 0].sum())) / solver.num_particles()
    solver.run(0.2, progress=False)
    m = solver.total_mass()
    v = solver.total_momentum() / m
    assert v[0] == pytest.approx(0.5, rel=0.01) and abs(v[1]) < 0.01
    x1 = solver.comm.allreduce(float(P.x[:, 0].sum())) / solver.num_particles()
    assert x1 - x0 == pytest.approx(0.5 * 0.2, rel=0.1)  # carried along (from rest: a short lag)
    # the belt holds the block up: its force, over the next steps, is the weight
    forces = []
    for _ in range(100):
        solver.step()
        forces.append(solver.reaction(floor))
    assert np.mean(forces, axis=0) == pytest.approx([0.0, m * G], rel=0.01, abs=0.01 * m * G)


def test_contact_applies_each_walls_share_of_the_coulomb_condition():
    """The compiled correction equals its definition: v + sum_w alpha_w (coulomb(v - u_w) + u_w - v)."""
    from dolfin_mpm.core.boundary import coulomb
    from dolfin_mpm.core.walls import Contact

    rng = np.random.default_rng(3)
    walls = [
        dm.RigidWall([(0.0, 0.0), (1.0, 0.0)], 0.3, "still"),
        dm.RigidWall([(1.0, 0.0), (2.0, 0.0)], np.inf, "rough, moving", velocity=(0.2, -0.1)),
    ]
    nodes = np.array([4, 0, 7, 2, 9])
    alpha = [rng.uniform(0.0, 1.0, len(nodes)) for _ in walls]
    contact = Contact(nodes, walls[0].normal, list(zip(walls, alpha)), np.ones(len(nodes)), owned=10)
    v = rng.normal(size=(10, 2))
    v[0] = (0.0, -0.1)  # straight into the walls: no tangential speed
    expected = v.copy()
    vi = v[nodes]
    changes = [
        a[:, None] * (coulomb(vi - w.velocity, w.normal, w.mu) + w.velocity - vi)
        for w, a in zip(walls, alpha)
    ]
    expected[nodes] = vi + sum(changes)
    contact.apply(v)
    assert np.allclose(v, expected, rtol=0.0, atol=1e-15)
    # Each wall's force is its share of the change of momentum (unit masses here), over dt.
    assert np.allclose(contact.changes.sum(axis=0), v[nodes] - vi, rtol=0.0, atol=1e-15)
    forces = contact.forces(dt=0.5)
    for k, w in enumerate(walls):
        assert np.allclose(forces[w], contact.changes[k].sum(axis=0) / 0.5)


def box(x0, x1, n):
    from dolfinx import mesh
    from mpi4py import MPI

    return mesh.create_box(
        MPI.COMM_WORLD, [np.array(x0, float), np.array(x1, float)], n, mesh.CellType.tetrahedron
    )


@pytest.mark.parametrize("halves", [1, 2])
def test_block_sliding_down_an_inclined_facet_decelerates_at_g_sin_minus_mu_cos(halves):
    """3D: a facet at 17 degrees, rotated 30 degrees about the vertical, on a structured box mesh.

    No mesh plane follows it; the block slides straight down the slope. Cut into two triangles
    along a diagonal under the block, it is still one plane (the triangles' normals differ by
    round-off), whose facets share the nodes along the cut."""
    theta, mu, turn = np.radians(17.0), 0.5, np.radians(30.0)
    grid = dm.Grid(box((0, 0, 0), (0.6, 0.6, 0.45), (15, 15, 12)))
    across = np.array([-np.sin(turn), np.cos(turn), 0.0])  # horizontal, along the slope's contour
    down = np.array([np.cos(theta) * np.cos(turn), np.cos(theta) * np.sin(turn), -np.sin(theta)])
    up = np.cross(down, across)  # the slope's normal, towards the material
    assert up[2] > 0.0
    a = np.array([0.3, 0.3, 0.3]) - 0.2 * down  # the slope's upper middle
    corners = [
        a - 0.15 * across,
        a + 0.15 * across,
        a + 0.4 * down + 0.15 * across,
        a + 0.4 * down - 0.15 * across,
    ]
    corners = (
        corners if np.cross(corners[1] - corners[0], corners[2] - corners[1]) @ up > 0 else corners[::-1]
    )
    if halves == 1:
        facets = [corners]
    else:  # two triangles, cut along a diagonal that runs under the block
        facets = [[corners[0], corners[1], corners[2]], [corners[0], corners[2], corners[3]]]
    slopes = [dm.RigidWall(f, mu=mu, name=f"slope {k}") for k, f in enumerate(facets)]
    assert all(np.allclose(w.normal, -up) for w in slopes)
    mat = dm.LinearElastic(E=1e6, nu=0.3, rho=1000.0)
    thickness = 0.06

    def local(x):  # along, across and above the slope, x.shape=(3, n)
        d = x.T - a
        return d @ down, d @ across, d @ up

    def block(x):
        s, c, t = local(x)
        return (s > 0.05) & (s < 0.17) & (np.abs(c) < 0.06) & (t > 0) & (t < thickness)

    P = dm.seed(grid, mat, ppc=4, where=block, velocity=tuple(down))  # 1 m/s down the slope
    t = local(P.x.T)[2]
    P.sigma[:] = (-mat.rho * G * np.cos(theta) * (thickness - t))[:, None, None] * np.outer(up, up)
    solver = dm.Solver(grid, P, mat, bcs=slopes, gravity=(0, 0, -G), flip=0.0)
    m = solver.total_mass()
    times, speeds, side = [], [], []
    while solver.time < 0.12:
        solver.step()
        times.append(solver.time)
        p = solver.total_momentum() / m
        speeds.append(p @ down)
        side.append(p @ across)
    times, speeds = np.array(times), np.array(speeds)
    late = times > 0.02  # after the first contact waves
    deceleration = np.polyfit(times[late], speeds[late], 1)[0]
    assert deceleration == pytest.approx(G * (np.sin(theta) - mu * np.cos(theta)), rel=0.01)
    assert np.max(np.abs(side)) < 1e-3 * speeds[0]  # straight down the slope
    assert solver.comm.allreduce(solver.state.wall_stops) == 0  # the grid alone held the block


def test_a_move_across_a_facet_stops_on_it_and_a_move_past_its_edge_does_not():
    floor = dm.RigidWall([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], name="floor")  # seen from above
    x = np.array([[0.5, 0.5, 0.01], [1.2, 0.5, 0.01], [0.5, 0.5, 0.5]])
    dx = np.array([[0.1, 0.0, -0.03], [0.0, 0.0, -0.03], [0.0, 0.0, -0.03]])
    v = np.array([[1.0, 0.0, -3.0], [0.0, 0.0, -3.0], [0.0, 0.0, -3.0]])
    assert stop_at_walls([floor], x, dx, v, time=0.0, dt=0.01) == 1
    assert np.allclose(dx[0], [0.1, 0.0, -0.01]) and np.allclose(v[0], [1.0, 0.0, 0.0])  # on it, sliding
    assert np.array_equal(dx[1:, 2], [-0.03, -0.03]) and np.array_equal(v[1:, 2], [-3.0, -3.0])


def test_a_facet_of_another_dimension_or_outside_the_mesh_is_refused():
    grid = dm.Grid(box((0, 0, 0), (1, 1, 1), (2, 2, 2)))
    mat = dm.LinearElastic(E=1e4, nu=0.3, rho=1000.0)
    P = dm.seed(grid, mat, ppc=1, where=lambda x: x[2] < 0.5)
    with pytest.raises(ValueError, match=r"^floor: the wall is a segment in 2D, the grid is 3D"):
        dm.Solver(grid, P, mat, bcs=[dm.RigidWall([(0, 0), (1, 0)], name="floor")])
    with pytest.raises(
        ValueError, match=r"^floor: facet point \[1.5, 0.0, 0.0\] lies outside the mesh \[0, 1\] x"
    ):
        dm.Solver(grid, P, mat, bcs=[dm.RigidWall([(0, 0, 0), (1.5, 0, 0), (0, 1, 0)], name="floor")])
    with pytest.raises(
        ValueError, match=r"^floor: \d+ particles start behind the wall .* go counter-clockwise"
    ):
        dm.Solver(
            grid, P, mat, bcs=[dm.RigidWall([(0, 0, 0), (0, 1, 0), (1, 1, 0), (1, 0, 0)], name="floor")]
        )


BOX = """
[mesh]
shape = "box"
lower = [0.0, 0.0, 0.0]
upper = [0.2, 0.2, 0.2]
cells = [4, 4, 4]

[materials.sand]
model = "elastic"
E = 1e5
nu = 0.3
rho = 1000.0

[bodies.block]
material = "sand"
region = { min = [0.05, 0.05, 0.0], max = [0.15, 0.15, 0.1] }

[walls.floor]
type = "frictional"
facet = [[0.0, 0.0, 0.0], [0.2, 0.0, 0.0], [0.2, 0.2, 0.0], [0.0, 0.2, 0.0]]
friction_angle = 30.0

[solver]
gravity = [0.0, 0.0, -9.81]

[time]
end = 0.01
"""


@pytest.mark.parametrize(
    "override, match",
    [
        (None, None),
        (
            "walls.floor.facet=[[0.0, 0.0, 0.0], [0.2, 0.0, 0.0]]",
            r"walls.floor.facet: must be three or more",
        ),
        (
            "walls.floor.facet=[[0.0, 0.0], [0.2, 0.0], [0.2, 0.2]]",
            r"walls.floor.facet: must be three or more points",
        ),
        (
            "walls.floor.facet=[[0, 0, 0], [0.2, 0, 0], [0.2, 0.2, 0.01], [0, 0.2, 0]]",
            r"walls.floor.facet: facet is not flat",
        ),
        (
            "walls.floor.segment=[[0.0, 0.0], [0.2, 0.0]]",
            r"walls.floor: give one of segment, polygon, facet, not",
        ),
    ],
)
def test_scenario_facet_wall_in_3d(tmp_path, override, match):
    from dolfin_mpm.app import scenario

    (tmp_path / "box.toml").write_text(BOX)
    if match is None:
        sim = scenario.build(scenario.load(tmp_path / "box.toml"))
        (floor,) = sim.walls["floor"]
        assert np.allclose(floor.normal, [0, 0, -1]) and floor.mu == pytest.approx(np.tan(np.radians(30.0)))
        sim.solver.run(0.01, progress=False)
        assert sim.solver.reaction(floor)[2] > 0.0  # the floor pushes the block up
        return
    with pytest.raises(scenario.ScenarioError, match=match):
        scenario.load(tmp_path / "box.toml", [override])


def test_scenario_segment_in_3d_and_facet_in_2d_are_refused(tmp_path):
    from dolfin_mpm.app import scenario

    text = BOX.replace("facet = [[0.0, 0.0, 0.0], [0.2, 0.0, 0.0], [0.2, 0.2, 0.0], [0.0, 0.2, 0.0]]",
                       "segment = [[0.0, 0.0], [0.2, 0.0]]")  # fmt: skip
    (tmp_path / "box.toml").write_text(text)
    with pytest.raises(
        scenario.ScenarioError, match=r"walls.floor.segment: walls as geometry in 3D are a facet"
    ):
        scenario.load(tmp_path / "box.toml")
    text = SILO.read_text().replace(
        "segment = [[0.0, 0.0], [0.05, 0.0]]", "facet = [[0, 0, 0], [1, 0, 0], [1, 1, 0]]"
    )
    (tmp_path / "silo.toml").write_text(text)
    with pytest.raises(
        scenario.ScenarioError, match=r"walls.bottom_left.facet: walls as geometry in 2D are a"
    ):
        scenario.load(tmp_path / "silo.toml")


@pytest.mark.parametrize("x_e", [0.5, 0.53])
def test_two_facets_carry_the_weight_over_each_wherever_their_edge_falls(x_e):
    """3D: an elastic layer at rest on two facets that meet at x_e, on a node plane or between."""
    thickness = 0.1
    grid = dm.Grid(box((0, 0, -0.1), (1, 0.2, 0.2), (20, 4, 6)))
    mat = dm.LinearElastic(E=1e6, nu=0.3, rho=1000.0)
    P = dm.seed(grid, mat, ppc=4, where=lambda x: (x[2] > 0) & (x[2] < thickness))
    K0 = 0.3 / 0.7
    P.sigma[:] = 0.0
    sz = -mat.rho * G * (thickness - P.x[:, 2])
    P.sigma[:, 0, 0], P.sigma[:, 1, 1], P.sigma[:, 2, 2] = K0 * sz, K0 * sz, sz
    left = dm.RigidWall([(0, 0, 0), (x_e, 0, 0), (x_e, 0.2, 0), (0, 0.2, 0)], name="left")
    right = dm.RigidWall([(x_e, 0, 0), (1, 0, 0), (1, 0.2, 0), (x_e, 0.2, 0)], name="right")
    sides = [
        dm.SlipBC(
            grid.nodes_where(lambda x: np.isclose(x[0], 0.0) | np.isclose(x[0], 1.0)), normal=(1, 0, 0)
        ),
        dm.SlipBC(
            grid.nodes_where(lambda x: np.isclose(x[1], 0.0) | np.isclose(x[1], 0.2)), normal=(0, 1, 0)
        ),
    ]
    solver = dm.Solver(grid, P, mat, bcs=[left, right, *sides], gravity=(0, 0, -G), damping=0.3)
    solver.run(0.1, progress=False)

    carried = [solver.reaction(wall)[2] for wall in (left, right)]
    weight = solver.total_mass() * G
    assert sum(carried) == pytest.approx(weight, rel=1e-3)  # at rest: the facets carry it all
    spacing = 0.05 / 4  # a wall of nodes would end at 0.55 for x_e = 0.53, 0.02 off
    assert abs(carried[0] / weight - x_e) < spacing
    assert abs(carried[1] / weight - (1 - x_e)) < spacing


@pytest.mark.parametrize("gdim", [2, 3])
def test_each_walls_mass_at_the_nodes_is_that_of_its_particles(gdim):
    """The one pass over the particles for all walls of a line: each wall's nodal sums are those
    of the particles within the limit in front of it and over it, term for term."""
    from dolfinx import mesh as dmesh
    from mpi4py import MPI

    from dolfin_mpm.core.locate import basis_at, locate
    from dolfin_mpm.core.walls import _wall_shares

    if gdim == 2:  # on one rank each: every point is local
        grid = dm.Grid(dmesh.create_rectangle(MPI.COMM_SELF, [np.zeros(2), np.ones(2)], [7, 6]))
        walls = [dm.RigidWall([(0.1, 0.3), (0.55, 0.3)])]
        walls.append(dm.RigidWall([(0.55, 0.3), (0.9, 0.3)], velocity=(0.2, 0.0)))
    else:
        grid = dm.Grid(dmesh.create_unit_cube(MPI.COMM_SELF, 4, 4, 4))
        square = [(0.1, 0.1, 0.3), (0.1, 0.6, 0.3), (0.6, 0.6, 0.3), (0.6, 0.1, 0.3)]  # seen from above
        walls = [dm.RigidWall(square), dm.RigidWall([(0.6, 0.1, 0.3), (0.6, 0.6, 0.3), (0.9, 0.3, 0.3)])]
    rng = np.random.default_rng(7)
    x = np.zeros((500, 3))
    x[:, :gdim] = rng.random((500, gdim))
    m = rng.random(500)
    basis = basis_at(grid, *locate(grid, x, np.full(500, -1, np.int32)))
    shares = _wall_shares(x, m, basis, walls, 0.2, 0.3)
    for w, share in zip(walls, shares):
        mine = np.flatnonzero((w.distance(x, 0.3) < 0.2) & w.over(x, 0.3))
        want = np.zeros(grid.num_nodes)
        np.add.at(want, basis.dofs[:, mine].T.ravel(), (basis.N[:, mine] * m[mine]).T.ravel())
        assert 10 < len(mine) < 400 and np.array_equal(share, want)


def stop_one_wall_at_a_time(walls, x, dx, v, time, dt):
    """What stop_at_walls does, in numpy, one wall after the other over all particles."""
    from dolfin_mpm.core.walls import ROUNDOFF

    stopped, g = 0, walls[0].gdim
    reach = np.sqrt(np.max(sum(dx[:, c] ** 2 for c in range(g)), initial=0.0))
    for w in walls:
        advance = dt * (w.velocity @ w.normal)
        phi0 = w.distance(x, time)
        phi1 = phi0 - dx[:, 0] * w.normal[0] - dx[:, 1] * w.normal[1] + advance
        if g == 3:
            phi1 -= dx[:, 2] * w.normal[2]
        cross = (phi0 < reach + abs(advance)) & (phi1 < 0.0) & (phi0 >= -ROUNDOFF * w.length)
        idx, phi0, phi1 = np.flatnonzero(cross), phi0[cross], phi1[cross]
        share = phi0 / (phi0 - phi1)
        crossing = x[idx, :g] + share[:, None] * dx[idx, :g]  # over the wall as it is then?
        if g == 2:
            a, t = w.start(time), w.tangent
            along = (crossing[:, 0] - a[0]) * t[0] + (crossing[:, 1] - a[1]) * t[1]
            along -= (w.velocity @ t) * dt * share
            on = (along >= 0.0) & (along <= w.length)
        else:
            y = crossing - w.velocity * time - (dt * share)[:, None] * w.velocity
            on = np.all(sum(y[:, [c]] * w._inward[:, c] for c in range(3)) >= w._offset, axis=1)
        idx, phi1 = idx[on], phi1[on]
        dx[idx, :g] += (phi1 - ROUNDOFF * w.length)[:, None] * w.normal
        vn = sum((v[idx, c] - w.velocity[c]) * w.normal[c] for c in range(g))
        v[idx, :g] -= np.maximum(vn, 0.0)[:, None] * w.normal
        stopped += idx.size
    return stopped


@pytest.mark.parametrize("gdim", [2, 3])
def test_the_compiled_stop_takes_the_walls_in_turn_as_numpy_does(gdim):
    """Bit for bit, for moving walls that meet at a corner, where a move may cross two, one of
    them inclined (so that no product with a normal's component is exact)."""
    rng = np.random.default_rng(5)
    if gdim == 2:
        floor, side = [(0.0, 0.0), (1.0, 0.0)], [(1.0, 0.0), (1.1, 1.0)]
    else:
        floor = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
        side = [(1, 0, 0), (1, 1, 0), (1.1, 1, 1), (1.1, 0, 1)]
    up, left = np.eye(gdim)[-1] * 0.3, np.eye(gdim)[0] * -0.2  # both walls move
    walls = [dm.RigidWall(floor, velocity=up, name="floor"), dm.RigidWall(side, velocity=left, name="side")]
    n, time, dt = 20000, 0.01, 0.05
    x = np.zeros((n, 3))
    x[:, :gdim] = rng.uniform(0.0, 1.0, (n, gdim))
    x[:, 1 if gdim == 2 else 2] = rng.uniform(0.003, 0.05, n)  # near the floor as it is at time
    x[: n // 2, 0] = 1.0 - 0.002 - rng.uniform(0.0, 0.05, n // 2)  # and half near the side
    dx = rng.normal(0.0, 0.02, (n, gdim))
    v = rng.normal(0.0, 1.0, (n, gdim))
    expected = dx.copy(), v.copy()
    count = stop_one_wall_at_a_time(walls, x, *expected, time, dt)
    assert count > 1000 and stop_at_walls(walls, x, dx, v, time, dt) == count
    assert np.array_equal(dx, expected[0]) and np.array_equal(v, expected[1])
