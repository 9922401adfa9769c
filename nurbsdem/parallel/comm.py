"""Which MPI communicator a run uses: the world of ``mpiexec -n P`` (P > 1), else none.

mpi4py is imported only when a launcher started this process (its environment says so), so a
serial run never initialises MPI and works without the ``mpi`` extra.
"""
from __future__ import annotations

import os
from typing import Any

from ..errors import InputError

#: environment variables by which MPI launchers announce the number of processes (MPICH/Hydra
#: and Intel MPI: PMI_SIZE; Open MPI: OMPI_COMM_WORLD_SIZE; PMIx: PMIX_SIZE)
LAUNCHER_SIZE_VARIABLES = ("PMI_SIZE", "OMPI_COMM_WORLD_SIZE", "PMIX_SIZE", "MPI_LOCALNRANKS")


def launched_size() -> int:
    """Number of processes the MPI launcher started (1 when none did)."""
    for name in LAUNCHER_SIZE_VARIABLES:
        value = os.environ.get(name, "")
        if value.isdigit():
            return int(value)
    return 1


def world() -> Any | None:
    """``MPI.COMM_WORLD`` when this process runs under an MPI launcher with more than one
    process, else None (a serial run).  Raises InputError (one line) when the launcher started
    several processes but mpi4py is missing."""
    if launched_size() <= 1:
        return None
    try:
        from mpi4py import MPI
    except ImportError:
        raise InputError("started by mpiexec with several processes, but mpi4py is not "
                         "installed: pip install 'nurbsdem[mpi]'") from None
    comm = MPI.COMM_WORLD
    return comm if comm.size > 1 else None


def threads_per_rank(comm: Any) -> int:
    """CPU cores per rank on this rank's node (at least 1): the compiled kernels' threads, so
    that P ranks on one node do not oversubscribe its cores."""
    from mpi4py import MPI
    local = comm.Split_type(MPI.COMM_TYPE_SHARED)
    n = local.size
    local.Free()
    return max(1, (os.cpu_count() or 1) // n)
