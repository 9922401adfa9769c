"""``MoveWall … ToContact`` of mesh and surface walls (:mod:`nurbsdem.curved_to_contact`):
a planar mesh goes where the flat wall goes; a curved mesh and a NURBS cylinder end with their
smallest gap to the spheres equal to ``Gap``, by an independent distance (trimesh's closest
points; the cylinder's distance in closed form)."""
from __future__ import annotations

import numpy as np
import pytest

import nurbsdem.shapes as shapes
from nurbsdem import Simulation
from nurbsdem.errors import InputError
from nurbsdem.geometry.surfaces import cylinder_patch
from nurbsdem.io.deck import build_model, parse_deck
from nurbsdem.io.shapefile import save_shape
from nurbsdem.solver import Solver

#: (centre (m), radius (m)) of the spheres
SPHERES = [((0.0, 0.0, 0.0), 0.010), ((0.05, 0.02, 0.004), 0.012), ((-0.03, -0.04, 0.002), 0.009),
           ((0.02, -0.06, -0.01), 0.011)]


def _sim(spheres=SPHERES) -> Simulation:
    sim = Simulation(gravity=(0, 0, -9.81))
    sim.add_material(1, density=2500)
    sim.add_interface(normal_penalty=1e5, tangential_penalty=1e5, friction=0.3)
    for x, r in spheres:
        sim.add_particle(shapes.sphere(r), 1, x)
    return sim


def test_planar_mesh_goes_where_the_flat_wall_goes(tmp_path):
    """Two triangles below the spheres, brought up along a slanted direction: the same travel
    as the flat wall's ToContact (the cap of the sphere sweep is the flat wall's formula)."""
    import trimesh
    trimesh.Trimesh([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]],
                    [[0, 1, 2], [0, 2, 3]]).export(tmp_path / "floor.stl")
    d = (0.1, -0.2, 1.0)
    moved = {}
    for kind in ("flat", "mesh"):
        sim = _sim()
        if kind == "flat":
            sim.add_wall("floor", (0, 0, -0.3), (0, 0, 1), (2, 2))
        else:
            sim.add_mesh_wall("floor", tmp_path / "floor.stl", position=(0, 0, -0.3))
        sim.move_wall("floor", to_contact=True, gap=1e-3, direction=d)
        moved[kind] = sim.wall_displacements["floor"]
    np.testing.assert_allclose(moved["mesh"], moved["flat"], rtol=1e-14, atol=1e-16)
    assert moved["mesh"][2] == pytest.approx(0.3 - 0.021 - 0.001, rel=1e-14)


def test_curved_mesh_ends_at_the_gap(tmp_path):
    """A tessellated ball lowered onto the spheres (slightly slanted): its smallest gap to
    them, from trimesh's closest points on the moved mesh's triangles, is Gap."""
    import trimesh
    ball = trimesh.creation.icosphere(subdivisions=2, radius=0.08)
    ball.apply_translation((0.01, -0.015, 0.4))
    ball.export(tmp_path / "ball.stl")
    ball = trimesh.load(tmp_path / "ball.stl")          # the file's float32 corners
    sim = _sim()
    sim.add_mesh_wall("ball", tmp_path / "ball.stl")
    gap = 2e-3
    sim.move_wall("ball", to_contact=True, gap=gap, direction=(0.05, 0.1, -1))
    ball.apply_translation(sim.wall_displacements["ball"])
    tris = ball.triangles
    gaps = []
    for x, r in SPHERES:          # trimesh's closest point on every triangle (no broad phase)
        q = trimesh.triangles.closest_point(tris, np.tile(x, (len(tris), 1)))
        gaps.append(np.linalg.norm(q - x, axis=1).min() - r)
    assert min(gaps) == pytest.approx(gap, rel=1e-10)


def test_nurbs_cylinder_ends_at_the_gap(tmp_path):
    """An exact NURBS cylinder (radius 0.1, axis x) lowered onto the spheres: the smallest
    of |centre − axis| − 0.1 − r over the spheres is Gap; with no sphere under it, a one-line
    error at the step."""
    save_shape(tmp_path / "drum.yaml", [cylinder_patch(0.1, 0.3, axis=(1, 0, 0))])
    sim = _sim()
    sim.add_surface_wall("drum", tmp_path / "drum.yaml", position=(-0.1, 0.01, 0.5))
    gap = 1.5e-3
    sim.move_wall("drum", to_contact=True, gap=gap, direction=(0, 0, -1))
    axis = np.array([0.0, 0.01, 0.5]) + sim.wall_displacements["drum"]
    gaps = [np.hypot(x[1] - axis[1], x[2] - axis[2]) - 0.1 - r for x, r in SPHERES]
    assert min(gaps) == pytest.approx(gap, rel=1e-10)
    text = sim.deck_text
    assert "MoveWall drum ToContact Gap 0.0015 Direction 0.0 0.0 -1.0" in text
    step = build_model(text, str(tmp_path / "again.inp")).steps[-1]
    assert step.to_contact and step.direction[2] == -1.0
    aside = _sim()
    aside.add_surface_wall("drum", tmp_path / "drum.yaml", position=(1.0, 0, 0.5))
    with pytest.raises(InputError, match="meets no particle along the direction"):
        aside.move_wall("drum", to_contact=True, direction=(0, 0, -1))


def test_ellipsoids_against_a_planar_mesh_and_a_nurbs_plane(tmp_path):
    """Turned ellipsoids (NURBS particles): a planar mesh lands where the flat wall does, and
    a NURBS plane patch brought along a slanted direction ends with the smallest gap, from
    the support function h(n) = |A Rᵀ n| (A = diag(a, b, c)), equal to Gap."""
    import trimesh
    from scipy.spatial.transform import Rotation
    trimesh.Trimesh([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]],
                    [[0, 1, 2], [0, 2, 3]]).export(tmp_path / "floor.stl")
    axes = (0.012, 0.008, 0.005)
    bodies = [((0.0, 0.0, 0.0), (0.3, -0.5, 0.2)), ((0.04, 0.01, 0.003), (1.0, 0.2, -0.4))]

    def sim_of():
        sim = Simulation(gravity=(0, 0, -9.81))
        sim.add_material(1, density=2500)
        sim.add_interface(normal_penalty=1e5, tangential_penalty=1e5, friction=0.3)
        for x, rv in bodies:
            sim.add_particle(shapes.ellipsoid(*axes), 1, x, rotation=rv)
        return sim
    moved = {}
    for kind in ("flat", "mesh"):
        sim = sim_of()
        if kind == "flat":
            sim.add_wall("floor", (0, 0, -0.2), (0, 0, 1), (2, 2))
        else:
            sim.add_mesh_wall("floor", tmp_path / "floor.stl", position=(0, 0, -0.2))
        sim.move_wall("floor", to_contact=True, gap=1e-3, direction=(0.1, 0.05, 1.0))
        moved[kind] = sim.wall_displacements["floor"]
    np.testing.assert_allclose(moved["mesh"], moved["flat"], rtol=1e-11, atol=1e-14)
    n = np.array([0.2, -0.1, 1.0]) / np.linalg.norm([0.2, -0.1, 1.0])
    from nurbsdem.geometry.surfaces import plane_patch
    save_shape(tmp_path / "plane.yaml", [plane_patch((0, 0, 0), n, (1.0, 1.0))])
    sim = sim_of()
    sim.add_surface_wall("plane", tmp_path / "plane.yaml", position=-0.3 * n)
    gap = 2e-3
    sim.move_wall("plane", to_contact=True, gap=gap, direction=(0.3, 0.1, 1.0))
    origin = -0.3 * n + sim.wall_displacements["plane"]
    gaps = [n @ (np.array(x) - origin)
            - np.linalg.norm(np.diag(axes) @ Rotation.from_rotvec(rv).as_matrix().T @ n)
            for x, rv in bodies]
    assert min(gaps) == pytest.approx(gap, rel=1e-10)


def test_a_restart_after_to_contact_keeps_the_wall_where_it_went(tmp_path, monkeypatch):
    """A mesh floor brought up to two spheres (ToContact in the deck), then a short settling
    step killed after its checkpoint and restarted: the same final state bit for bit as the
    run straight through, the floor where ToContact left it."""
    import trimesh
    from runs import assert_same_final_state, killed_and_restarted
    trimesh.Trimesh([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]],
                    [[0, 1, 2], [0, 2, 3]]).export(tmp_path / "floor.stl")
    deck = tmp_path / "case.inp"
    deck.write_text("""Environment
  Gravity 0 0 -9.81
Materials
  Material 1 Density 2500
Shapes
  Shape 1 Sphere Radius 0.01
Particles
  Particle 1 Shape 1 Material 1 Position 0 0 0.02
  Particle 2 Shape 1 Material 1 Position 0.03 0 0.021
Walls
  Mesh 7 Name floor File floor.stl Position 0 0 -0.3
Contact
  Interface 1 NormalPenalty 1e5 NormalDamping 5 TangentialPenalty 1e5 Friction 0.3
Steps
  Step 1 MoveWall floor ToContact Gap 0.0005 Direction 0 0 1
  Step 2 Dynamic Duration 0.02 TimeStep 1e-3
Output
  Directory results
  Monitors Every 0.002
  Results Every 0.005
  Checkpoint Every 0.01
""")
    ref = tmp_path / "ref"
    Solver(parse_deck(deck), output=ref, quiet=True).run()
    out = tmp_path / "out"
    killed_and_restarted(deck, out, 0.012, monkeypatch)
    assert_same_final_state(out, ref, monitors=("wall_floor.csv",))
    rows = np.genfromtxt(out / "monitors" / "wall_floor.csv", delimiter=",", names=True)
    assert rows["displacement_z"][-1] == pytest.approx(0.3 + 0.02 - 0.01 - 0.0005, rel=1e-14)


def test_a_one_sided_mesh_stops_only_at_particles_in_front(tmp_path):
    """Two facets at z = 0 lowered along −z: one facing down (x < 0) over a sphere 8 cm
    below, one facing up (x > 0) over a sphere 3 cm below.  Two-sided, the nearer sphere
    stops the wall; one-sided, the up-facing facet meets its sphere from behind and lets it
    through, so the wall stops at the farther one (travel centre depth − r − gap)."""
    import trimesh
    down = [[-0.2, -0.1, 0], [-0.2, 0.1, 0], [-0.01, 0.1, 0], [-0.01, -0.1, 0]]
    up = [[0.01, -0.1, 0], [0.2, -0.1, 0], [0.2, 0.1, 0], [0.01, 0.1, 0]]
    trimesh.Trimesh(down + up, [[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]],
                    process=False).export(tmp_path / "facets.stl")
    spheres = [((-0.1, 0.0, -0.08), 0.01), ((0.1, 0.0, -0.03), 0.01)]
    gap, moved = 1e-3, {}
    for one_sided in (False, True):
        sim = _sim(spheres)
        sim.add_mesh_wall("facets", tmp_path / "facets.stl", one_sided=one_sided)
        sim.move_wall("facets", to_contact=True, gap=gap, direction=(0, 0, -1))
        moved[one_sided] = sim.wall_displacements["facets"]
    assert moved[False][2] == pytest.approx(-(0.03 - 0.01 - gap), rel=1e-13)
    assert moved[True][2] == pytest.approx(-(0.08 - 0.01 - gap), rel=1e-13)
    assert moved[True][0] == moved[True][1] == 0.0


def test_a_refused_contact_in_the_root_find_is_a_one_line_input_error(tmp_path, monkeypatch):
    """Where a particle's contact with the surface wall has no unique solution during the
    root find (the wall curving more tightly than the particle), the step fails with an
    InputError naming the step, the wall and what to do instead, not the solver's error."""
    import nurbsdem.curved_to_contact as ctc
    from nurbsdem.contact.surface_particle import NOT_UNIQUE, refusal

    def refused(*args):
        raise refusal(args[-1], np.zeros(3), 0, NOT_UNIQUE)
    monkeypatch.setattr(ctc, "_nurbs", refused)
    save_shape(tmp_path / "drum.yaml", [cylinder_patch(0.1, 0.3, axis=(1, 0, 0))])
    sim = _sim([])
    sim.add_particle(shapes.ellipsoid(0.02, 0.015, 0.01), 1, (0, 0, 0))
    sim.add_surface_wall("drum", tmp_path / "drum.yaml", position=(-0.1, 0.0, 0.5))
    with pytest.raises(InputError) as err:
        sim.move_wall("drum", to_contact=True, gap=1e-3, direction=(0, 0, -1))
    text = str(err.value)
    assert "MoveWall drum ToContact: surface wall 'drum'" in text and "not unique" in text
    assert "Displacement" in text and "\n" not in text
