"""Runs on several MPI ranks: the communicator (:mod:`.comm`), the domain decomposition bit
for bit equal to the serial run (:mod:`.domain`) and its cut (:mod:`.cut`).  Needs the ``mpi``
extra (mpi4py and an MPI library) only when started by ``mpiexec -n P`` with P > 1."""
from .comm import launched_size, threads_per_rank, world
from .cut import decompose
from .domain import Domain

__all__ = ["Domain", "decompose", "launched_size", "threads_per_rank", "world"]
