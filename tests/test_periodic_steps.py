"""Periodic cells on the compiled deck steps (nurbsdem.dynamics.periodic_steps): spheres and
ellipsoids thrown sideways in a cell periodic in x and y, pressed by a lid, cross its faces
(wraps at the list builds) and touch each other's images; the compiled loop runs them and
gives the Python driver's monitors and results bit for bit, with explicit and with implicit
normal dashpots."""
from __future__ import annotations

import numpy as np
import pytest

from nurbsdem.dynamics import images as images_module
from nurbsdem.dynamics import internal_step
from runs import spread_points
from test_curved_steps import _counting_steps, _same_bits
from test_sphere_steps import _both_paths


def _periodic_deck() -> str:
    """16 spheres and 4 ellipsoids moving at up to 0.8 m/s across a 40 mm cell."""
    rng = np.random.default_rng(11)
    pts = spread_points(rng, 20, [0.007, 0.007, 0.007], [0.033, 0.033, 0.036], 0.0115)
    lines = []
    for i, p in enumerate(pts):
        v = np.append(rng.uniform(-0.8, 0.8, 2), 0.0)
        lines.append(f"  Particle {i + 1} Shape {1 if i % 5 else 2} Material 1 Position "
                     f"{p[0]:.6f} {p[1]:.6f} {p[2]:.6f} Velocity {v[0]:.4f} {v[1]:.4f} 0")
    return ("""Environment
  Gravity 0 0 -9.81
  Periodic X 0 0.04 Y 0 0.04
Materials
  Material 1 Density 2700
Shapes
  Shape 1 Sphere Radius 0.005
  Shape 2 Ellipsoid SemiAxes 0.0055 0.0045 0.004
Particles
""" + "\n".join(lines) + """
Walls
  Wall 1 Name floor Point 0.02 0.02 0 Normal 0 0 1 Size 0.08 0.08
  Wall 2 Name lid Point 0.02 0.02 0.045 Normal 0 0 -1 Size 0.08 0.08
Contact
  Interface 1 NormalPenalty 1e5 TangentialPenalty 1e4 NormalDamping 1 Friction 0.5
Steps
  Step 1 Dynamic Duration 0.02 TimeStep 1e-3
  Step 2 MoveWall lid Displacement 0 0 -0.022 Duration 0.02 TimeStep 1e-3
Output
  Directory results
  VTK Every 0.02 Resolution 3
  Monitors Every 0.002
  Results Every 0.01
""")


@pytest.mark.parametrize("damping", ["explicit", "implicit"])
def test_a_periodic_cell_gives_the_same_bits_on_the_compiled_loop(tmp_path, monkeypatch,
                                                                  damping):
    """With ``Damping Implicit`` too: the dashpots solved over the network in which an image
    is its owner (nurbsdem.dynamics.implicit.implicit_dashpots)."""
    used = _counting_steps(monkeypatch)
    wraps, images = [], []
    apply_wrap, of = internal_step.InternalSteps._apply_wrap, images_module.ImageBodies.of

    def counting_wrap(self, cs):
        shift = getattr(cs, "wrap", None)
        wraps.append(shift is not None and len(shift) > 0 and bool(np.any(shift != 0.0)))
        apply_wrap(self, cs)

    def counting_images(n, b, image):
        im = of(n, b, image)
        images.append(im is not None)
        return im
    monkeypatch.setattr(internal_step.InternalSteps, "_apply_wrap", counting_wrap)
    monkeypatch.setattr(images_module.ImageBodies, "of", staticmethod(counting_images))
    deck = _periodic_deck()
    if damping == "implicit":
        deck = deck.replace("TimeStep 1e-3\n", "TimeStep 1e-3 Damping Implicit\n")
        assert deck.count("Damping Implicit") == 2
    (py, s_py), (cc, s_cc) = _both_paths(tmp_path, "cell.inp", deck)
    assert not any(used[:s_py.steps]) and all(used[s_py.steps:])    # Python, then compiled
    assert sum(wraps) >= 3 and sum(images) >= 20       # the Python run crossed the faces
    _same_bits(py, cc, s_py, s_cc, ("energy.csv", "contacts.csv", "wall_lid.csv"))
    assert s_cc.active_max >= 3
