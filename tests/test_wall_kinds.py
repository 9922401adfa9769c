"""The curved wall kinds (nurbsdem/contact/wall_kinds.py) and their deck entries
(nurbsdem/io/deck_curved.py): one registry each, which must agree, and the dispatch by a
wall's geometry."""
from __future__ import annotations

import numpy as np
import pytest

from nurbsdem.contact.kinds import MESH_WALL, SURFACE_WALL
from nurbsdem.contact.mesh_wall import build_mesh_wall
from nurbsdem.contact.surface_wall import build_surface_wall
from nurbsdem.contact.wall_kinds import WALL_KINDS, kind_named, kind_of
from nurbsdem.geometry.surfaces import cylinder_patch
from nurbsdem.io.deck_curved import CURVED_WALL_FILES
from nurbsdem.io.deck_schema import SCHEMA

COMMON = {"Name", "File", "Position", "Rotation", "Material"}


def test_every_kind_has_one_deck_entry_with_the_keys_it_reads():
    """Each contact kind has its deck entry and the reverse; an entry's keys are the common
    ones and its own, exactly as the deck schema lists them."""
    assert {k.name for k in WALL_KINDS} == set(CURVED_WALL_FILES)
    assert len({k.code for k in WALL_KINDS}) == len(WALL_KINDS)
    for name, f in CURVED_WALL_FILES.items():
        assert kind_named(name).name == f.name == name
        assert set(SCHEMA["Walls"][f.keyword].keys) == COMMON | f.keys


def test_a_walls_geometry_names_its_kind():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    mesh = build_mesh_wall(v, np.array([[0, 1, 2]]))
    surface = build_surface_wall([cylinder_patch(0.1, 0.2)])
    assert kind_of(mesh).code == MESH_WALL and kind_of(surface).code == SURFACE_WALL
    pts, pad = kind_of(mesh).box_points(mesh)
    assert np.array_equal(pts, v) and pad == 0.0
    pts, pad = kind_of(surface).box_points(surface)
    assert pts is surface.seed_x and pad == surface.spacing > 0
    with pytest.raises(TypeError, match="no curved wall kind"):
        kind_of(v)
    with pytest.raises(KeyError):
        kind_named("cone")


def test_the_kinds_pack_disjoint_fields_that_complete_the_compiled_walls():
    """Each kind packs its own fields of the compiled deck steps' walls and workspaces: no
    field twice, and with the fields ``pack_curved`` packs itself (poses, boxes, particles,
    outputs) exactly those of CurvedConst and CurvedWork; a field packed twice raises."""
    from nurbsdem.contact import curved_compiled as cc
    common_const = {"n_walls", "first", "nb", "radius", "kind", "omega", "center", "t0", "R0",
                    "shift0", "corners", "reach", "sphere", "nurbs", "body_shape", "n_nurbs",
                    "ptab", "pinfo", "pcen", "prad", "pseeds"}
    common_work = {"mark", "out_a", "out_b", "out_pa", "out_pb", "out_normal", "out_depth",
                   "out_key", "count"}
    const = {k: None for k in common_const}
    for kind in WALL_KINDS:
        cc._add_fields(const, kind.packed([], False), kind.name)
    assert set(const) == set(cc.CurvedConst._fields)
    work = {k: None for k in common_work}
    for kind in WALL_KINDS:
        cc._add_fields(work, kind.packed_work([], 0, const), kind.name)
    assert set(work) == set(cc.CurvedWork._fields)
    with pytest.raises(ValueError, match="mesh wall kind packs fields already packed"):
        cc._add_fields(const, {"faces": None}, "mesh")
