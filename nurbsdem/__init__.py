"""nurbsdem: discrete element method for convex rigid particles bounded by exact NURBS surfaces.

The public names load on first use (PEP 562), so ``import nurbsdem`` stays fast (numba and
the compiled kernels are imported only when a shape is built or loaded)::

    import nurbsdem
    s = nurbsdem.shapes.sphere(0.01)           # generators: sphere, ellipsoid, paper_particle ...
    a = nurbsdem.load_shape("inputs/shapes/A.yaml")
    sim = nurbsdem.Simulation(gravity=(0, 0, -9.81))   # scripting: see nurbsdem.simulation
"""
from __future__ import annotations

import importlib
import os
from typing import Any

from .errors import GeometryError, InputError, NurbsdemError

# numba's parallel kernels (the LCP batches) run on OpenMP where the GNU OpenMP runtime is
# there, else on numba's own work queue, unless the user chose a layer. OpenMP's workers wait
# for the next batch briefly spinning, so they share the short, frequent LCP batches of a time
# loop; the work queue's workers sleep between batches and wake too late to share them (on 2
# cores a batch then runs on about one). Not TBB (picked first by numba whenever a
# libtbb is installed, e.g. by Debian's yade; last here, and never reached: the work queue is
# always there): a long run was seen to hang at interpreter exit, spinning in TBB's finaliser
# after all its output was written. Effective when nurbsdem is imported before numba.
os.environ.setdefault("NUMBA_THREADING_LAYER_PRIORITY", "omp workqueue tbb")


def _ranks_on_this_node() -> int:
    """Processes an MPI launcher started on this node (1 without a launcher)."""
    for name in ("MPI_LOCALNRANKS", "OMPI_COMM_WORLD_LOCAL_SIZE", "PMI_SIZE"):
        value = os.environ.get(name, "")
        if value.isdigit():
            return int(value)
    return 1


# Several MPI ranks on a node: OpenBLAS's threads (it spins while waiting) would compete with
# the ranks for the cores; each rank gets its share unless the user chose (effective when
# nurbsdem is imported before NumPy, as by the command line).
if _ranks_on_this_node() > 1:
    os.environ.setdefault("OPENBLAS_NUM_THREADS",
                          str(max(1, (os.cpu_count() or 1) // _ranks_on_this_node())))

# numba's cache is checked per source file; a kernel inlined from another module that changed
# would keep running its old code (a segmentation fault after an upgrade): each module's
# kernels are dropped when its code or that of a package module it imports changed
# (nurbsdem.cachecheck), before any kernel loads.
from .cachecheck import check_caches  # noqa: E402

check_caches()

__version__ = "0.1.0"

#: Public names loaded on first use: name -> (module, attribute; None = the module itself).
_LAZY: dict[str, tuple[str, str | None]] = {
    "shapes": (".shapes", None),
    "Patch": (".geometry.nurbs", "Patch"),
    "Shape": (".geometry.shape", "Shape"),
    "load_shape": (".io.shapefile", "load_shape"),
    "save_shape": (".io.shapefile", "save_shape"),
    "Simulation": (".simulation", "Simulation"),      # the scripting API
}

__all__ = ["__version__", "shapes", "Simulation", "Patch", "Shape", "load_shape", "save_shape",
           "NurbsdemError", "InputError", "GeometryError"]


def __getattr__(name: str) -> Any:
    """Import a public name of :data:`_LAZY` on first access and keep it."""
    try:
        module, attr = _LAZY[name]
    except KeyError:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    mod = importlib.import_module(module, __name__)
    value = mod if attr is None else getattr(mod, attr)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
