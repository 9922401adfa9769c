"""Helpers shared by the tests that run decks: spread-out random positions, a run killed
after a checkpoint and restarted, and the comparison of two runs' final states."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from nurbsdem.io.deck import parse_deck
from nurbsdem.io.writers import read_results_sample, read_results_times
from nurbsdem.solver import Solver

STATE_KEYS = ("position", "quaternion", "velocity", "angular_velocity")


def spread_points(rng: np.random.Generator, n: int, lo, hi, min_dist: float) -> list[np.ndarray]:
    """n points uniform in the box [lo, hi] (m), at least ``min_dist`` apart (rejection)."""
    pts: list[np.ndarray] = []
    while len(pts) < n:
        p = rng.uniform(lo, hi)
        if all(np.linalg.norm(p - q) > min_dist for q in pts):
            pts.append(p)
    return pts


def killed_and_restarted(deck: Path, out: Path, kill_after: float, monkeypatch) -> None:
    """Run ``deck`` into ``out``, kill it (an exception out of the sampling) at the first
    sample after ``kill_after`` s, then restart it from its checkpoint to the end."""
    class Killed(Exception):
        pass
    original = Solver._sample

    def dying(self, writers, force=False, samples=()):
        original(self, writers, force, samples)
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
