"""inputs/heap/heap.inp, in a short version (16 of the paper's particles poured in 0.4 s, then
0.2 s): every particle the inlet creates is accounted for (on the floor or taken by the
outlet below it), the energy balance stays closed, and the angle of repose can be measured
from results.h5."""
from __future__ import annotations

import sys
from pathlib import Path

import h5py
import numpy as np

from nurbsdem.simulation import Simulation

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "postproc"))
from repose import angle_of_repose  # noqa: E402

COUNT = 16


def _csv(path: Path) -> np.ndarray:
    return np.genfromtxt(path, delimiter=",", names=True)


def test_a_short_heap_accounts_for_every_particle(tmp_path):
    text = (ROOT / "inputs" / "heap" / "heap.inp").read_text()
    for old, new in (("Count 200", f"Count {COUNT}"), ("Rate 40", "Rate 60"),
                     ("../shapes/", str(ROOT / "inputs" / "shapes") + "/"),
                     ("Step 1 Dynamic Duration 5.0", "Step 1 Dynamic Duration 0.4"),
                     ("Step 2 Dynamic Duration 1.0", "Step 2 Dynamic Duration 0.2")):
        assert old in text, old
        text = text.replace(old, new)
    deck = tmp_path / "heap.inp"
    deck.write_text(text)
    out = tmp_path / "out"
    Simulation.from_deck(deck, output=out).run()
    feed, off = _csv(out / "monitors" / "inlet_feed.csv"), _csv(out / "monitors" / "outlet_off.csv")
    with h5py.File(out / "results.h5") as f:
        count, pos = f["count"][:], f["position"][:]
        last = pos[f["offset"][-2]:f["offset"][-1]]
    assert feed["inserted"][-1] == COUNT
    assert count[-1] + off["count"][-1] == COUNT
    assert np.all(last[:, 2] > 0.0)                          # on the floor's side
    energy = _csv(out / "monitors" / "energy.csv")
    turned = np.abs(energy["external_work"]).max() + np.abs(energy["potential"]).max()
    assert np.abs(energy["balance_error"]).max() < 1e-3 * turned
    rep = angle_of_repose(last, 0.034, axis=(0.0, 0.0), rings=4, inner=0.0, outer=1.0)
    assert np.isfinite(rep.angle)
