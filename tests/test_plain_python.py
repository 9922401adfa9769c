"""``NUMBA_DISABLE_JIT=1`` runs a deck as plain Python, through the same code: the compiled
time loop (:func:`~nurbsdem.dynamics.deck_steps.run_deck_steps`) and every kernel it calls,
with the same results to the bit as the compiled run."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np

from nurbsdem.io.shapefile import save_shape
from nurbsdem.shapes import paper_particle

#: two of the paper's particles falling on each other and on the floor, an exact sphere
#: rolling on it: NURBS–NURBS (LCP), NURBS–wall and sphere–wall contacts, ``Damping
#: Implicit`` with ``Accuracy`` as in the paper's example
DECK = """Environment
  Gravity 0 0 -9.81
Materials
  Material 1 Density 2700
Shapes
  Shape 1 File A.yaml
  Shape 2 File B.yaml
  Shape 3 Sphere Radius 0.02
Particles
  Particle 1 Shape 1 Material 1 Position 0.06 0.06 0.0285 Velocity 0 0 -0.2
  Particle 2 Shape 2 Material 1 Position 0.062 0.06 0.0815 Velocity 0 0 -0.5
  Particle 3 Shape 3 Material 1 Position 0.17 0.17 0.0199 AngularVelocity 0 3 0
Walls
  Box 1 Min 0 0 0 Max 0.25 0.25 0.40
Contact
  Interface 1 NormalPenalty 1e5 TangentialPenalty 1e4 NormalDamping 1e2 TangentialDamping 0 Friction 0.5
Steps
  Step 1 Dynamic Duration 0.012 TimeStep 1e-3 Damping Implicit Accuracy 3e-5 Safety 0.7
Output
  Directory {out}
  VTK Every 0.006 Resolution 4
  Monitors Every 0.001
"""

#: solves the deck given as argv[1], counting the calls of the compiled loop's function
RUN = """
import sys
from nurbsdem.cli import main
from nurbsdem.dynamics import deck_steps
calls = [0]
loop = deck_steps.run_deck_steps
def counted(*args):
    calls[0] += 1
    return loop(*args)
deck_steps.run_deck_steps = counted
main(["solve", sys.argv[1], "--quiet"], standalone_mode=False)
print("loop calls", calls[0])
"""


def _solve(folder: Path, plain: bool) -> tuple[Path, int]:
    """Solve the deck in ``folder`` (plain Python when ``plain``); its output folder and the
    number of calls of the time loop."""
    out = folder / ("plain" if plain else "compiled")
    deck = folder / f"{out.name}.inp"
    deck.write_text(DECK.format(out=out))
    env = dict(os.environ)
    env.pop("NUMBA_DISABLE_JIT", None)
    if plain:
        env["NUMBA_DISABLE_JIT"] = "1"
    run = subprocess.run([sys.executable, "-c", RUN, str(deck)], env=env, capture_output=True,
                         text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    return out, int(run.stdout.split("loop calls")[-1])


def test_a_deck_runs_as_plain_python_with_the_compiled_runs_bits(tmp_path):
    for kind in "AB":
        save_shape(tmp_path / f"{kind}.yaml", paper_particle(kind), name=kind)
    plain, plain_calls = _solve(tmp_path, plain=True)
    compiled, compiled_calls = _solve(tmp_path, plain=False)
    assert plain_calls > 0 and compiled_calls > 0        # the same loop, in both
    contacts = np.loadtxt(plain / "monitors" / "contacts.csv", delimiter=",", skiprows=1)
    assert contacts[:, 2].max() >= 2                      # contacts carried loads
    monitors = sorted(p.relative_to(plain) for p in (plain / "monitors").glob("*.csv"))
    assert len(monitors) >= 6
    for name in monitors:
        assert (plain / name).read_bytes() == (compiled / name).read_bytes(), name
    with h5py.File(plain / "results.h5") as a, h5py.File(compiled / "results.h5") as b:
        for key in ("position", "quaternion", "velocity", "angular_velocity"):
            assert np.array_equal(a[key][...], b[key][...]), key
