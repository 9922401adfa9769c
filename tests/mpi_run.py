"""Run a deck the way tests/test_mpi.py needs, serially or under ``mpiexec -n P``.

    python tests/mpi_run.py DECK OUT [--kill-after T] [--misjudge F] [--api]

--kill-after T  stop the run by an exception at the first sample after T s (after a
                checkpoint was written: a killed run to restart from); exits 0.
--misjudge F    the time-step control chooses F times too few sub-steps, so the guard rolls
                deck steps back and repeats them with more (tests/test_solver.py does the same).
--api           run through the Python API (nurbsdem.Simulation) instead of the Solver.
"""
from __future__ import annotations

import argparse
import sys


class Killed(Exception):
    pass


def main(argv: list[str]) -> int:
    from nurbsdem.dynamics.system import DemSystem
    from nurbsdem.io.deck import parse_deck
    from nurbsdem.solver import Solver

    ap = argparse.ArgumentParser()
    ap.add_argument("deck")
    ap.add_argument("out")
    ap.add_argument("--kill-after", type=float, default=None)
    ap.add_argument("--misjudge", type=int, default=None)
    ap.add_argument("--api", action="store_true")
    a = ap.parse_args(argv)
    if a.misjudge:
        needed = DemSystem._needed_substeps

        def too_few(self, dt_safe):
            self.max_refinements = 3
            return max(1, needed(self, dt_safe) // a.misjudge)
        DemSystem._needed_substeps = too_few
    if a.kill_after is not None:
        sample = Solver._sample

        def dying(self, writers, force=False, samples=(), states=()):
            sample(self, writers, force, samples, states)
            if self.time > a.kill_after:
                raise Killed
        Solver._sample = dying
    try:
        if a.api:
            from nurbsdem import Simulation
            Simulation.from_deck(a.deck, output=a.out, quiet=True).run()
        else:
            Solver(parse_deck(a.deck), output=a.out, quiet=True).run()
    except Killed:
        print("killed")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
