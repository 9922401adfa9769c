"""What turns a model's deck ids into a :class:`~nurbsdem.dynamics.DemSystem`: the material,
wall-material and shape indices, the contact laws per pair of materials, and the particles
and walls of a system for the current bodies (:class:`SystemAssembly`)."""
from __future__ import annotations

import numpy as np

from .contact.detect import ContactTable
from .contact.scene import SceneContacts
from .dynamics import DemSystem, InterfaceTable, PrescribedMotion
from .dynamics.laws import law_named
from .dynamics.stepcontrol import shape_compliance
from .model import Bodies, Model, material_pair
from .periodic_checks import check_cell_reach


class SystemAssembly:
    """The indices and contact laws of ``model`` and the systems built from them.

    Materials: deck ids -> 0..M-1 (:attr:`mat_index`); walls: M + k, k the index of their
    material among the walls' materials, None (rigid walls) first (:attr:`wall_index`);
    shapes: deck ids -> 0..S-1 in the scene (:attr:`shape_index`)."""

    def __init__(self, model: Model) -> None:
        self.model = model
        mats = sorted(model.materials)
        self.mat_index = {m: i for i, m in enumerate(mats)}
        wall_mats = sorted({w.material_id for w in model.walls + model.curved_walls},
                           key=lambda m: (m is not None, m if m is not None else 0))
        self.wall_index = {wm: len(mats) + k for k, wm in enumerate(wall_mats)}
        self.shape_ids = sorted(model.shapes)
        self.shape_index = {s: i for i, s in enumerate(self.shape_ids)}
        self.shapes = [model.shapes[s].shape for s in self.shape_ids]
        self.interfaces = self._interface_table()
        self._compliances: dict = {}
        self._kinds: dict[tuple[int, int], dict] = {}
        self._contact_table: ContactTable | None = None

    def contact_table(self) -> ContactTable:
        """The contact table of :attr:`shapes`, made once: every scene of the run shares it
        (it depends on the shapes only, and a run with inlets or outlets builds a scene at
        each exchange of particles)."""
        if self._contact_table is None:
            self._contact_table = ContactTable(self.shapes)
        return self._contact_table

    def _interface_table(self) -> InterfaceTable:
        """Contact laws per pair of material indices (walls: material M), from the deck."""
        table = InterfaceTable(default=None)
        mats = sorted(self.mat_index)

        def law(itf, ma, mb=None, wall=None):    # mb None: a wall of material `wall`
            kind = law_named(itf.model)
            pair = (material_pair(self.model, itf, kind.name, ma, mb, wall)
                    if kind.uses_materials else None)
            return kind.from_interface(itf, pair)
        for i, ma in enumerate(mats):
            for mb in mats[i:]:
                itf = self.model.interface("particle-particle", (ma, mb))
                if itf is not None:
                    table.set(self.mat_index[ma], self.mat_index[mb], law(itf, ma, mb))
            itf = self.model.interface("particle-wall", (ma,))
            if itf is not None:
                for wm, k in self.wall_index.items():
                    table.set(self.mat_index[ma], k, law(itf, ma, wall=wm))
        return table

    def compliance(self, shape_id: int, rho: float) -> tuple[float, float]:
        """Worst point compliances (1/kg) of a shape at density rho, for the a-priori time-step
        estimate (:func:`~nurbsdem.dynamics.stepcontrol.shape_compliance`), once per pair."""
        key = (shape_id, rho)
        if key not in self._compliances:
            entry = self.model.shapes[shape_id]
            self._compliances[key] = shape_compliance(entry.shape, entry.mass(rho),
                                                      entry.mass_inertia(rho), entry.centroid)
        return self._compliances[key]

    def particle_kind(self, shape_id: int, material_id: int) -> dict:
        """The arguments of :meth:`DemSystem.add_particle` that every particle of one shape
        and material shares: mass (kg), inertia J0 (kg m^2, file frame), material index,
        centroid in the file frame and bounding radius (m), a-priori compliances; formed
        once per pair (a run with inlets or outlets builds a system at each exchange)."""
        key = (shape_id, material_id)
        if key not in self._kinds:
            entry = self.model.shapes[shape_id]
            rho = self.model.materials[material_id].density
            self._kinds[key] = dict(mass=entry.mass(rho), J0=entry.mass_inertia(rho),
                                    material=self.mat_index[material_id],
                                    centroid_file=entry.centroid,
                                    radius=entry.bounding_radius,
                                    compliance=self.compliance(shape_id, rho))
        return dict(self._kinds[key])

    def system(self, bodies: Bodies, t0: float, dt: float, motions: list[PrescribedMotion],
               safety: float, compiled_steps: bool, implicit_damping: bool = False,
               accuracy: float | None = None) -> DemSystem:
        """A DemSystem at time ``t0`` (s) with time step ``dt`` (s) for ``bodies`` (in their
        order), the walls moving by ``motions`` (the flat walls, then the mesh and surface walls);
        ``safety``: the fraction of the stability limit the sub-stepping uses;
        ``compiled_steps``: whether the deck steps run compiled
        (:attr:`DemSystem.compiled_steps`)."""
        model = self.model
        sysm = DemSystem(dt=dt, gravity=model.gravity, interfaces=self.interfaces,
                         safety=safety, t0=t0,
                         implicit_damping=implicit_damping,
                         accuracy=accuracy)
        sysm.compiled_steps = compiled_steps
        b = bodies
        m0 = int(b.material_id.min()) if len(b) else 0
        mats = int(b.material_id.max()) - m0 + 1 if len(b) else 1
        keys, kind = np.unique(np.asarray(b.shape_id, np.int64) * mats + (b.material_id - m0),
                               return_inverse=True)       # a key per (shape, material)
        sysm.add_particle_kinds(np.ravel(kind), [self.particle_kind(int(k // mats),
                                                                   int(k % mats) + m0)
                                                 for k in keys],
                                b.rotation_matrices(), b.position, b.velocity,
                                b.angular_velocity)
        for k, w in enumerate(model.walls + model.curved_walls):    # mesh, surface: last
            sysm.add_wall(motions[k], material=self.wall_index[w.material_id], name=w.name)
        return sysm

    def scene(self, previous: SceneContacts | None, bodies: Bodies,
              contact_options: dict) -> SceneContacts:
        """The contact scene of ``bodies``: ``previous`` (its search structures and history
        carried on) while it has as many bodies, else a new one with ``contact_options``
        (keywords of :class:`~nurbsdem.contact.scene.SceneContacts`), through the model's
        periodic cell if it has one."""
        if previous is not None and previous.n == len(bodies):
            return previous
        body_shape = np.array([self.shape_index[int(s)] for s in bodies.shape_id], np.int64)
        periodic = self.model.periodic
        scene = SceneContacts(self.shapes, body_shape, [w.patch for w in self.model.walls],
                              cell=None if periodic is None else periodic.cell(),
                              table=self.contact_table(), **contact_options)
        if periodic is not None and scene.n:       # the reach with the scene's skin and margin
            check_cell_reach(self.model, 2.0 * float(scene.radius.max()) + scene.margin
                             + scene.skin)
        return scene


def decompose(comm, sysm: DemSystem, scene: SceneContacts):
    """Decompose the system over the ranks of ``comm`` (a scene carried over from the previous
    step keeps its cut and ghosts); returns the :class:`~nurbsdem.parallel.Domain`."""
    from .parallel import Domain
    old = scene.domain
    sysm.compiled_steps = False
    dom = Domain(comm, sysm, scene, owner=None if old is None else old.owner,
                 plan=None if old is None else old.plan)
    dom.cuts = old.cuts if old is not None else 1
    sysm.domain = scene.domain = dom
    return dom

