"""Mesh and NURBS-surface walls on several MPI ranks give the serial run bit for bit.

A turning drum (an exact NURBS cylinder, a triangle-mesh baffle inside, flat end plates) holds
ellipsoids and exact spheres: the ranks solve the wall contacts of the particles they own and
merge them in the serial order (the spheres' contacts with a wall before the NURBS
particles', :func:`nurbsdem.contact.curved_walls.serial_order`), so results.h5, every monitor
(the walls' loads among them) and the checkpoint equal the serial run's exactly: with the
linear law, with rolling resistance, with Hertz–Mindlin and with ``Damping Implicit`` (whose
dashpot solve over the gathered network sees the drum's spin as the serial run does), each
alone and the last three together.
"""
from __future__ import annotations

import numpy as np
import pytest

from nurbsdem.contact.curved_walls import serial_order, wall_contact_key
from test_curved_steps import _drum_deck
from test_mpi import _run, BIN, assert_same_run, needs_mpi


#: two ellipsoids (shape 1, the first particles) and six spheres (shape 2): four just above
#: the drum beside the baffle, two above the baffle, so that the drum meets both kinds at once
PARTICLES = """Particles
  Particle 1 Shape 1 Material 1 Position 0.008 0.032 -0.040
  Particle 2 Shape 1 Material 1 Position -0.008 -0.032 -0.040
  Particle 3 Shape 2 Material 1 Position 0.008 -0.030 -0.044
  Particle 4 Shape 2 Material 1 Position -0.008 0.030 -0.044
  Particle 5 Shape 2 Material 1 Position 0.0 0.0 -0.035
  Particle 6 Shape 2 Material 1 Position 0.0 0.012 -0.028
  Particle 7 Shape 2 Material 1 Position 0.0 -0.012 -0.028
  Particle 8 Shape 2 Material 1 Position 0.008 0.038 -0.026
"""


#: the drum's contact laws: the linear law; with rolling resistance (the drum's turning
#: spin in the rolling springs and in the drum's work); Hertz–Mindlin (the contacts' radii
#: from the curvatures of both surfaces, walls rigid); the implicit normal dashpots
LAWS = {"linear": {},
        "rolling": {"Friction 0.5": "Friction 0.5 RollingFriction 0.2"},
        "hertz": {"Material 1 Density 2500": "Material 1 Density 2500 YoungModulus 5e6 "
                                             "PoissonRatio 0.3",
                  "Interface 1 NormalPenalty 2e4 NormalDamping 6 TangentialPenalty 2e4 "
                  "Friction 0.5": "Interface 1 Model HertzMindlin Restitution 0.5 "
                                  "Friction 0.5"},
        "implicit": {"TimeStep 1e-3\n": "TimeStep 1e-3 Damping Implicit\n"}}


def _deck(folder, law: str = "linear"):
    """The drum deck with the laws named in ``law`` (keys of :data:`LAWS`, space-separated,
    applied in that order)."""
    text = _drum_deck(folder).replace(
        "  Shape 1 Sphere Radius 0.006", "  Shape 1 Ellipsoid SemiAxes 0.008 0.0065 0.005"
    ).replace("Step 1 Dynamic Duration 0.08", "Step 1 Dynamic Duration 0.04").replace(
        "Center 0 0 0 Duration 0.08", "Center 0 0 0 Duration 0.03").replace(
        "Step 3 Dynamic Duration 0.02", "Step 3 Dynamic Duration 0.01").replace(
        "NormalDamping 2", "NormalDamping 6")
    for name in law.split():
        for old, new in LAWS[name].items():
            assert old in text, old
            text = text.replace(old, new)
    head, rest = text.split("Particles\n")
    deck = folder / "drum.inp"
    deck.write_text(head + PARTICLES + rest[rest.index("Walls"):])
    return deck


def test_the_serial_order_puts_a_walls_spheres_before_its_nurbs_particles():
    """Keys of contacts with two curved walls (particle 0 a NURBS particle, 1 and 2 spheres)
    sort wall by wall, spheres first, then by particle and rank; pair keys come first."""
    nb, walls = 5, 2
    nurbs = np.array([True, False, False])
    keys = np.array([wall_contact_key(nb, o, w, walls, r)
                     for o, w, r in ((0, 0, 0), (0, 0, 1), (2, 0, 0), (1, 1, 0), (0, 1, 0),
                                     (1, 0, 0))] + [7])
    order = np.argsort(serial_order(keys, nb, walls, nurbs), kind="stable")
    np.testing.assert_array_equal(order, [6, 5, 2, 0, 1, 3, 4])


@needs_mpi
# the suite's time: one run holds Hertz–Mindlin, rolling resistance and the implicit
# dashpots together; each law alone is in the slow suite
@pytest.mark.parametrize("law", [pytest.param(law, marks=pytest.mark.slow) for law in LAWS]
                         + ["hertz rolling implicit"])
def test_a_turning_drum_with_a_mesh_baffle_on_two_ranks(tmp_path, law):
    deck = _deck(tmp_path, law)
    _run([BIN / "nurbsdem", "solve", deck, "--output", tmp_path / "serial"])
    log = _run([BIN / "nurbsdem", "solve", deck, "--output", tmp_path / "two", "--verbose"], 2)
    assert any("owned [4, 4]" in line for line in log.splitlines())
    assert_same_run(tmp_path / "two", tmp_path / "serial")
    drum = np.genfromtxt(tmp_path / "two" / "monitors" / "wall_drum.csv", delimiter=",",
                         names=True)
    baffle = np.genfromtxt(tmp_path / "two" / "monitors" / "wall_baffle.csv", delimiter=",",
                           names=True)
    assert np.abs(drum["torque_x"]).max() > 0 and np.abs(baffle["reaction_z"]).max() > 0
    assert drum["reaction_z"][-1] > 0
