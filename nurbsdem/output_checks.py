"""The size of a run's ParaView samples against the free space of the disk they go to.

A sample of ``particles.pvd`` tessellates every particle: ``(Resolution + 1)²`` vertices per
patch, written as compressed XML (about :data:`DISK_BYTES_PER_VERTEX` bytes per vertex).
40 000 spheres sampled every 0.01 s (the ``VTK Every`` default) write about 40 GiB per
second simulated, and a run that fills its disk stops at the sample that did not fit.
:func:`warn_output_size` says so before the run, on the ``nurbsdem`` logger, with the
numbers to change; the run still starts (the estimate is coarse, and the user may make room).
"""
from __future__ import annotations

import logging
import math
import shutil
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # pragma: no cover
    from .model import Model

#: Bytes on disk per tessellation vertex of a particle in a compressed ``.vtu`` sample (its
#: point, normal and point data after deflate; the paper's particles at Resolution 8 take 22).
DISK_BYTES_PER_VERTEX = 22


def max_particle_count(model: "Model") -> tuple[int, int | None]:
    """(largest number of particles any step has, line of the step that makes it)."""
    from .model import ReplicateStep
    n, worst, line = model.particle_count, model.particle_count, None
    for s in model.steps:
        if isinstance(s, ReplicateStep):
            n *= int(s.layers)
            if n > worst:
                worst, line = n, s.line
    return worst, line


def output_line(model: "Model") -> int | None:
    """The line of the deck's ``VTK`` entry, or ``None``."""
    for k, line in enumerate(model.text.splitlines(), start=1):
        if line.split("#")[0].strip().lower().startswith("vtk"):
            return k
    return None


def most_particles(model: "Model") -> int:
    """The most particles the run can hold: the deck's (after its ``Replicate`` steps) and
    every inlet's ``Count``."""
    return max_particle_count(model)[0] + sum(int(i.count) for i in model.inlets)


def vtk_output_bytes(model: "Model") -> tuple[float, int, int]:
    """An estimate of the bytes the run's particle samples write: (bytes, samples, particles
    at most). Each sample holds at most :func:`most_particles`, each with the most patches
    of the deck's shapes."""
    out = model.output
    samples = int(math.floor(model.total_time / out.vtk_every + 1e-9)) + 1
    n = most_particles(model)
    patches = max(len(e.shape.patches) for e in model.shapes.values())
    per_sample = n * patches * (int(out.vtk_resolution) + 1) ** 2 * DISK_BYTES_PER_VERTEX
    return float(samples * per_sample), samples, n


def free_bytes(directory: Path) -> int:
    """Free bytes of the disk holding ``directory`` (or its nearest existing parent)."""
    path = Path(directory).resolve()
    while not path.exists() and path != path.parent:
        path = path.parent
    return int(shutil.disk_usage(path).free)


def gib(nbytes: float) -> str:
    """Bytes as GiB, three digits."""
    return f"{nbytes / 1024 ** 3:.3g} GiB"


def output_size_problem(model: "Model") -> str | None:
    """The warning's text when the particle samples would not fit the free space of the
    output's disk, else ``None``."""
    out = model.output
    if out is None or out.vtk_every <= 0 or not model.shapes or model.total_time <= 0:
        return None
    need, samples, n = vtk_output_bytes(model)
    have = free_bytes(out.directory)
    if need <= have:
        return None
    fit = int(have // (need / samples))       # samples that fit, the one at t = 0 included
    if fit >= 2:
        every = model.total_time / (fit - 1)
        every = math.ceil(every / 10 ** math.floor(math.log10(every) - 2)) * 10 ** math.floor(
            math.log10(every) - 2)                # rounded up to three digits
        fix = f"raise VTK Every to {every:.3g} s or more, or lower Resolution"
    else:
        fix = "not even two samples fit: lower Resolution"
    return (f"VTK Every {out.vtk_every:g} s writes about {gib(need)} of ParaView samples "
            f"({samples} samples of up to {n} particles at Resolution {out.vtk_resolution}); "
            f"the disk of {out.directory} has {gib(have)} free: the run stops when it is full "
            f"({fix})")


def warn_output_size(model: "Model") -> None:
    """:func:`output_size_problem` on the ``nurbsdem`` logger, ``deck:line: message`` (the
    ``VTK`` line, the deck alone without one; the message alone for a scene built in
    Python).  No ParaView output (``vtk_every`` 0 in Python): no warning."""
    problem = output_size_problem(model)
    if problem is None:
        return
    deck = bool(getattr(model, "text", None)) and bool(model.path)
    line = output_line(model) if deck else None
    loc = f"{model.path}:{line}: " if line else f"{model.path}: " if deck else ""
    logging.getLogger("nurbsdem").warning(f"{loc}{problem}")
