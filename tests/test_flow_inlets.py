"""Inlets in runs (nurbsdem.flow_run, nurbsdem.dynamics.flow): a disc inlet places every
centroid in its disc; after timed steps of known duration an inlet has inserted
floor(Rate × t) particles, counted from each step's start, and inlets and outlets exchange
particles at each step's end; a pour of NURBS particles places them without overlap (the
exact contact test), accounts for every particle and keeps the energy balance closed."""
from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
from nurbsdem import Simulation, shapes
from nurbsdem.dynamics.flow import InsertionRegion, Inlet
from nurbsdem.flow_run import FlowRun
from nurbsdem.geometry.rotation import quat_to_matrix
from nurbsdem.validation import pair_penetration

ROOT = Path(__file__).resolve().parents[1]
PAPER_SHAPE = ROOT / "inputs" / "shapes" / "C.yaml"        # the paper's smallest


def rows(path: Path) -> list[dict[str, float]]:
    with open(path) as fh:
        return [{k: float(v) for k, v in r.items()} for r in csv.DictReader(fh)]


def spy_insertions(monkeypatch) -> list:
    """(bodies present, bodies added) of every exchange of the run."""
    seen = []
    original = FlowRun.insert

    def spy(self, t, bodies):
        added = original(self, t, bodies)
        seen.append((bodies.copy(), added.copy()))
        return added
    monkeypatch.setattr(FlowRun, "insert", spy)
    return seen


def scene(tmp_path: Path, gravity=(0, 0, -9.81)) -> Simulation:
    sim = Simulation(gravity=gravity, output=tmp_path / "out", quiet=True)
    sim.add_material(1, density=2500.0)
    sim.add_interface(normal_penalty=1e4, normal_damping=0.5, tangential_penalty=1e4,
                      friction=0.3)
    return sim


# ---------------------------------------------------------------------------- discs

#: the disc tests' tolerance (m): a centroid lies in the disc's plane and within R - r of its
#: axis (its bounding sphere inside the rim) up to the round-off of the sampling
DISC_TOL = 1e-12


def test_a_disc_inlet_places_every_centroid_in_its_disc(tmp_path, monkeypatch):
    seen = spy_insertions(monkeypatch)
    r, big_r = 0.003, 0.02
    centre, normal = np.array([0.03, 0.03, 0.1]), np.array([0.2, 0.1, 1.0])
    sim = scene(tmp_path)
    sim.add_box((0, 0, 0), (0.06, 0.06, 0.15))
    sim.add_inlet([shapes.sphere(r)], 1, None, rate=1000, count=25, velocity=(0, 0, -1),
                  seed=5, name="shower", disc=centre, normal=normal, radius=big_r)
    sim.run_dynamic(0.03, 1e-3)
    sim.close()
    added = np.concatenate([a.position for _, a in seen])
    assert len(added) == 25
    n = normal / np.linalg.norm(normal)
    axial = (added - centre) @ n
    radial = np.linalg.norm(added - centre - axial[:, None] * n, axis=1)
    assert np.all(np.abs(axial) <= DISC_TOL)
    assert np.all(radial <= big_r - r + DISC_TOL)
    assert radial.max() > 0.5 * (big_r - r)               # spread over the disc, not a point


def test_a_thick_disc_keeps_each_bounding_sphere_inside():
    radii = np.array([0.004, 0.002])
    region = InsertionRegion(centre=np.array([0.0, 0.0, 1.0]), axis=np.array([1.0, -1.0, 2.0]),
                             radius=0.05, thickness=0.02)
    inlet = Inlet(region, np.array([1, 2]), np.array([0.5, 0.5]), radii, np.ones(2), 2000.0,
                  count=60, seed=1)
    new = inlet.insert(1.0, np.zeros((0, 3)), np.zeros(0))
    assert len(new.shapes) == 60
    r = radii[np.searchsorted(inlet.shapes, new.shapes)]
    n = region.axis / np.linalg.norm(region.axis)
    axial = (new.positions - region.centre) @ n
    radial = np.linalg.norm(new.positions - region.centre - axial[:, None] * n, axis=1)
    assert np.all(np.abs(axial) <= 0.5 * region.thickness - r + DISC_TOL)
    assert np.all(radial <= region.radius - r + DISC_TOL)


# ---------------------------------------------------------------------------- timing


def test_counts_follow_each_step_and_the_exchange_happens_at_the_step_end(tmp_path):
    """No gravity: particles fall at 2 m/s through an outlet plane 4 mm under the inlet's
    box, so that some cross it between the last segment end (10 ms) and the end of the
    13 ms step."""
    rate = 2000.0
    sim = scene(tmp_path, gravity=(0, 0, 0))
    sim.add_inlet([shapes.sphere(0.004)], 1, (0.0, 0.0, 0.04, 0.06, 0.06, 0.07), rate=rate,
                  count=200, velocity=(0, 0, -2), seed=3, every=0.005, name="feed")
    sim.add_outlet(point=(0, 0, 0.04), normal=(0, 0, -1), every=0.005, name="sink")
    sim.run_dynamic(0.013, 1e-3)
    first = sim.bodies
    sim.run_dynamic(0.007, 1e-3)
    second = sim.bodies
    sim.close()
    inlet = rows(tmp_path / "out" / "monitors" / "inlet_feed.csv")
    outlet = rows(tmp_path / "out" / "monitors" / "outlet_sink.csv")
    at = {round(r["time"], 9): r for r in inlet}
    out_at = {round(r["time"], 9): r for r in outlet}
    assert sorted(at) == [0.005, 0.01, 0.013, 0.018, 0.02]     # segments restart each step
    for t in at:
        assert abs(at[t]["inserted"] - math.floor(rate * t + 1e-9)) <= 1
    assert at[0.013]["inserted"] == 26 and at[0.02]["inserted"] == 40
    assert out_at[0.013]["count"] > out_at[0.01]["count"]     # removed at the step's end
    for bodies, t in ((first, 0.013), (second, 0.02)):
        assert not np.any(bodies.position[:, 2] < 0.04)       # none left beyond the plane
        assert len(bodies) + out_at[t]["count"] == at[t]["inserted"]


def test_a_rate_counts_on_from_each_step_start_with_what_it_owed():
    """A fraction of a particle owed at a step's end stays owed: 1.5 particles per 10 ms
    step make 3 after two steps, not 2; waiting particles stay owed the same way."""
    inlet = Inlet(InsertionRegion(lo=np.zeros(3), hi=np.ones(3)), np.array([1]),
                  np.array([1.0]), np.array([0.01]), np.array([1.0]), 150.0, count=100)
    inlet.restart_clock(0.0)
    assert inlet.due(0.01) == 1
    inlet.inserted = 1
    inlet.restart_clock(0.01)
    assert inlet.due(0.02) == 2 and inlet.owed_total(0.02) == 3
    inlet.restart_clock(0.02)                 # the 2 not inserted wait into the next step
    assert inlet.due(0.02) == 2 and inlet.due(0.03) == 3


# ---------------------------------------------------------------------------- NURBS pour


def nurbs_pour(tmp_path: Path, monkeypatch, count: int, duration: float):
    seen = spy_insertions(monkeypatch)
    sim = scene(tmp_path)
    sim.add_box((0, 0, 0), (0.2, 0.2, 0.4))
    sim.add_inlet([PAPER_SHAPE], 1, (0.0, 0.0, 0.2, 0.2, 0.2, 0.4), rate=400, count=count,
                  velocity=(0, 0, -1.5), seed=2, every=0.01, name="feed")
    sim.add_outlet(box=(0, 0, 0, 0.1, 0.2, 0.03), every=0.01, name="floor")
    sim.run_dynamic(duration, 1e-3)
    bodies = sim.bodies
    shape = sim.model.shapes[1].shape
    sim.close()
    return seen, bodies, shape


def assert_pour_accounted(tmp_path, seen, bodies, shape, count):
    for present, added in seen:
        everyone = [present, added]
        x = np.concatenate([b.position for b in everyone])
        q = np.concatenate([b.quaternion for b in everyone])
        for i in range(len(present), len(x)):
            for j in range(i):
                depth = pair_penetration(shape, x[i], quat_to_matrix(q[i]),
                                         shape, x[j], quat_to_matrix(q[j]))
                assert depth <= 0.0, (i, j, depth)
    inlet = rows(tmp_path / "out" / "monitors" / "inlet_feed.csv")
    outlet = rows(tmp_path / "out" / "monitors" / "outlet_floor.csv")
    assert inlet[-1]["inserted"] == count and inlet[-1]["waiting"] == 0
    assert len(bodies) + outlet[-1]["count"] == inlet[-1]["inserted"]
    energy = rows(tmp_path / "out" / "monitors" / "energy.csv")
    scale = max(abs(e["external_work"]) + abs(e["kinetic"]) for e in energy)
    # closed to 0.1 % of the energy moved at the end; while particles strike the floor at
    # ~2 m/s the normal springs' discrete work and the change of their potential differ by
    # the O(h²) of the integrator (nurbsdem/dynamics/energy.py): a transient of a few 0.1 %
    assert abs(energy[-1]["balance_error"]) < 1e-3 * scale
    assert max(abs(e["balance_error"]) for e in energy) < 3e-3 * scale
    return outlet


def test_a_pour_of_nurbs_particles_places_them_apart_and_accounts_for_them(
        tmp_path, monkeypatch):
    seen, bodies, shape = nurbs_pour(tmp_path, monkeypatch, 12, 0.25)
    outlet = assert_pour_accounted(tmp_path, seen, bodies, shape, 12)
    assert outlet[-1]["count"] > 0 and len(bodies) > 0      # some left through the floor
