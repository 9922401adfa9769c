"""postproc/paraview_view.py renders a real run with the real ParaView (``pvpython``).

A small deck (two spheres and an ellipsoid, three shapes, resting in a box: particle-particle
and particle-wall contacts) is solved, then ``pvpython postproc/paraview_view.py DIR --png``
renders it offscreen (under ``xvfb-run`` when there is no display). The PNG must be a real
picture: the requested size, many colours, and each shape's colour (the script's
``PALETTE``) on the particles, outside the legend. Skipped, saying why, where ParaView is not
installed (Debian: ``apt-get install python3-paraview xvfb``; ``.ci/run`` installs both).
"""
from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "postproc" / "paraview_view.py"
WIDTH, HEIGHT = 640, 480

DECK = """\
Environment
  Gravity 0 0 -9.81
Materials
  Material 1 Density 2700
Shapes
  Shape 1 Sphere Radius 0.012
  Shape 2 Ellipsoid SemiAxes 0.016 0.011 0.008
  Shape 3 Sphere Radius 0.016
Particles
  Particle 1 Shape 1 Material 1 Position 0.03 0.03 0.01205
  Particle 2 Shape 2 Material 1 Position 0.07 0.03 0.00805
  Particle 3 Shape 3 Material 1 Position 0.06 0.07 0.01605
  Particle 4 Shape 1 Material 1 Position 0.03 0.031 0.0361
Walls
  Box 1 Min 0 0 0 Max 0.11 0.11 0.08
Contact
  Interface 1 NormalPenalty 1e5 TangentialPenalty 1e4 NormalDamping 1e2 TangentialDamping 0 Friction 0.5
Steps
  Step 1 Dynamic Duration 0.02 TimeStep 1e-3
Output
  Directory results
  VTK Every 0.01 Resolution 6
  Monitors Every 0.001
"""


@pytest.fixture(scope="module")
def pvpython() -> list[str]:
    """The command prefix that runs pvpython with a display, or skip saying what is missing."""
    pv = shutil.which("pvpython")
    if pv is None:
        pytest.skip("ParaView's pvpython is not installed (Debian: apt-get install "
                    "python3-paraview xvfb; .ci/run installs both when it can)")
    if os.environ.get("DISPLAY"):
        return [pv]
    xvfb = shutil.which("xvfb-run")
    if xvfb is None:
        pytest.skip("no display and no xvfb-run to render offscreen (apt-get install xvfb)")
    return [xvfb, "-a", "-s", "-screen 0 1280x1024x24", pv]


def _palette() -> list[tuple[float, float, float]]:
    """The script's PALETTE (read from its source: the script needs ParaView to import)."""
    for node in ast.parse(SCRIPT.read_text()).body:
        if isinstance(node, ast.Assign) and getattr(node.targets[0], "id", "") == "PALETTE":
            return [tuple(c) for c in ast.literal_eval(node.value)]
    raise AssertionError("PALETTE not found in postproc/paraview_view.py")


def _hsv(rgb: np.ndarray) -> np.ndarray:
    from matplotlib.colors import rgb_to_hsv
    return rgb_to_hsv(np.clip(rgb, 0.0, 1.0))


@pytest.fixture(scope="module")
def results(tmp_path_factory) -> Path:
    """A solved run of DECK (≈ 4 s)."""
    tmp = tmp_path_factory.mktemp("paraview")
    deck = tmp / "scene.inp"
    deck.write_text(DECK)
    out = tmp / "results"
    p = subprocess.run([sys.executable, "-m", "nurbsdem", "solve", str(deck), "--output",
                        str(out), "--quiet"], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    for name in ("particles.pvd", "walls.pvd", "contacts.pvd"):
        assert (out / name).is_file(), name
    return out


def test_paraview_renders_png(pvpython, results, tmp_path):
    pytest.importorskip("matplotlib", reason="reading the PNG needs matplotlib (the plot extra)")
    import matplotlib.image as mpimg

    cmd = pvpython
    png = tmp_path / "view.png"
    for attempt in range(2):
        p = subprocess.run(cmd + [str(SCRIPT), str(results), "--png", str(png), "--size",
                                  str(WIDTH), str(HEIGHT)],
                           capture_output=True, text=True, timeout=300, cwd=tmp_path)
        # the X server of ``xvfb-run -a`` occasionally fails to start (a display-number
        # race with another xvfb-run on the machine): one retry
        log = p.stdout + p.stderr
        if p.returncode == 0 or not ("OpenGLRenderWindow" in log or "xvfb-run: error" in log):
            break
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    assert png.is_file(), p.stdout[-3000:] + p.stderr[-3000:]
    assert png.stat().st_size > 10_000

    img = mpimg.imread(png)[..., :3]
    assert img.shape[:2] == (HEIGHT, WIDTH)
    colours = np.unique((img.reshape(-1, 3) * 255).round().astype(np.int64), axis=0)
    assert len(colours) > 200, f"only {len(colours)} distinct colours: not a rendered scene"

    # each shape's colour on the particles: the legend (upper right) is cut away first
    scene = _hsv(img[:, : int(0.75 * WIDTH)]).reshape(-1, 3)
    palette = _palette()
    for sid in (1, 2, 3):
        h, s, _ = _hsv(np.array(palette[sid - 1]))
        dh = np.abs(scene[:, 0] - h)
        dh = np.minimum(dh, 1.0 - dh)
        hits = int(np.count_nonzero((dh < 0.03) & (scene[:, 1] > 0.3 * s)))
        assert hits > 300, f"shape {sid}: {hits} pixels of its colour {palette[sid - 1]}"
