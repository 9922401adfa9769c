"""System level: time-step control and sub-stepping, instability guard, energy balance order,
prescribed walls (reaction, external work), checkpoints and determinism."""
from __future__ import annotations

import logging
import math

import numpy as np
import pytest

from nurbsdem.dynamics import (ContactLaw, DemSystem, InstabilityError, InterfaceTable,
                               PrescribedMotion, SpherePlaneProvider, critical_step,
                               sphere_inertia)
from nurbsdem.errors import InputError

PAPER = ContactLaw(en=1e5, cn=1e2, et=1e4, ct=0.0, mu=0.5)
RHO = 2700.0
VOL = {"A": 98.57e-6, "B": 50.47e-6, "C": 21.29e-6}
MASS = {k: RHO * v for k, v in VOL.items()}
RADIUS = {k: (3 * v / (4 * math.pi)) ** (1 / 3) for k, v in VOL.items()}
BOX = 0.25
PLANES = [([0, 0, 0], [0, 0, 1]), ([0, 0, 0], [1, 0, 0]), ([BOX, 0, 0], [-1, 0, 0]),
          ([0, 0, 0], [0, 1, 0]), ([0, BOX, 0], [0, -1, 0])]


def paper_box(substeps=None, n=6, dt=1e-3, law=PAPER, seed=3, kinds="C", implicit=False):
    """n analytic spheres with the paper's particle masses in the paper's box (no lid);
    implicit: implicit normal dashpots."""
    s = DemSystem(dt=dt, interfaces=InterfaceTable(default=law), substeps=substeps,
                  implicit_damping=implicit)
    rng = np.random.default_rng(seed)
    radii = []
    for i in range(n):
        k = kinds[i % len(kinds)]
        x = [0.04 + 0.085 * (i % 3), 0.06 + 0.12 * ((i // 3) % 2), 0.03 + 0.05 * i]
        s.add_particle(MASS[k], sphere_inertia(MASS[k], RADIUS[k]), x, v=rng.uniform(-0.3, 0.3, 3),
                       radius=RADIUS[k])
        radii.append(RADIUS[k])
    for _ in PLANES:
        s.add_wall()
    s.set_contact_provider(SpherePlaneProvider(radii, PLANES))
    return s


def test_critical_steps_match_the_digest_table():
    mC, mA = MASS["C"], MASS["A"]
    assert critical_step(1e5, 1e2, mC / 2)[2] == pytest.approx(4.7e-4, rel=0.01)
    assert critical_step(1e5, 0.0, mC / 2)[2] == pytest.approx(1.07e-3, rel=0.01)
    assert critical_step(1e5, 1e2, mC)[2] == pytest.approx(8.2e-4, rel=0.01)
    assert critical_step(1e5, 1e2, mA / 2)[2] == pytest.approx(1.5e-3, rel=0.02)
    s = paper_box(kinds="AC")
    dt_cr, limits = s.critical_time_step()
    assert dt_cr == pytest.approx(4.66e-4, rel=0.01)
    worst = min(limits, key=lambda m: m.dt_cr)
    assert worst.mode == "normal" and worst.interface == (0, 0, "pp")


def test_paper_step_is_substepped_and_stable_but_blows_up_without_substeps(caplog):
    with caplog.at_level(logging.INFO, logger="nurbsdem"):
        s = paper_box()
        s.initialize()
    assert s.substeps == 5 and s.dt_internal == pytest.approx(2e-4)
    assert any("5 sub-step(s)" in r.getMessage() for r in caplog.records)
    e = s.advance(500)
    assert np.isfinite(s.bodies.x).all() and e.kinetic < 0.05 * e.initial_mechanical
    assert abs(e.balance_error) < 0.02 * e.dissipated

    bad = paper_box(substeps=1)
    with pytest.raises(InstabilityError) as info:
        bad.advance(500)
    err = info.value
    assert "unstable" in str(err) and "critical step" in str(err)
    # rolled back to the last good state, which is bit-for-bit that of a run stopped there
    assert bad.time == pytest.approx(err.time) and np.isfinite(bad.bodies.x).all()
    ref = paper_box(substeps=1)
    ref.advance(bad.step_count)
    st_bad, st_ref = bad.get_state(), ref.get_state()
    for k in st_ref:
        assert np.array_equal(st_bad[k], st_ref[k]), k


def _oblique_impact(sub):
    m, r = 0.1, 0.02
    law = ContactLaw(en=1e5, cn=20.0, et=2e4, ct=0.5, mu=0.3)
    s = DemSystem(dt=1e-3, interfaces=InterfaceTable(default=law), substeps=sub)
    s.add_particle(m, sphere_inertia(m, r), [0, 0, r + 1e-3], v=[0.8, 0.3, -1.0],
                   omega=[5.0, -20.0, 3.0], radius=r)
    s.add_wall()
    s.set_contact_provider(SpherePlaneProvider([r], [([0, 0, 0], [0, 0, 1])]))
    return s


def test_energy_balance_error_is_second_order():
    errs = []
    for sub in (8, 16, 32):
        s = _oblique_impact(sub)
        e = s.advance(60)
        assert e.dissipated_normal > 0 and e.dissipated_friction > 0 and e.dissipated_tangential > 0
        errs.append(abs(e.balance_error) / e.dissipated)
    assert errs[-1] < 1e-3
    assert errs[0] / errs[1] > 3.0 and errs[1] / errs[2] > 3.0


def test_prescribed_lid_reaction_and_external_work():
    m, r, g = 0.1, 0.02, 9.81
    law = ContactLaw(en=1e5, cn=30.0, et=1e4, mu=0.5)
    s = DemSystem(dt=1e-4, interfaces=InterfaceTable(default=law))
    s.add_particle(m, sphere_inertia(m, r), [0, 0, r - m * g / 1e5], radius=r)
    s.add_wall()
    lid_motion = PrescribedMotion.piecewise_linear([0.0, 0.2, 0.4], [[0, 0, 0], [0, 0, -2e-3],
                                                                     [0, 0, -2e-3]])
    lid = s.add_wall(lid_motion)
    assert lid == 2
    s.set_contact_provider(SpherePlaneProvider([r], [([0, 0, 0], [0, 0, 1]),
                                                     ([0, 0, 2 * r + 1e-3], [0, 0, -1])]))
    s.advance(6000)
    e = s.energy()
    # static equilibrium: lid pushes down by F, floor carries F + mg; penetrations share 1 mm
    F = 1e5 * (1e-3 - m * g / 1e5) / 2
    assert s.wall_reaction[1] == pytest.approx([0, 0, -F], abs=1e-6 * F)
    assert s.wall_contact_force[0] == pytest.approx([0, 0, -(F + m * g)], abs=1e-6 * F)
    assert s.wall_work[1] == pytest.approx(e.external_work)
    assert e.external_work > 0
    assert abs(e.balance_error) < 1e-3 * e.external_work
    # the stored energy cannot exceed the work input
    assert e.elastic <= e.external_work + (e.initial_mechanical - e.potential)


def assert_restart_bit_for_bit(make, n: int, tmp_path) -> None:
    """A system from ``make()`` run 2n deck steps equals one run n steps, saved to an .npz
    file, restored into a fresh ``make()`` and run n more: state and energies bit for bit."""
    ref = make()
    ref.advance(2 * n)
    a = make()
    a.advance(n)
    assert a.hist_keys.size > 0            # tangential histories are part of the state
    np.savez(tmp_path / "ck.npz", **a.get_state())
    b = make()
    with np.load(tmp_path / "ck.npz") as f:
        b.set_state({k: f[k] for k in f.files})
    b.advance(n)
    sr, sb = ref.get_state(), b.get_state()
    for k in sr:
        assert np.array_equal(sr[k], sb[k]), k
    assert ref.energy() == b.energy()


def test_checkpoint_restore_continues_bit_for_bit(tmp_path):
    assert_restart_bit_for_bit(
        lambda: paper_box(law=ContactLaw(en=1e5, cn=1e2, et=1e4, ct=0.1, mu=0.5)), 120, tmp_path)


def test_history_is_dropped_when_the_contact_ends():
    s = _oblique_impact(16)
    seen = False
    for _ in range(40):
        s.step()
        seen |= s.hist_keys.size > 0
    assert seen
    s2 = DemSystem(dt=1e-4, interfaces=InterfaceTable(default=PAPER))
    s2.add_particle(0.1, sphere_inertia(0.1, 0.02), [0, 0, 0.021], v=[0.5, 0, -1.0], radius=0.02)
    s2.add_wall()
    s2.set_contact_provider(SpherePlaneProvider([0.02], [([0, 0, 0], [0, 0, 1])]))
    keys_during = []
    for _ in range(300):
        s2.step()
        keys_during.append(s2.hist_keys.size)
    assert max(keys_during) == 1 and keys_during[-1] == 0 and s2.energy().elastic == 0.0


def test_contact_between_undefined_materials_is_an_input_error():
    table = InterfaceTable()
    table.set(0, 1, PAPER)
    s = DemSystem(dt=1e-4, interfaces=table)
    s.add_particle(0.1, sphere_inertia(0.1, 0.02), [0, 0, 0.019], material=0, radius=0.02)
    s.add_wall(material=0)
    s.set_contact_provider(SpherePlaneProvider([0.02], [([0, 0, 0], [0, 0, 1])]))
    with pytest.raises(InputError, match="no contact interface"):
        s.initialize()


def test_a_checkpoint_without_exact_sums_restarts_from_its_ledger(tmp_path):
    """A checkpoint written before the ledger summed exactly (no ``exact_ledger``): the
    restored accumulators read its ledger and walls' work back unchanged, and the run goes on
    with the balance closed (to round-off: the sums start from the rounded values)."""
    from nurbsdem.dynamics.exact_sum import exact_values

    def make():
        m, r = 0.1, 0.02
        s = DemSystem(dt=1e-4, interfaces=InterfaceTable(
            default=ContactLaw(en=1e5, cn=30.0, et=1e4, mu=0.5)))
        s.add_particle(m, sphere_inertia(m, r), [0, 0, r - 5e-5], v=[0.1, 0, -0.2], radius=r)
        s.add_wall()
        s.set_contact_provider(SpherePlaneProvider([r], [([0, 0, 0], [0, 0, 1])]))
        return s
    ref, old = make(), make()
    ref.advance(400)
    old.advance(200)
    st = old.get_state()
    del st["exact_ledger"]
    new = make()
    new.set_state(st)
    assert st["ledger"][0] > 0.0                 # it has dissipated: the sums are not zero
    np.testing.assert_array_equal(exact_values(new.exact_ledger),
                                  np.concatenate([st["ledger"][:4], st["wall_work"]]))
    np.testing.assert_array_equal(new.ledger.to_array(), st["ledger"])
    new.advance(200)
    e, e_ref = new.energy(), ref.energy()
    assert e.dissipated == pytest.approx(e_ref.dissipated, rel=1e-12)
    assert e.external_work == pytest.approx(e_ref.external_work, rel=1e-12, abs=1e-15)
    assert abs(e.balance_error - e_ref.balance_error) < 1e-12 * max(e.dissipated, 1e-12)


def test_the_diagnosis_names_the_deepest_penetration_over_the_smaller_size():
    """An instability's diagnosis reads the deepest contact relative to the smaller of its
    bodies (a wall has no size); no contacts: 0."""
    from types import SimpleNamespace

    from nurbsdem.dynamics.system import max_relative_depth
    ell = np.array([0.02, 0.01, 0.04])
    cs = SimpleNamespace(depth=np.array([0.001, 0.003, 0.002]), body_a=np.array([0, 1, 2]),
                         body_b=np.array([2, 2, 3]))          # body 3: a wall
    assert max_relative_depth(cs, ell, 1) == pytest.approx(0.3)
    assert max_relative_depth(None, ell, 1) == 0.0
