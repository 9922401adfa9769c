"""Hertz–Mindlin in the deck: Material YoungModulus/PoissonRatio, Interface Model HertzMindlin,
Box/Wall Material; the input errors; a run that writes the contact radius and stiffness."""
from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np
import pytest

from nurbsdem.dynamics.laws.hertz_mindlin import HertzMindlin as HertzMindlinLaw, effective_moduli
from nurbsdem.errors import InputError
from nurbsdem.io.deck import parse_deck
from nurbsdem.solver import Solver
from runs import assert_same_final_state, killed_and_restarted

DECK = """\
Environment
  Gravity 0 0 -9.81
Materials
  Material 1 Density 2700 YoungModulus 7e9 PoissonRatio 0.3
  Material 2 Density 7800 YoungModulus 2e11 PoissonRatio 0.29
Shapes
  Shape 1 Ellipsoid SemiAxes 0.02 0.015 0.01
  Shape 2 Sphere Radius 0.012
Particles
  Particle 1 Shape 1 Material 1 Position 0.05 0.05 0.0100001 Rotation 0 0 0
  Particle 2 Shape 2 Material 1 Position 0.05 0.05 0.05
Walls
  Box 1 Min 0 0 0 Max 0.1 0.1 0.2 {box}
Contact
  {iface}
Steps
  Step 1 Dynamic Duration 0.02 TimeStep 1e-3
Output
  Directory results
  VTK Every 0.01 Resolution 4
"""

HM = "Interface 1 Model HertzMindlin Restitution 0.5 Friction 0.3"


def _write(tmp_path: Path, iface: str = HM, box: str = "", mats: str | None = None) -> Path:
    text = DECK.format(iface=iface, box=box)
    if mats is not None:
        text = text.replace("  Material 1 Density 2700 YoungModulus 7e9 PoissonRatio 0.3\n", mats)
    p = tmp_path / "h.inp"
    p.write_text(text)
    return p


def test_deck_keys_parse(tmp_path):
    m = parse_deck(_write(tmp_path, box="Material 2"))
    assert m.materials[1].young_modulus == 7e9 and m.materials[1].poisson_ratio == 0.3
    itf = m.interfaces[0]
    assert itf.model == "hertz" and itf.restitution == 0.5 and itf.friction == 0.3
    assert {w.material_id for w in m.walls} == {2}
    # the linear default is unchanged
    m2 = parse_deck(_write(tmp_path, iface="Interface 1 NormalPenalty 1e5 Friction 0.5"))
    assert m2.interfaces[0].model == "linear" and m2.interfaces[0].normal_penalty == 1e5
    m3 = parse_deck(_write(tmp_path, iface="Interface 1 Model LinearPenalty NormalPenalty 1e5"))
    assert m3.interfaces[0].model == "linear"


@pytest.mark.parametrize("iface, box, mats, message", [
    ("Interface 1 Model HertzMindlin Friction 0.3", "", None, "Restitution"),
    ("Interface 1 Model HertzMindlin Restitution 1.5", "", None, r"Restitution must lie in \(0, 1\]"),
    ("Interface 1 Model HertzMindlin Restitution 0.5 NormalPenalty 1e5", "", None,
     "NormalPenalty does not apply to a HertzMindlin interface"),
    ("Interface 1 NormalPenalty 1e5 Restitution 0.5", "", None, "Restitution applies to Model HertzMindlin"),
    ("Interface 1 Model Hooke Restitution 0.5", "", None, "Model must be LinearPenalty or HertzMindlin"),
    (HM, "", "  Material 1 Density 2700 PoissonRatio 0.6\n", "PoissonRatio must lie in"),
    (HM, "", "  Material 1 Density 2700 YoungModulus -1\n", "YoungModulus must be > 0"),
])
def test_deck_errors(tmp_path, iface, box, mats, message):
    with pytest.raises(InputError, match=message) as info:
        parse_deck(_write(tmp_path, iface=iface, box=box, mats=mats))
    assert str(info.value).startswith(str(tmp_path / "h.inp") + ":") or "h.inp:" in str(info.value)


def test_solver_needs_young_modulus(tmp_path):
    """The deck check refuses it (below); a model built otherwise is refused by the solver."""
    model = parse_deck(_write(tmp_path))
    model.materials[1].young_modulus = None
    with pytest.raises(InputError, match="needs YoungModulus on Material 1"):
        Solver(model, output=tmp_path / "out", quiet=True)


def test_wall_material_sets_the_effective_modulus(tmp_path):
    rigid = Solver(parse_deck(_write(tmp_path)), output=tmp_path / "o1", quiet=True)
    steel = Solver(parse_deck(_write(tmp_path, box="Material 2")), output=tmp_path / "o2",
                   quiet=True)
    lw_r = rigid.interfaces.get(rigid.mat_index[1], rigid.wall_index[None])
    lw_s = steel.interfaces.get(steel.mat_index[1], steel.wall_index[2])
    assert isinstance(lw_r, HertzMindlinLaw)
    assert lw_r.e_star == pytest.approx(7e9 / (1 - 0.09))
    assert lw_s.e_star == pytest.approx(effective_moduli(7e9, 0.3, 2e11, 0.29)[0])
    lpp = rigid.interfaces.get(rigid.mat_index[1], rigid.mat_index[1])
    assert lpp.e_star == pytest.approx(7e9 / (1 - 0.09) / 2)


def test_run_writes_radius_and_stiffness(tmp_path):
    p = _write(tmp_path)            # 0.12 s: the sphere falls onto the ellipsoid at ~0.09 s
    p.write_text(p.read_text().replace("Duration 0.02", "Duration 0.12"))
    s = Solver(parse_deck(p), output=tmp_path / "out", quiet=True)
    s.run()
    mon = np.genfromtxt(tmp_path / "out" / "monitors" / "hertz.csv", delimiter=",", names=True)
    assert mon["active"].max() >= 1
    hit = mon["active"] > 0
    # the ellipsoid lies on its flat side: radii of curvature a²/c = 0.04, b²/c = 0.0225 m
    assert np.nanmax(mon["radius_max"][hit]) > 0.02
    vtus = sorted((tmp_path / "out" / "vtk").glob("contacts_*.vtu"))
    data = meshio.read(vtus[1]).point_data              # t = 0.01 s: the ellipsoid resting
    assert "contact_radius" in data and "stiffness_normal" in data
    assert np.all(np.isfinite(data["contact_radius"]))
    # the energy ledger stays closed with the nonlinear law (error: the integration's)
    en = np.genfromtxt(tmp_path / "out" / "monitors" / "energy.csv", delimiter=",", names=True)
    scale = en["potential"][0] - en["potential"].min() + en["kinetic"].max()
    assert en["dissipated"][-1] > 0.1 * scale           # the sphere hit the ellipsoid
    assert np.abs(en["balance_error"]).max() < 1e-2 * scale


def test_restart_is_bit_for_bit(tmp_path, monkeypatch):
    """A Hertz run killed after a checkpoint and restarted ends in the same state, with the
    same monitors (the per-contact coefficients and radii are part of the state)."""
    text = DECK.format(iface=HM, box="").replace("Duration 0.02", "Duration 0.04").replace(
        "Position 0.05 0.05 0.011", "Position 0.05 0.05 0.0100001").replace(
        "  VTK Every 0.01 Resolution 4\n", "  VTK Every 0.01 Resolution 4\n  Checkpoint Every 0.01\n")
    deck = tmp_path / "h.inp"
    deck.write_text(text)
    ref, out = tmp_path / "ref", tmp_path / "out"
    Solver(parse_deck(deck), output=ref, quiet=True).run()
    killed_and_restarted(deck, out, 0.025, monkeypatch)
    assert_same_final_state(out, ref, ("energy.csv", "contacts.csv", "hertz.csv"))


@pytest.mark.parametrize("box, mats, message", [
    ("", "  Material 1 Density 2700\n", "covers material 1, which needs a YoungModulus"),
    ("Material 7", None, "wall bottom: unknown material 7"),
    ("Material 3", "  Material 1 Density 2700 YoungModulus 7e9\n  Material 3 Density 1000\n",
     "needs a YoungModulus to be a wall material"),
])
def test_check_refuses_missing_constants(tmp_path, box, mats, message):
    with pytest.raises(InputError, match=message):
        parse_deck(_write(tmp_path, box=box, mats=mats))


def test_each_wall_takes_its_own_material(tmp_path):
    """A steel box with a lid of material 1 and a rigid wall: three wall materials, each with
    its own effective modulus against the particles (the lid, named on its line only, does not
    turn the box into material 1, nor the box the rigid wall into steel)."""
    p = _write(tmp_path, box="Material 2")
    text = p.read_text().replace(
        "Walls\n", "Walls\n  Wall 20 Name lid Point 0.05 0.05 0.19 Normal 0 0 -1 Size 0.1 0.1 "
        "Material 1\n  Wall 21 Name plate Point 0.05 0.05 0.18 Normal 0 0 -1 Size 0.02 0.02\n")
    p.write_text(text)
    s = Solver(parse_deck(p), output=tmp_path / "out", quiet=True)
    m1 = s.mat_index[1]
    lid, box, plate = (s.interfaces.get(m1, s.wall_index[k]) for k in (1, 2, None))
    assert lid.e_star == pytest.approx(effective_moduli(7e9, 0.3, 7e9, 0.3)[0])
    assert box.e_star == pytest.approx(effective_moduli(7e9, 0.3, 2e11, 0.29)[0])
    assert plate.e_star == pytest.approx(7e9 / (1 - 0.09))
    walls = {w.name: k for k, w in enumerate(s.model.walls)}
    sysm = s._build_system(1e-3, s._fixed_motions())
    mats = sysm.walls.material
    assert mats[walls["lid"]] == s.wall_index[1] and mats[walls["bottom"]] == s.wall_index[2]
    assert mats[walls["plate"]] == s.wall_index[None]


def test_random_groups_give_the_reference_linearisation(tmp_path):
    """The a-priori linearisation takes the lightest particle of Random groups too."""
    p = _write(tmp_path)
    p.write_text(p.read_text().replace(
        "  Particle 2 Shape 2 Material 1 Position 0.05 0.05 0.05\n",
        "  Random 5 Shapes 2 Counts 3 Material 1 Region 0.02 0.02 0.06 0.08 0.08 0.15 Seed 2\n"))
    s = Solver(parse_deck(p), output=tmp_path / "out", quiet=True)
    law = s.interfaces.get(s.mat_index[1], s.mat_index[1])
    assert law.en > 0 and law.cn > 0 and law.et > 0
