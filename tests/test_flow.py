"""Inlets and outlets (nurbsdem.dynamics.flow): the schedule, no overlap at insertion, a full
inlet that waits and resumes, the mix's fractions, discs, and the outlets' counts."""
import numpy as np
import pytest

from nurbsdem.dynamics.flow import InsertionRegion, Inlet, Outlet


def make_inlet(**kw):
    args = dict(region=InsertionRegion(lo=np.zeros(3), hi=np.array([0.2, 0.2, 0.1])),
                shapes=np.array([1, 2, 3]), fractions=np.array([0.4, 0.3, 0.3]),
                radii=np.array([0.01, 0.008, 0.006]), masses=np.array([3e-3, 2e-3, 1e-3]),
                rate=500.0, count=2000, seed=3)
    args.update(kw)
    return Inlet(**args)


def test_schedule_follows_rate_count_mass_and_time():
    inlet = make_inlet()
    assert inlet.due(0.1) == 50 and inlet.due(10.0) == 2000
    inlet.inserted = 1990
    assert inlet.due(10.0) == 10
    timed = make_inlet(until=0.2, start=0.1, count=None)
    assert timed.due(0.05) == 0 and timed.due(0.15) == 25 and timed.due(5.0) == 50
    by_mass = make_inlet(rate=1.1, rate_is_mass=True, count=None, mass=1.0)
    assert by_mass.number_rate == pytest.approx(1.1 / (0.4 * 3e-3 + 0.3 * 2e-3 + 0.3 * 1e-3))
    by_mass.inserted_mass = 1.0
    assert by_mass.due(100.0) == 0


def test_pouring_places_no_overlap_and_keeps_every_particle_inside():
    inlet = make_inlet()
    rng = np.random.default_rng(0)
    # a bed of present particles, partly inside the region
    centers = rng.uniform([0, 0, -0.05], [0.2, 0.2, 0.05], (200, 3))
    radii = np.full(200, 0.004)
    keep = np.ones(200, bool)
    for i in range(200):                       # make the bed itself overlap-free
        d = np.linalg.norm(centers[:i][keep[:i]] - centers[i], axis=1)
        keep[i] = np.all(d >= radii[i] * 2)
    centers, radii = centers[keep], radii[keep]
    total = 0
    for step in range(1, 6):
        new = inlet.insert(0.02 * step, centers, radii)
        r_new = inlet.radii[np.searchsorted(inlet.shapes, new.shapes)]
        assert np.all(new.positions - r_new[:, None] >= -1e-12)
        assert np.all(new.positions + r_new[:, None] <= [0.2, 0.2, 0.1 + 1e-12])
        centers = np.concatenate([centers, new.positions])
        radii = np.concatenate([radii, r_new])
        total += len(new.shapes)
        assert np.allclose(np.linalg.norm(new.quaternions, axis=1), 1.0)
    d = np.linalg.norm(centers[:, None] - centers[None], axis=2)
    np.fill_diagonal(d, np.inf)
    assert np.all(d >= radii[:, None] + radii[None] - 1e-15)
    assert total == inlet.inserted == 50 - inlet.waiting


def test_a_full_inlet_waits_and_resumes_when_there_is_room():
    inlet = make_inlet(region=InsertionRegion(lo=np.zeros(3), hi=np.full(3, 0.03)),
                       fractions=np.array([1.0, 0, 0]), max_attempts=200)
    new = inlet.insert(0.01, np.zeros((0, 3)), np.zeros(0))   # 5 due, 1 fits (r = 0.01)
    assert len(new.shapes) == 1 and inlet.waiting == 4
    blocked = inlet.insert(0.01, new.positions, np.array([0.01]))
    assert len(blocked.shapes) == 0 and inlet.waiting == 4
    freed = inlet.insert(0.01, np.zeros((0, 3)), np.zeros(0))   # the first one left
    assert len(freed.shapes) == 1 and inlet.inserted == 2 and inlet.waiting == 3


def test_the_mix_follows_its_fractions():
    n = 1500
    inlet = make_inlet(region=InsertionRegion(lo=np.zeros(3), hi=np.full(3, 10.0)),
                       count=n, rate=n)
    new = inlet.insert(1.0, np.zeros((0, 3)), np.zeros(0))
    assert len(new.shapes) == n
    counts = np.array([np.sum(new.shapes == s) for s in (1, 2, 3)])
    sigma = np.sqrt(n * inlet.fractions * (1 - inlet.fractions))
    assert np.all(np.abs(counts - n * inlet.fractions) < 4 * sigma)


def test_a_disc_region_places_inside_the_disc():
    region = InsertionRegion(centre=np.array([0, 0, 1.0]), axis=np.array([0, 0, 1.0]),
                             radius=0.1, thickness=0.02)
    inlet = make_inlet(region=region, fractions=np.array([0, 0, 1.0]), rate=100, count=20)
    new = inlet.insert(1.0, np.zeros((0, 3)), np.zeros(0))
    assert len(new.shapes) == 20
    rho = np.linalg.norm(new.positions[:, :2], axis=1)
    assert np.all(rho <= 0.1 - 0.006 + 1e-12)
    assert np.all(np.abs(new.positions[:, 2] - 1.0) <= 0.01 - 0.006 + 1e-12)


def test_outlets_count_what_they_remove():
    box = Outlet("bin", lo=np.array([0, 0, -1.0]), hi=np.array([1, 1, 0.0]))
    plane = Outlet("floor", point=np.zeros(3), normal=np.array([0, 0, -1.0]))
    x = np.array([[0.5, 0.5, -0.1], [0.5, 0.5, 0.1], [2.0, 0.5, -0.5]])
    m = np.array([1.0, 2.0, 4.0])
    assert box.remove(0.0, x, m).tolist() == [0]
    assert plane.remove(0.0, x, m).tolist() == [0, 2]
    assert box.count == 1 and box.mass == 1.0 and plane.mass == 5.0
    box.remove(0.5, x[[2]], m[[2]])
    plane.remove(0.5, x[[0]], m[[0]])
    assert box.rows[-1] == (0.5, 1, 1.0, 0.0)
    assert plane.rows[-1] == (0.5, 3, 6.0, pytest.approx(2.0))
