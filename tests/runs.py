"""Helpers shared by the tests that run decks: spread-out random positions, a run killed
after a checkpoint and restarted, and the comparison of two runs' final states."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from nurbsdem.io.deck import parse_deck
from nurbsdem.io.results import read_results_sample, read_results_times
from nurbsdem.solver import Solver

STATE_KEYS = ("position", "quaternion", "velocity", "angular_velocity")


def spread_points(rng: np.random.Generator, n: int, lo, hi, min_dist: float) -> list[np.ndarray]:
    """n points uniform in the box [lo, hi] (m), more than ``min_dist`` apart: the points, and
    the state ``rng`` is left in, of the plain rejection loop (one ``rng.uniform(lo, hi)`` per
    candidate, accepted when ``np.linalg.norm`` to every accepted point exceeds
    ``min_dist``), found in batches: a copy of the generator draws the candidates, those
    certainly too close to an accepted point are dropped at once, the others are tested in
    order (within round-off of ``min_dist`` by ``np.linalg.norm``); ``rng`` then draws as
    many candidates as the loop would have."""
    probe = np.random.Generator(type(rng.bit_generator)())
    probe.bit_generator.state = rng.bit_generator.state
    near, far = (min_dist * (1 - 1e-9)) ** 2, (min_dist * (1 + 1e-9)) ** 2
    pts: list[np.ndarray] = []
    used, batch = 0, 4096

    def accepted(p: np.ndarray) -> bool:
        if not pts:
            return True
        d2 = ((np.array(pts) - p) ** 2).sum(axis=1)
        if (d2 <= near).any():
            return False
        return bool((d2 > far).all()) or all(np.linalg.norm(p - q) > min_dist for q in pts)

    while len(pts) < n:
        cand = probe.uniform(lo, hi, size=(batch, 3))
        alive = np.ones(batch, bool)
        if pts:
            d2 = ((cand[:, None, :] - np.array(pts)[None]) ** 2).sum(axis=2)
            alive = ~(d2 <= near).any(axis=1)
        taken = batch
        for i in np.nonzero(alive)[0]:
            if accepted(cand[i]):
                pts.append(cand[i].copy())
                if len(pts) == n:
                    taken = int(i) + 1
                    break
        used += taken
    rng.uniform(lo, hi, size=(used, 3))
    return pts


def killed_and_restarted(deck: Path, out: Path, kill_after: float, monkeypatch) -> None:
    """Run ``deck`` into ``out``, kill it (an exception out of the sampling) at the first
    sample after ``kill_after`` s, then restart it from its checkpoint to the end."""
    class Killed(Exception):
        pass
    original = Solver._sample

    def dying(self, writers, force=False, samples=(), states=()):
        original(self, writers, force, samples, states)
        if self.time > kill_after:
            raise Killed
    monkeypatch.setattr(Solver, "_sample", dying)
    with pytest.raises(Killed):
        Solver(parse_deck(deck), output=out, quiet=True).run()
    monkeypatch.setattr(Solver, "_sample", original)
    Solver(parse_deck(deck), output=out, restart=out / "checkpoint.h5", quiet=True).run()


def assert_same_final_state(out: Path, ref: Path, monitors=()) -> None:
    """The two runs have the same sample times, the same last sample bit for bit and the
    same monitor files."""
    times = read_results_times(out / "results.h5")
    np.testing.assert_array_equal(times, read_results_times(ref / "results.h5"))
    a = read_results_sample(out / "results.h5", len(times) - 1)
    b = read_results_sample(ref / "results.h5", len(times) - 1)
    for key in STATE_KEYS:
        np.testing.assert_array_equal(a[key], b[key])          # bit for bit
    for name in monitors:
        assert (out / "monitors" / name).read_text() == (ref / "monitors" / name).read_text()
