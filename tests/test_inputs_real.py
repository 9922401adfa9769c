"""Inputs users really write: resting overlaps, contacts too soft for the
load, and the messages of shape files and Giraffe imports.

* A particle at its resting overlap m g / k on a floor, two stacked spheres, and a pack
  written back into a deck from a settled run are accepted and stay at rest (the contact
  force equals the weight it carries); overlaps beyond what the contact law carries are
  refused with the measured depth and the accepted one, at the particle's line.
* A contact whose static overlap under one particle's weight exceeds a tenth of its size is
  refused before the run, at the Interface's line, for the linear and the Hertz law.
"""
from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import nurbsdem
from nurbsdem import Simulation
from nurbsdem.errors import InputError
from nurbsdem.io.deck import parse_deck
from nurbsdem.validation import (MAX_RESTING_FRACTION, RESTING_LOADS, SOFT_FRACTION,
                                 static_overlap)

R, RHO, K, G = 0.02, 2700.0, 1e5, 9.81
M = RHO * 4.0 / 3.0 * math.pi * R ** 3
D = M * G / K                   # the resting overlap m g / k: 8.88e-6 m


def _deck(tmp_path: Path, particles: str, interface: str = f"NormalPenalty {K:g}",
          gravity: float = G) -> Path:
    text = f"""Environment
  Gravity 0 0 {-gravity!r}
Materials
  Material 1 Density {RHO:g} YoungModulus 1e7 PoissonRatio 0.3
Shapes
  Shape 1 Sphere Radius {R!r}
Particles
{particles}
Walls
  Box 1 Min 0 0 0 Max 0.2 0.2 0.3
Contact
  Interface 1 {interface}
Steps
  Step 1 Dynamic Duration 0.002 TimeStep 0.0001
Output
  Directory out
"""
    p = tmp_path / "case.inp"
    p.write_text(text)
    return p


def _particle(pid: int, z: float, x: float = 0.1, rot=(0.0, 0.0, 0.0)) -> str:
    return (f"  Particle {pid} Shape 1 Material 1 Position {x!r} 0.1 {z!r} "
            f"Rotation {rot[0]!r} {rot[1]!r} {rot[2]!r}")


# ---------------------------------------------------------------------------- resting overlaps


def test_sphere_at_its_resting_overlap_is_accepted_by_the_deck(tmp_path):
    model = parse_deck(_deck(tmp_path, _particle(1, R - D)))
    assert model.bodies.position[0, 2] == pytest.approx(R - D)
    assert static_overlap(model, "particle-wall", (1,), M, R) == pytest.approx(D, rel=1e-12)


def test_stacked_spheres_at_their_resting_overlaps_are_accepted(tmp_path):
    z1 = R - 2 * D                   # the floor carries both
    parse_deck(_deck(tmp_path, _particle(1, z1) + "\n" + _particle(2, z1 + 2 * R - D)))


def test_sphere_and_stack_stay_at_rest_with_force_equal_to_weight():
    """The API places the settled state; after 20 steps nothing moved and the contact
    forces are the weights they carry (2 m g on the floor, m g between the spheres)."""
    sim = Simulation(gravity=(0, 0, -G))
    sim.add_material(1, RHO)
    sim.add_interface(normal_penalty=K)
    sim.add_box(min=(0, 0, 0), max=(0.2, 0.2, 0.2))
    z1 = R - 2 * D
    sim.add_particle(nurbsdem.shapes.sphere(R), 1, (0.1, 0.1, z1))
    sim.add_particle(nurbsdem.shapes.sphere(R), 1, (0.1, 0.1, z1 + 2 * R - D))
    sim.run_dynamic(duration=2e-3, time_step=1e-4)
    assert np.abs(sim.positions[:, 2] - [z1, z1 + 2 * R - D]).max() < 1e-12
    c = sim.contacts()
    fz = sorted(abs(float(f[2])) for f in c["force_normal"])
    assert fz == pytest.approx([M * G, 2 * M * G], rel=1e-9)


def test_overlap_beyond_what_the_contact_carries_is_refused_with_both_depths(tmp_path):
    deep = 2 * RESTING_LOADS * D
    with pytest.raises(InputError) as exc:
        parse_deck(_deck(tmp_path, _particle(1, R - deep)))
    msg = str(exc.value)
    assert msg.startswith(f"{tmp_path / 'case.inp'}:8: particle 1 penetrates wall 'bottom' by ")
    assert f"{deep:.3g} m; at most {RESTING_LOADS * D:.3g} m is accepted" in msg
    with pytest.raises(InputError, match=r":9: particle 2 overlaps particle 1 by .* at most"):
        parse_deck(_deck(tmp_path, _particle(1, R) + "\n" + _particle(2, 3 * R - deep)))


def test_a_tall_piles_deepest_contact_is_accepted_up_to_all_the_particles_weight(tmp_path):
    """The floor under a pile carries all the particles' weight: with 40 particles in the
    deck, a sphere sinking 30 resting overlaps into the floor (more than 20, less than the 40
    that carry them all) is accepted; with 2 particles the same depth is refused."""
    deep = 30 * D
    spots = [(x, y, z) for z in (0.12, 0.165, 0.21) for y in (0.03, 0.075, 0.12, 0.165)
             for x in (0.03, 0.075, 0.12, 0.165)][:38]
    far = "\n".join(f"  Particle {k} Shape 1 Material 1 Position {x!r} {y!r} {z!r}"
                    for k, (x, y, z) in enumerate(spots, start=3))
    parse_deck(_deck(tmp_path, _particle(1, R - deep) + "\n" + _particle(2, 3 * R) + "\n"
                     + far))
    with pytest.raises(InputError, match="all the particles' weight"):
        parse_deck(_deck(tmp_path, _particle(1, R - deep) + "\n" + _particle(2, 3 * R)))


def test_without_gravity_only_round_off_is_accepted(tmp_path):
    with pytest.raises(InputError, match="penetrates wall 'bottom'"):
        parse_deck(_deck(tmp_path, _particle(1, R - D), gravity=0.0))


def test_large_accepted_overlap_warns(tmp_path, caplog):
    """Soft enough that 20 resting overlaps exceed 1 % of the size: accepted with a warning
    (and never beyond MAX_RESTING_FRACTION of the bounding radius)."""
    k = 3e3
    d = M * G / k
    with caplog.at_level(logging.WARNING, logger="nurbsdem"):
        parse_deck(_deck(tmp_path, _particle(1, R - 3 * d), f"NormalPenalty {k:g}"))
    assert any("penetrates wall 'bottom'" in r.getMessage() and "accepted" in r.getMessage()
               for r in caplog.records)
    rb = nurbsdem.shapes.sphere(R).bounding_radius
    with pytest.raises(InputError, match="at most"):
        parse_deck(_deck(tmp_path, _particle(1, R - 1.01 * MAX_RESTING_FRACTION * rb),
                         "NormalPenalty 1e3"))


def test_settled_pack_written_back_into_a_deck_runs(tmp_path):
    """A pack settled in one run, its positions and rotations written as Particle lines, is
    accepted and runs (before: refused at the first resting contact)."""
    r = 0.01
    sim = Simulation(gravity=(0, 0, -G))
    sim.add_material(1, RHO)
    sim.add_interface(normal_penalty=K, normal_damping=40.0, tangential_penalty=K,
                      tangential_damping=40.0, friction=0.5)
    sim.add_box(min=(0, 0, 0), max=(0.05, 0.05, 0.3))
    rng = np.random.default_rng(2)
    for k in range(8):
        xy = 0.025 + rng.uniform(-0.004, 0.004, 2)
        sim.add_particle(nurbsdem.shapes.sphere(r), 1, (xy[0], xy[1], 0.012 + 0.025 * k))
    sim.run_dynamic(duration=0.6, time_step=1e-3)
    assert np.abs(sim.velocities).max() < 2e-2
    rot = Rotation.from_matrix(sim.rotations).as_rotvec()
    lines = "\n".join(
        f"  Particle {i + 1} Shape 1 Material 1 Position {' '.join(map(repr, map(float, p)))} "
        f"Rotation {' '.join(map(repr, map(float, q)))}"
        for i, (p, q) in enumerate(zip(sim.positions, rot)))
    deck = _deck(tmp_path, lines, f"NormalPenalty {K:g} NormalDamping 40 TangentialPenalty "
                                  f"{K:g} TangentialDamping 40 Friction 0.5")
    text = deck.read_text().replace(f"Radius {R!r}", f"Radius {r!r}").replace(
        "Max 0.2 0.2 0.3", "Max 0.05 0.05 0.3")
    deck.write_text(text)
    again = Simulation.from_deck(deck, output=tmp_path / "out")
    again.run()
    assert np.abs(again.positions - sim.positions).max() < 1e-4


# ---------------------------------------------------------------------------- too soft


def test_contact_too_soft_for_the_weight_is_refused_at_the_interface(tmp_path):
    k = 10.0            # m g / k = 0.089 m, more than the sphere
    with pytest.raises(InputError) as exc:
        parse_deck(_deck(tmp_path, _particle(1, 0.1), f"NormalPenalty {k:g}"))
    msg = str(exc.value)
    assert msg.startswith(f"{tmp_path / 'case.inp'}:12: Interface 1: the contact is too soft "
                          f"for the load")
    assert f"sinks {M * G / k:.3g} m" in msg and "raise NormalPenalty above" in msg
    rb = nurbsdem.shapes.sphere(R).bounding_radius
    k_min = M * G / (SOFT_FRACTION * rb)
    parse_deck(_deck(tmp_path, _particle(1, 0.1), f"NormalPenalty {1.01 * k_min:g}"))


def test_hertz_contact_too_soft_is_refused(tmp_path):
    deck = _deck(tmp_path, _particle(1, 0.1), "Model HertzMindlin Restitution 0.5")
    parse_deck(deck)                      # E = 1e7 Pa carries a 2 cm sphere
    deck.write_text(deck.read_text().replace("YoungModulus 1e7", "YoungModulus 10"))
    with pytest.raises(InputError, match=r":12: Interface 1: the contact is too soft .*"
                                         r"YoungModulus"):
        parse_deck(deck)


def test_api_contact_too_soft_is_refused_before_the_run():
    sim = Simulation(gravity=(0, 0, -G))
    sim.add_material(1, RHO)
    sim.add_interface(normal_penalty=10.0)
    sim.add_box(min=(0, 0, 0), max=(0.2, 0.2, 0.2))
    sim.add_particle(nurbsdem.shapes.sphere(R), 1, (0.1, 0.1, 0.1))
    with pytest.raises(InputError, match="too soft for the load"):
        sim.run_dynamic(duration=1e-3, time_step=1e-4)


# ---------------------------------------------------------------------------- messages


def _shape_deck(tmp_path: Path, shape_line: str, box_max_x: str = "0.2") -> Path:
    from nurbsdem.io.shapefile import save_shape
    save_shape(tmp_path / "s.yaml", nurbsdem.shapes.sphere(0.01))
    text = _deck(tmp_path, _particle(1, 0.1)).read_text()
    text = text.replace(f"Shape 1 Sphere Radius {R!r}", shape_line)
    text = text.replace("Max 0.2 0.2 0.3", f"Max {box_max_x} 0.2 0.3")
    (tmp_path / "case.inp").write_text(text)
    return tmp_path / "case.inp"


def test_a_folder_given_as_a_shape_file_says_so(tmp_path):
    (tmp_path / "shapes").mkdir()
    deck = _shape_deck(tmp_path, "Shape 1 File shapes")
    with pytest.raises(InputError, match=r"case\.inp:6: shape file shapes: is a folder, not a "
                                         r"file$"):
        parse_deck(deck)
    sim = Simulation()
    sim.add_material(1, 2000)
    with pytest.raises(InputError, match="add_particle: shape file .*: is a folder, not a file"):
        sim.add_particle(tmp_path / "shapes", 1, (0, 0, 0))
    from nurbsdem.io.shapefile import load_shape
    with pytest.raises(InputError, match="cannot read file: it is a folder, not a file"):
        load_shape(tmp_path / "shapes")


def test_a_box_too_thin_names_its_sides(tmp_path):
    deck = _shape_deck(tmp_path, "Shape 1 File s.yaml", box_max_x="1e-320")
    with pytest.raises(InputError, match=r"case\.inp:10: wall 'bottom' of the Box: its sides are "
                                         r"1e-320 m and 0.2 m long: each must be at least 1e-09 m"):
        parse_deck(deck)


@pytest.mark.parametrize("tol", ["1e300", "0.5"])
def test_convexity_tolerance_has_a_range_in_the_deck(tmp_path, tol):
    deck = _shape_deck(tmp_path, f"Shape 1 File s.yaml ConvexityTolerance {tol}")
    with pytest.raises(InputError, match=r"case\.inp:6: Shape 1: ConvexityTolerance .* is out "
                                         r"of range: it must be at most 0.1"):
        parse_deck(deck)


@pytest.mark.parametrize("tol", [float("inf"), float("nan"), 1e300, -1.0])
def test_convexity_tolerance_has_a_range_in_the_api_and_cli(tmp_path, tol):
    """A 27 % dent passed with ConvexityTolerance 1e300: now no tolerance accepts it."""
    from nurbsdem.geometry import generators as gen
    from nurbsdem.geometry.nurbs import Patch
    from nurbsdem.io.shapefile import load_shape, save_shape
    patches = gen.sphere_patches(1.0)
    p = patches[2]
    cp = p.control_points.copy()
    cp[2, 2] *= 1.0 - 1.5
    patches[2] = Patch(4, 4, p.knots_u, p.knots_v, cp, p.weights)
    f = tmp_path / "dent.yaml"
    save_shape(f, patches)
    with pytest.raises(InputError, match="convexity tolerance .* is out of range: it must be "
                                         "from 0 to 0.1"):
        load_shape(f, convexity_tol=tol)
    from click.testing import CliRunner
    from nurbsdem.cli import main
    r = CliRunner().invoke(main, ["info", str(f), "--convexity-tol", repr(tol)])
    assert r.exit_code == 2 and ("out of range" in r.output or "Invalid value" in r.output)


def test_nan_vertex_in_a_ply_is_refused(tmp_path):
    import trimesh
    from nurbsdem.geometry.fit import read_input
    m = trimesh.creation.icosphere(2, 0.01)
    v = m.vertices.copy()
    v[5] = np.nan
    trimesh.Trimesh(v, m.faces, process=False).export(tmp_path / "nan.ply")
    with pytest.raises(InputError, match=r"nan\.ply: vertex 5 \(counted from 0\) has non-finite "
                                         r"coordinates nan nan nan"):
        read_input(tmp_path / "nan.ply")
    trimesh.PointCloud(np.vstack([m.vertices, [[np.inf, 0, 0]]])).export(tmp_path / "pc.ply")
    with pytest.raises(InputError, match="vertex 162 .* non-finite coordinates inf 0 0"):
        read_input(tmp_path / "pc.ply")
    m.export(tmp_path / "ok.ply")
    assert len(read_input(tmp_path / "ok.ply").points) == len(m.vertices)


# ---------------------------------------------------------------------------- fit


def test_fit_of_a_noisy_sphere_cloud_is_unbiased_and_reports_the_noise(caplog):
    """1 % radial noise on a sphere: the points themselves are fitted (not their hull, which
    envelops the noise: +6.7 % with 20 000 points), the volume is within 1 % of the sphere's
    and the RMS residual estimates the noise, with a warning."""
    from nurbsdem.geometry.fit import FitInput, fit_particle
    rng = np.random.default_rng(3)
    d = rng.normal(size=(2000, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    r, sigma = 0.01, 0.01
    pts = d * r * (1.0 + sigma * rng.normal(size=(2000, 1)))
    with caplog.at_level(logging.WARNING, logger="nurbsdem"):
        res = fit_particle(FitInput(pts, None, "noisy.xyz"))
    assert abs(res.shape.volume / (4.0 / 3.0 * math.pi * r ** 3) - 1.0) < 0.01
    assert res.shape.convexity.relative <= 1e-4
    assert res.noise == pytest.approx(sigma * r, rel=0.1)
    assert res.volume_hull > 1.02 * res.shape.volume          # the hull is biased outward
    assert any("noisy data" in rec.getMessage() for rec in caplog.records)
    assert any("noise estimate" in line for line in res.lines())


def test_fit_is_scale_invariant_down_to_a_micrometre():
    """A 1 um mesh (LinAlgError before) and the shipped grain scan scaled by 1e-4 fit as
    their metre-sized versions."""
    import trimesh
    from nurbsdem.geometry.fit import FitInput, fit_particle, read_input
    m = trimesh.creation.icosphere(3, 1e-6)
    res = fit_particle(FitInput(np.asarray(m.vertices), m, "um.stl"), n_cp=6)
    assert res.shape.volume == pytest.approx(m.volume, rel=2e-3)
    assert res.size == pytest.approx(2e-6 * math.sqrt(3.0), rel=1e-3)
    big = trimesh.creation.icosphere(3, 1.0)
    ref = fit_particle(FitInput(np.asarray(big.vertices), big, "m.stl"), n_cp=6)
    assert res.shape.volume == pytest.approx(ref.shape.volume * 1e-18, rel=1e-9)
    scan = Path(__file__).resolve().parent.parent / "inputs" / "shapes" / "grain_scan.ply"
    data = read_input(scan)
    data.points = data.points * 1e-4
    data.mesh = data.mesh.copy()
    data.mesh.apply_scale(1e-4)
    small = fit_particle(data)
    from nurbsdem.io.shapefile import load_shape
    shipped = load_shape(scan.parent / "grain.yaml")
    assert small.shape.volume == pytest.approx(shipped.volume * 1e-12, rel=1e-9)


def test_shell_points_keep_the_noise_band_and_drop_the_interior():
    from nurbsdem.geometry.fit import shell_points
    rng = np.random.default_rng(5)
    d = rng.normal(size=(3000, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    shell = d * (1.0 + 0.01 * rng.normal(size=(3000, 1)))
    inner = 0.5 * d[:300]
    keep, band = shell_points(np.concatenate([shell, inner]))
    assert keep[:3000].mean() > 0.99 and not keep[3000:].any()
    assert 0.01 / 2 / math.sqrt(3) < band < 0.1
    clean = d[:500]                            # noise-free: every point is on the hull
    keep, band = shell_points(clean)
    assert keep.all() and band < 1e-8
