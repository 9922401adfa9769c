"""Periodic cells (nurbsdem.contact.periodic): the search through the cell against all 27
images, wrapping, a contact across a face equal to the same contact in the middle, and the
refusal of a cell shorter than twice the contact reach."""
import itertools

import numpy as np
import pytest

from nurbsdem.contact.lcp import NF, NI
from nurbsdem.contact.periodic import (make_cell, minimum_image, periodic_sphere_pairs,
                                       wrap)
from nurbsdem.contact.sphere import _sphere_sphere_row


def brute(x, r, margin, cell):
    L = cell.length
    found = set()
    choices = [(-1, 0, 1) if p else (0,) for p in cell.periodic]
    for i, j in itertools.combinations(range(len(x)), 2):
        for s in itertools.product(*choices):
            if np.linalg.norm(x[j] + np.array(s) * L - x[i]) < r[i] + r[j] + margin:
                found.add((i, j, *s))
    return found


@pytest.mark.parametrize("periodic", [(1, 0, 0), (1, 1, 0), (1, 1, 1), (0, 1, 1)])
def test_pairs_through_the_cell_equal_all_images(periodic):
    rng = np.random.default_rng(sum(periodic) + 7 * periodic[0])
    cell = make_cell((0, -0.1, 0.2), (0.3, 0.2, 0.45), periodic)
    for n in (2, 30, 300):
        x, _ = wrap(rng.uniform(-0.5, 0.8, (n, 3)) * [1, 1, 1], cell)
        x[:, ~cell.periodic] = rng.uniform(cell.lo, cell.hi, (n, 3))[:, ~cell.periodic]
        r = rng.uniform(0.005, 0.03, n)
        pairs, shift = periodic_sphere_pairs(x, r, 0.004, cell)
        got = {(int(i), int(j), *map(int, s)) for (i, j), s in zip(pairs, shift)}
        assert len(got) == len(pairs)
        assert got == brute(x, r, 0.004, cell)


def test_wrap_and_minimum_image():
    cell = make_cell((0, 0, 0), (1, 2, 3), (1, 1, 0))
    x = np.array([[-0.25, 4.5, 7.0], [1.0, -2.0, -1.0]])
    w, s = wrap(x, cell)
    assert np.allclose(w, [[0.75, 0.5, 7.0], [0.0, 0.0, -1.0]])
    assert np.array_equal(s, [[-1, 2, 0], [1, -1, 0]])
    assert np.allclose(w + s * cell.length, x)
    assert np.allclose(minimum_image([0.9, -1.5, 2.9], cell), [-0.1, 0.5, 2.9])


def test_a_contact_across_the_face_equals_the_same_contact_in_the_middle():
    cell = make_cell((0, 0, 0), (1, 1, 1), (1, 0, 0))
    xa, xb = np.array([0.99, 0.5, 0.5]), np.array([0.015, 0.52, 0.49])
    pairs, shift = periodic_sphere_pairs(np.array([xa, xb]), np.array([0.02, 0.03]), 0.0, cell)
    assert pairs.tolist() == [[0, 1]] and shift.tolist() == [[1, 0, 0]]
    image = xb + shift[0] * cell.length
    across_f, across_i = np.zeros((1, NF)), np.zeros((1, NI), np.int64)
    _sphere_sphere_row(*xa, 0.02, *image, 0.03, across_f, across_i, 0)
    d = np.array([-0.49, 0, 0])                      # the same pair moved to the middle
    mid_f, mid_i = np.zeros((1, NF)), np.zeros((1, NI), np.int64)
    _sphere_sphere_row(*(xa + d), 0.02, *(image + d), 0.03, mid_f, mid_i, 0)
    assert across_f[0, 0] == pytest.approx(mid_f[0, 0], abs=1e-16)       # signed distance
    assert np.allclose(across_f[0, 1:4], mid_f[0, 1:4], atol=1e-14)       # normal
    assert across_i[0, 0] == mid_i[0, 0] == 1


def test_a_cell_shorter_than_twice_the_reach_is_refused():
    cell = make_cell((0, 0, 0), (0.1, 1, 1), (1, 0, 0))
    with pytest.raises(ValueError, match="periodic length along x .* under twice"):
        periodic_sphere_pairs(np.array([[0.05, 0.5, 0.5]]), np.array([0.03]), 0.0, cell)
    with pytest.raises(ValueError, match="repeats along one axis"):
        make_cell((0, 0, 0), (1, 1, 1), (0, 0, 0))
