"""Names of the files and folders in the output directory (fixed: scripts rely on them; the
layout: :mod:`nurbsdem.io.writers`), and the tolerance of a restart's time."""
from __future__ import annotations

#: Series names (``<name>.pvd``, ``vtk/<name>_NNNNNN.vtu``).
SERIES = ("particles", "walls", "contacts")
RESULTS_NAME = "results.h5"
MONITOR_DIR = "monitors"
VTK_DIR = "vtk"


def time_tol(t: float) -> float:
    """Tolerance (s) for comparing sample times with a restart time."""
    return 1e-9 * max(1.0, abs(t))
