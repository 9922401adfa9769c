"""Pouring 2 000 spheres into a box with an outlet in a corner of its floor
(``benchmarks/bench_pour.py``): every inserted particle is in the box or was discharged, in
count and in mass; none was placed overlapping another; all left are inside the box; the
energy balance closes to the explicit scheme's order, h²: at half the internal step its
error falls about fourfold.  A long run (minutes): marked slow."""
from __future__ import annotations

import pytest

import bench_pour  # benchmarks/


@pytest.mark.slow
def test_a_pour_of_2000_spheres_accounts_for_every_one_and_closes_its_balance(tmp_path):
    r = bench_pour.pour(2000, tmp_path / "full")
    assert r["inserted"] == 2000 and r["waiting"] == 0
    assert r["count_error"] == 0 and r["discharged"] > 0 and r["in_box"] > 1000
    assert r["mass_error"] < 1e-12
    assert r["min_gap"] >= 0.0 and r["inside"]
    assert r["balance"] < 3e-3
    half = bench_pour.pour(2000, tmp_path / "half", safety=0.25)
    assert half["count_error"] == 0
    assert 2.5 < r["balance"] / half["balance"] < 6.0       # second order: 4
