"""Periodic cells on several MPI ranks give the serial run bit for bit.

Every rank wraps every particle at a list build (all of them synchronised from their owners
first) and lists the pairs, images across the faces included, with a particle it owns; the
contacts' image translations travel with the merged rows, the wraps' potential jumps are
booked among the kicks' work in the serial order, and the implicit dashpots of the gathered
network take an image as its owner as the serial solve does (:mod:`nurbsdem.parallel.domain`).
The shear box of ``inputs/periodic`` (a periodic bulk under a lid that comes down) on two
ranks equals the serial run in results.h5, every monitor and the checkpoint, with explicit
and with implicit dashpots, with a mesh floor instead of the flat one, and after a restart
on two ranks; so does a pour into a periodic box with a sideways velocity, whose particles
cross the faces.
"""
from __future__ import annotations

import re
import sys

import numpy as np
import pytest

from test_mpi import _run, BIN, HERE, RUN, assert_same_run, needs_mpi
from test_periodic_flow import DECK

SHEAR_BOX = HERE.parent / "inputs" / "periodic" / "shear_box.inp"

#: the periodic pour of test_periodic_flow with a sideways velocity, 40 spheres, 0.05 s
POUR = DECK.replace(
    "Interface 1 NormalPenalty 1e4 NormalDamping 0.5",
    "Interface 1 NormalPenalty 1e4 NormalDamping 0.5 TangentialPenalty 1e4 Friction 0.3"
).replace("Box 0 0 0.02 0.04 0.03 0.04 Rate 1000 Count 10",
          "Box 0 0 0.02 0.03 0.03 0.04 Rate 4000 Count 40 Velocity 0.3 0.2 -0.5 Seed 7 "
          "Every 0.005").replace("Duration 0.01", "Duration 0.05") + """Output
  Monitors Every 0.005
  Results Every 0.01
"""


def _deck(folder, implicit: bool):
    text = SHEAR_BOX.read_text()
    if implicit:
        text = text.replace("TimeStep 1e-3\n", "TimeStep 1e-3 Damping Implicit\n")
        assert text.count("Damping Implicit") == 2
    deck = folder / "shear_box.inp"
    deck.write_text(text)
    return deck


def _mesh_floor(folder, deck):
    """The shear box's flat floor replaced by a two-triangle mesh covering the cell and a
    margin of 1.5 cm around it."""
    import trimesh
    v = np.array([[-0.015, -0.015, 0], [0.075, -0.015, 0], [0.075, 0.075, 0],
                  [-0.015, 0.075, 0]], float)
    trimesh.Trimesh(v, np.array([[0, 1, 2], [0, 2, 3]]), process=False).export(
        folder / "floor.stl")
    text = deck.read_text()
    flat = "  Wall 1 Name floor Point 0.03 0.03 0 Normal 0 0 1 Size 0.09 0.09\n"
    assert flat in text
    deck.write_text(text.replace(flat, "").replace("Walls\n",
                                                   "Walls\n  Mesh 3 Name floor File floor.stl\n"))


@needs_mpi
@pytest.mark.parametrize("implicit, mesh", [
    # the suite's time: one run holds the implicit dashpots and the mesh floor together;
    # each alone is in the slow suite
    pytest.param(False, False, id="explicit", marks=pytest.mark.slow),
    pytest.param(True, False, id="implicit", marks=pytest.mark.slow),
    pytest.param(False, True, id="mesh floor", marks=pytest.mark.slow),
    pytest.param(True, True, id="implicit on a mesh floor")])
def test_the_periodic_shear_box_on_two_ranks(tmp_path, implicit, mesh):
    deck = _deck(tmp_path, implicit)
    if mesh:
        _mesh_floor(tmp_path, deck)
    _run([BIN / "nurbsdem", "solve", deck, "--output", tmp_path / "serial"])
    log = _run([BIN / "nurbsdem", "solve", deck, "--output", tmp_path / "two", "--verbose"], 2)
    ghosts = [tuple(map(int, g)) for g in re.findall(r"ghosts \[(\d+), (\d+)\]", log)]
    assert ghosts and all(a > 0 and b > 0 for a, b in ghosts)      # pairs across the cut
    assert_same_run(tmp_path / "two", tmp_path / "serial")


@needs_mpi
@pytest.mark.slow      # the suite's time: test_mpi_flow restarts a pour on two ranks
def test_the_periodic_shear_box_killed_on_two_ranks_restarts(tmp_path):
    deck = _deck(tmp_path, False)
    _run([BIN / "nurbsdem", "solve", deck, "--output", tmp_path / "serial"])
    out = tmp_path / "out"
    assert "killed" in _run([sys.executable, RUN, deck, out, "--kill-after", "0.07"], 2)
    _run([BIN / "nurbsdem", "solve", deck, "--output", out, "--restart",
          out / "checkpoint.h5"], 2)
    assert_same_run(out, tmp_path / "serial")


@needs_mpi
def test_a_pour_into_a_periodic_box_on_two_ranks(tmp_path):
    deck = tmp_path / "pour.inp"
    deck.write_text(POUR)
    _run([BIN / "nurbsdem", "solve", deck, "--output", tmp_path / "serial"])
    _run([BIN / "nurbsdem", "solve", deck, "--output", tmp_path / "two"], 2)
    assert_same_run(tmp_path / "two", tmp_path / "serial")
