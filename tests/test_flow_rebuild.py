"""A system built anew at an exchange of particles: the rows of its particles formed from
per-kind arrays (:func:`nurbsdem.dynamics.rigid.kind_rows`, what
:meth:`~nurbsdem.system_assembly.SystemAssembly.system` uses) equal those formed from one
mapping per particle (:func:`~nurbsdem.dynamics.rigid.particle_rows`) bit for bit; an
exchange that removes and inserts nothing builds no system."""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from nurbsdem import Simulation, shapes
from nurbsdem.dynamics import DemSystem
from nurbsdem.dynamics.rigid import kind_rows, particle_rows
from nurbsdem.flow_run import FlowRun
from nurbsdem.solver import Solver


def _kinds(rng):
    """Three kinds: masses (kg), inertia tensors (kg m², general, not principal), centroids
    (m), materials, bounding radii (m), compliances (1/kg)."""
    out = []
    for k in range(3):
        P = Rotation.random(random_state=10 + k).as_matrix()
        J0 = P @ np.diag(np.sort(rng.uniform(1.0, 2.0, 3)) * 1e-6) @ P.T
        out.append(dict(mass=rng.uniform(0.01, 0.1), J0=J0, centroid_file=rng.normal(size=3),
                        material=k % 2, radius=rng.uniform(0.001, 0.01),
                        compliance=(rng.uniform(10, 20), rng.uniform(20, 40))))
    return out


def test_kind_rows_equal_particle_rows_bit_for_bit():
    rng = np.random.default_rng(4)
    kinds = _kinds(rng)
    n = 200
    kind = rng.integers(0, 3, n)
    R = Rotation.random(n, random_state=5).as_matrix()
    x, v, w = rng.normal(size=(n, 3)), rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    each = [dict({k: val for k, val in kinds[kind[i]].items() if k != "compliance"},
                 R=R[i], x=x[i], v=v[i], omega=w[i]) for i in range(n)]
    old = particle_rows(each)
    new = kind_rows(kind, np.array([k["mass"] for k in kinds]),
                    np.array([k["J0"] for k in kinds]),
                    np.array([k["centroid_file"] for k in kinds]),
                    np.array([k["material"] for k in kinds]),
                    np.array([k["radius"] for k in kinds]), R, x, v, w)
    assert old.keys() == new.keys()
    for key in old:
        assert old[key].dtype == new[key].dtype and np.array_equal(old[key], new[key]), key

    a, b = DemSystem(dt=1e-3), DemSystem(dt=1e-3)
    a.add_particles([dict(kinds[kind[i]], R=R[i], x=x[i], v=v[i], omega=w[i])
                     for i in range(n)])
    b.add_particle_kinds(kind, kinds, R, x, v, w)
    assert a._compliance == b._compliance
    for key in ("mass", "J0", "I", "P", "q", "L", "x", "v", "radius", "material"):
        assert np.array_equal(getattr(a.bodies, key), getattr(b.bodies, key)), key


def _box(folder):
    """A simulation of a box 50 mm square with one material and interface, no particles."""
    sim = Simulation(gravity=(0, 0, -9.81), output=folder / "out", quiet=True)
    sim.add_material(1, density=2500.0)
    sim.add_interface(normal_penalty=1e4, normal_damping=0.5, tangential_penalty=1e4,
                      friction=0.3)
    sim.add_box((0, 0, 0), (0.05, 0.05, 0.15))
    return sim


def test_an_exchange_with_nothing_to_exchange_builds_no_system(tmp_path, monkeypatch):
    added, rebuilt = [], []
    insert, rebuild = FlowRun.insert, Solver.rebuild

    def spy_insert(self, t, bodies):
        new = insert(self, t, bodies)
        added.append(len(new))
        return new

    def spy_rebuild(self, *args):
        rebuilt.append(len(self.bodies))
        return rebuild(self, *args)
    monkeypatch.setattr(FlowRun, "insert", spy_insert)
    monkeypatch.setattr(Solver, "rebuild", spy_rebuild)
    sim = _box(tmp_path)
    sim.add_inlet([shapes.sphere(0.004)], 1, (0.004, 0.004, 0.1, 0.046, 0.046, 0.12),
                  rate=1000, count=6, seed=2, every=0.002, name="feed")
    sim.add_outlet((0, 0, -1, 1, 1, -0.5), every=0.002, name="never")
    sim.run_dynamic(0.012, 1e-3)
    sim.close()
    assert len(added) == 6 and added.count(0) == 3       # three exchanges of nothing
    assert rebuilt == [2, 4, 6]                          # a system only for the others


def test_a_rebuilt_system_goes_on_with_the_last_ones_time_step_control(tmp_path, monkeypatch):
    """A system built at an exchange takes over the last one's sub-steps, refinement and
    estimates, and takes the exact (Lanczos) estimate again only where the gate asks for it
    (:meth:`~nurbsdem.dynamics.substep_control.SubstepControl._first_control_step`)."""
    seen = []
    rebuild = Solver.rebuild

    def spy_rebuild(self, t0, step_count, warned, control=None):
        rebuild(self, t0, step_count, warned, control)
        s = self.system
        seen.append((control, s.network_estimates, s.control_state()))
    monkeypatch.setattr(Solver, "rebuild", spy_rebuild)
    sim = _box(tmp_path)
    sim.add_inlet([shapes.sphere(0.004)], 1, (0.004, 0.004, 0.02, 0.046, 0.046, 0.12),
                  rate=4000, count=40, seed=2, every=0.002, name="feed")
    sim.run_dynamic(0.04, 1e-3)
    sim.close()
    assert len(seen) >= 5 and all(c is not None for c, _, _ in seen)
    for control, estimates, state in seen:
        if state[3] < control[3]:        # a smaller a-priori step (here: the first particles)
            assert estimates == 1                        # a fresh start
            continue
        assert state[1:3] == control[1:3]                # the guard's refinement goes on
        if estimates == 0:                               # the gate let the count stand
            assert state == control
    assert sum(e == 0 for _, e, _ in seen) >= 2          # the saving the carry-over is for


def _pour_with_rebuilds(folder, monkeypatch, carry: bool):
    """A pour of 40 spheres into a box, each rebuild's first evaluation's solved pairs and
    listed pairs recorded; with ``carry`` False the new scenes start cold."""
    import nurbsdem.flow_run as flow_run
    seen = []
    rebuild = Solver.rebuild

    def spy_rebuild(self, *args):
        rebuild(self, *args)
        seen.append((self.scene.timers.lcps, len(self.scene.pairs.keys)))
    monkeypatch.setattr(Solver, "rebuild", spy_rebuild)
    if not carry:
        monkeypatch.setattr(flow_run, "_carried_rows", lambda *args: None)
    sim = _box(folder)
    sim.add_inlet([shapes.sphere(0.004)], 1, (0.004, 0.004, 0.02, 0.046, 0.046, 0.12),
                  rate=4000, count=40, seed=2, every=0.002, name="feed")
    sim.run_dynamic(0.03, 1e-3)
    bodies = sim.bodies
    sim.close()
    return seen, bodies


def test_a_rebuilt_scene_starts_from_the_last_ones_rows_and_certificates(tmp_path,
                                                                          monkeypatch):
    """At an exchange the new scene takes the listed pairs' last rows and certificates with
    the bodies' odometers (:func:`nurbsdem.flow_run._carried_rows`): its first evaluation
    solves only the pairs that are due, where a cold scene solves every listed pair; exact
    spheres' rows are closed forms, so the run agrees with the cold one to round-off (not to
    the bit: a certified pair's gap is a lower bound, and the gaps feed the step control)."""
    warm, end_warm = _pour_with_rebuilds(tmp_path / "warm", monkeypatch, True)
    monkeypatch.undo()
    cold, end_cold = _pour_with_rebuilds(tmp_path / "cold", monkeypatch, False)
    assert len(warm) == len(cold) >= 5
    assert all(solved == listed for solved, listed in cold)
    assert sum(s for s, _ in warm) < 0.8 * sum(s for s, _ in cold)
    np.testing.assert_allclose(end_warm.position, end_cold.position, rtol=0, atol=1e-12)
    np.testing.assert_allclose(end_warm.velocity, end_cold.velocity, rtol=0, atol=1e-10)
