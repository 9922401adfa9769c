"""Inlets and outlets on several MPI ranks give the serial run bit for bit.

Every rank holds the serial state at a deck step's end, runs the same exchange (the same
random streams) and cuts the new set of particles anew (:mod:`nurbsdem.flow_run`): a pour
into a box with an outlet in a corner, on two ranks, equals the serial run in results.h5,
every monitor (the inlet's and the outlet's counts among them) and the checkpoint; killed
mid-pour on two ranks and restarted from its checkpoint, it still does.
"""
from __future__ import annotations

import re
import sys

import numpy as np
import pytest

from test_mpi import _run, BIN, HERE, RUN, assert_same_run, needs_mpi

POUR = HERE / "data" / "flow_pour.inp"


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    out = tmp_path_factory.mktemp("flow_serial") / "ref"
    _run([BIN / "nurbsdem", "solve", POUR, "--output", out])
    return out


@needs_mpi
def test_a_pour_with_an_outlet_on_two_ranks(serial, tmp_path):
    log = _run([BIN / "nurbsdem", "solve", POUR, "--output", tmp_path / "two", "--verbose"], 2)
    assert_same_run(tmp_path / "two", serial)
    # the systems built at the exchanges are cut anew: both ranks own particles
    owned = [tuple(map(int, m)) for m in re.findall(r"particle\(s\) out, \d+ in: \d+ particles;"
                                                   r" .*owned \[(\d+), (\d+)\]", log)]
    assert owned and all(a > 0 and b > 0 for a, b in owned[1:])
    outlet = np.genfromtxt(serial / "monitors" / "outlet_corner.csv", delimiter=",", names=True)
    inlet = np.genfromtxt(serial / "monitors" / "inlet_feed.csv", delimiter=",", names=True)
    assert outlet["count"][-1] > 0 and inlet["inserted"][-1] == 60


@needs_mpi
def test_a_pour_killed_on_two_ranks_restarts_mid_pour(serial, tmp_path):
    out = tmp_path / "out"
    assert "killed" in _run([sys.executable, RUN, POUR, out, "--kill-after", "0.03"], 2)
    inlet = np.genfromtxt(out / "monitors" / "inlet_feed.csv", delimiter=",", names=True)
    assert 0 < inlet["inserted"][-1] < 60            # killed mid-pour
    _run([BIN / "nurbsdem", "solve", POUR, "--output", out, "--restart",
          out / "checkpoint.h5"], 2)
    assert_same_run(out, serial)
