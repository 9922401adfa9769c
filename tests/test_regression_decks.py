"""Regression decks (inputs/regression/*.inp) run end to end; their monitors are compared with
the stored references (inputs/regression/reference/<deck>/, made by
inputs/regression/make_references.py) and with the physics each deck demonstrates."""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from nurbsdem.io.deck import parse_deck
from nurbsdem.io.results import read_results_sample, read_results_times
from nurbsdem.solver import Solver

ROOT = Path(__file__).resolve().parents[1]
DECKS = ROOT / "inputs" / "regression"
REFS = DECKS / "reference"


def read_csv(path: Path) -> dict[str, np.ndarray]:
    with open(path) as fh:
        rows = list(csv.DictReader(fh))
    return {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}


def solve(name: str, out: Path):
    model = parse_deck(DECKS / f"{name}.inp")
    summary = Solver(model, output=out, quiet=True).run()
    return model, summary


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Each deck solved once for the whole module."""
    cache = {}

    def get(name):
        if name not in cache:
            out = tmp_path_factory.mktemp(name)
            cache[name] = (out,) + solve(name, out)
        return cache[name]
    return get


def compare(name: str, out: Path, monitor: str, columns, rtol: float, atol_frac: float) -> None:
    new = read_csv(out / "monitors" / monitor)
    ref = read_csv(REFS / name / monitor)
    np.testing.assert_array_equal(new["time"], ref["time"])
    for c in columns:
        scale = max(np.abs(ref[c]).max(), 1e-300)
        np.testing.assert_allclose(new[c], ref[c], rtol=rtol, atol=atol_frac * scale,
                                   err_msg=f"{name}: monitors/{monitor} column {c}")


ENERGY = ("kinetic", "potential", "elastic", "dissipated", "external_work", "mechanical")


def test_drop_one_matches_reference_and_comes_to_rest(runs):
    out, model, summary = runs("drop_one")
    compare("drop_one", out, "energy.csv", ENERGY, 1e-6, 1e-6)
    e = read_csv(out / "monitors" / "energy.csv")
    assert e["kinetic"][-1] < 1e-12 * e["mechanical"][0]                # at rest
    # the resting particle is held by the floor: the floor's reaction (the force holding it
    # in place, against the particle's push) equals the weight
    floor = read_csv(out / "monitors" / "wall_bottom.csv")
    entry = model.shapes[1]
    weight = entry.mass(model.materials[1].density) * 9.81
    assert floor["reaction_z"][-1] == pytest.approx(weight, rel=1e-6)
    assert summary.failed == 0


def test_two_spheres_exchange_velocities_and_conserve_energy(runs):
    out, model, summary = runs("two_spheres")
    compare("two_spheres", out, "energy.csv", ENERGY, 1e-7, 1e-7)
    e = read_csv(out / "monitors" / "energy.csv")
    assert abs(e["mechanical"][-1] / e["mechanical"][0] - 1) < 1e-3     # frictionless, undamped
    path = out / "results.h5"
    last = read_results_sample(path, len(read_results_times(path)) - 1)
    v = last["velocity"][np.argsort(last["particle_id"])]
    np.testing.assert_allclose(v[:, 0], [-0.5, 0.5], atol=1e-3)       # equal masses swap velocities


def test_small_deposition_settles_like_the_reference(runs):
    out, model, summary = runs("deposition_small")
    e = read_csv(out / "monitors" / "energy.csv")
    ref = read_csv(REFS / "deposition_small" / "energy.csv")
    # chaotic: compare the outcome, not the trajectory
    assert e["potential"][-1] == pytest.approx(ref["potential"][-1], rel=0.05)
    assert e["dissipated"][-1] == pytest.approx(ref["dissipated"][-1], rel=0.05)
    assert abs(e["balance_error"][-1]) < 0.02 * e["dissipated"][-1]
    c = read_csv(out / "monitors" / "contacts.csv")
    assert c["failed"].sum() == 0
    assert c["active"].max() >= 6


def test_lid_press_matches_reference(runs):
    out, model, summary = runs("lid_press")
    compare("lid_press", out, "energy.csv", ENERGY, 1e-4, 1e-4)
    compare("lid_press", out, "wall_lid.csv", ("displacement_z", "reaction_z"), 1e-4, 1e-4)
    lid = read_csv(out / "monitors" / "wall_lid.csv")
    e = read_csv(out / "monitors" / "energy.csv")
    # the lid pushes down into the particles: the force holding it is downward, and the
    # work the lid does is the external work of the balance
    assert lid["reaction_z"].min() < -10.0
    assert abs(e["balance_error"][-1]) < 1e-3 * e["external_work"].max()
