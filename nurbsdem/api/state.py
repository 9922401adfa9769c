"""The state of a :class:`~nurbsdem.simulation.Simulation` read between steps: the bodies,
the walls' displacements, the energies and the contacts, from the solver once a step has run
and from the scene before."""
from __future__ import annotations

import numpy as np

from ..model import Bodies, Model


def bodies(model: Model, solver) -> Bodies:
    """The particles' current state (a copy; before any step: as the scene places them)."""
    if solver is not None:
        return solver.bodies.copy()
    from ..placement import explicit_bodies
    return explicit_bodies(model)


def time(solver) -> float:
    """Simulated time (s)."""
    return float(solver.time) if solver is not None else 0.0


def wall_displacements(model: Model, solver) -> dict[str, np.ndarray]:
    """Each wall's displacement from where it was defined (m), by name (a mesh or surface
    wall's translation; its turns are not in it)."""
    names = model.wall_names
    off = solver.wall_offset if solver is not None else np.zeros((len(names), 3))
    return {name: np.array(off[k]) for k, name in enumerate(names)}


def free_energies(model: Model, b: Bodies) -> tuple[float, float]:
    """(kinetic, potential) energy of the bodies ``b`` (J; potential 0 at the origin)."""
    kin = pot = 0.0
    R = b.rotation_matrices()
    for i in range(len(b)):
        entry = model.shapes[int(b.shape_id[i])]
        rho = model.materials[int(b.material_id[i])].density
        mass = entry.mass(rho)
        J = R[i] @ entry.mass_inertia(rho) @ R[i].T
        w = b.angular_velocity[i]
        kin += 0.5 * mass * float(b.velocity[i] @ b.velocity[i]) + 0.5 * float(w @ J @ w)
        pot -= mass * float(model.gravity @ b.position[i])
    return kin, pot


def energy(model: Model, solver) -> dict[str, float]:
    """The energies of :meth:`~nurbsdem.simulation.Simulation.energy` (J): the solver's at the
    end of the last step when it was a dynamic one, else those of the bodies as they are."""
    e = solver.end_energy if solver is not None else None
    if e is not None and e["step"] == solver.step_index - 1:
        return {k: v for k, v in e.items() if k != "step"}
    kin, pot = free_energies(model, bodies(model, solver))
    off = (solver.energy_offset if solver is not None
           else {"dissipated": 0.0, "external_work": 0.0})
    return dict(time=time(solver), kinetic=kin, potential=pot, elastic=0.0,
                dissipated=float(off["dissipated"]), external_work=float(off["external_work"]),
                mechanical=kin + pot,
                balance_error=0.0 if e is None and solver is None else float("nan"))


def contacts(model: Model, solver) -> dict[str, np.ndarray]:
    """The contacts of :meth:`~nurbsdem.simulation.Simulation.contacts` (copies; empty unless
    the last step was a dynamic one)."""
    c = solver.end_contacts if solver is not None else None
    if c is None or c["step"] != solver.step_index - 1:
        z3 = np.zeros((0, 3))
        c = dict(body_a=np.zeros(0, np.int64), body_b=np.zeros(0, np.int64), point=z3,
                 normal=z3, depth=np.zeros(0), force_normal=z3, force_tangential=z3)
    pairs = np.stack([c["body_a"], c["body_b"]], axis=1).reshape(-1, 2)
    ids_all = np.concatenate([bodies(model, solver).id,
                              np.zeros(len(model.wall_names), np.int64)])
    return dict(pairs=pairs, ids=ids_all[pairs] if len(pairs) else pairs.copy(),
                point=c["point"].copy(), normal=c["normal"].copy(), depth=c["depth"].copy(),
                force_normal=c["force_normal"].copy(),
                force_tangential=c["force_tangential"].copy(),
                force=c["force_normal"] + c["force_tangential"])
