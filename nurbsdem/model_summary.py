"""The text of :meth:`nurbsdem.model.Model.summary` (``nurbsdem check``): the scene, its steps
and its flows in words, with units.  It reads a model by its attributes (steps by their
``kind``) and imports nothing of :mod:`nurbsdem.model`, which calls it."""
from __future__ import annotations

from typing import Any

from .errors import vector_text as _vec


def summary_text(model: Any) -> str:
    """The text of :meth:`Model.summary`."""
    out = [f"Deck: {model.path}", f"Gravity: {_vec(model.gravity)} m/s^2"]
    p = model.periodic
    if p is not None:
        out.append("Periodic: " + ", ".join(f"{'xyz'[k]} {p.lo[k]:g} .. {p.hi[k]:g} m"
                                             for k in range(3) if p.axes[k]))
    out.append("Materials:")
    for mat in model.materials.values():
        out.append(f"  {mat.id}: density {mat.density:g} kg/m^3"
                   + (f", E {mat.young_modulus:g} Pa, nu {mat.poisson_ratio:g}"
                      if mat.young_modulus is not None else ""))
    out.append("Shapes:")
    for s in model.shapes.values():
        src = f"file {s.source}" if s.kind == "file" else f"{s.kind} {_vec(s.params)} m"
        over = []
        if s.volume_override is not None:
            over.append("volume")
        if s.inertia_override is not None:
            over.append("inertia")
        extra = f" (given {' and '.join(over)})" if over else ""
        out.append(f"  {s.id}: {s.name}: {src}, {len(s.shape.patches)} patches, volume "
                   f"{s.volume:.6g} m^3{extra}, bounding radius {s.bounding_radius:.4g} m")
    out.append(f"Particles: {model.particle_count}")
    for g in model.random_groups:
        parts = ", ".join(f"{n} x shape {sid}" for sid, n in zip(g.shape_ids, g.counts))
        out.append(f"  Random {g.id} (ids {g.id}-{g.id + g.total - 1}): {parts}, material "
                   f"{g.material_id}, region [{_vec(g.region_lo)}] - [{_vec(g.region_hi)}] m, "
                   f"seed {g.seed}")
    for p in model.particles:
        out.append(f"  Particle {p.id}: shape {p.shape_id}, material {p.material_id}, "
                   f"centroid {_vec(p.position)} m")
    if model.bodies is not None:
        masses = [model.shapes[int(s)].mass(model.materials[int(mm)].density)
                  for s, mm in zip(model.bodies.shape_id, model.bodies.material_id)]
        out.append(f"  placed {len(model.bodies)} bodies, total mass {sum(masses):.6g} kg")
    out.append(f"Walls: {len(model.walls) + len(model.curved_walls)}")
    for w in model.walls:
        out.append(f"  {w.id}: {w.name} at {_vec(w.center)} m, normal {_vec(w.normal)}")
    for c in model.curved_walls:
        out.append(f"  {c.id}: {c.name}: {c.kind} {c.file}, position {_vec(c.position)} m, "
                   f"rotation {_vec(c.rotation)} rad")
    out.append("Contact interfaces:")
    for i in model.interfaces:
        scope = i.between or "all pairs"
        if i.materials:
            scope += f", materials {' '.join(map(str, i.materials))}"
        if i.model == "hertz":
            out.append(f"  {i.id} ({scope}): Hertz-Mindlin (exact curvature), restitution "
                       f"{i.restitution:g}, mu {i.friction:g}")
            continue
        out.append(f"  {i.id} ({scope}): en {i.normal_penalty:g} N/m, et "
                   f"{i.tangential_penalty:g} N/m, cn {i.normal_damping:g} N s/m, ct "
                   f"{i.tangential_damping:g} N s/m, mu {i.friction:g}")
    out.append("Steps:")
    t = 0.0
    for s in model.steps:
        if s.kind == "dynamic":
            desc = f"Dynamic {s.duration:g} s, time step {s.time_step:g} s"
        elif s.kind == "replicate":
            desc = f"Replicate into {s.layers} layers over {s.height:g} m"
        else:
            if s.to_contact:
                desc = f"MoveWall {s.wall} to contact, gap {s.gap:g} m"
            else:
                from .wall_tables import describe_moves
                desc = (f"MoveWall {describe_moves(s)} in {s.duration:g} s, time step "
                        f"{s.time_step:g} s")
        if getattr(s, "damping", "explicit") == "implicit":
            desc += ", implicit dashpots"
        if getattr(s, "accuracy", None) is not None:
            desc += f", accuracy {s.accuracy:g}"
        if getattr(s, "safety", None) is not None:
            desc += f", safety {s.safety:g}"
        out.append(f"  {s.id}: t = {t:g} s: {desc}")
        t += s.duration_s
    out.append(f"Total simulated time: {t:g} s")
    for i in model.inlets:
        into = (f"the disc at {_vec(i.centre)} m, normal {_vec(i.normal)}, radius "
                f"{i.radius:g} m, thickness {i.thickness:g} m" if i.is_disc else
                f"the box {_vec(i.lo)} .. {_vec(i.hi)} m")
        out.append(f"Inlet {i.name}: {i.count} particles of shapes {list(i.shapes)} at "
                   f"{i.rate:g} per s into {into}")
    for o in model.outlets:
        where = (f"in the box {_vec(o.lo)} .. {_vec(o.hi)} m" if o.normal is None else
                 f"beyond the plane through {_vec(o.point)} m, normal {_vec(o.normal)}")
        out.append(f"Outlet {o.name}: removes the particles {where}")
    o = model.output
    if o is not None:
        out.append(f"Output: {o.directory}; VTK every {o.vtk_every:g} s (resolution "
                   f"{o.vtk_resolution}); monitors every {o.monitors_every:g} s; results.h5 "
                   f"every {o.results_interval:g} s; checkpoint every {o.checkpoint_every:g} s")
    return "\n".join(out)


# ---------------------------------------------------------------------------- comparing models

#: Fields that do not change the simulation (where an entry is written, file names).
