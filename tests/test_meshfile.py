"""Mesh files of equipment (nurbsdem.io.meshfile): the three formats, placement, one clear
line for each bad file, and a file read once while it is unchanged."""
import os

import numpy as np
import pytest
import trimesh

from nurbsdem.errors import InputError
from nurbsdem.io.meshfile import read_wall_mesh, size_mismatch


@pytest.mark.parametrize("suffix", [".stl", ".obj", ".ply"])
def test_formats_read_the_same_placed_box(tmp_path, suffix):
    box = trimesh.creation.box(extents=(2.0, 4.0, 6.0))
    path = tmp_path / f"box{suffix}"
    box.export(path)
    got = read_wall_mesh(path, scale=0.5, position=(1, 2, 3), rotation=(0, 0, np.pi / 2))
    assert got.faces.shape == (12, 3) and got.vertices.shape == (8, 3)
    assert got.warnings == []
    # half size, turned 90 degrees about z (x <-> y), centred at (1, 2, 3)
    assert np.allclose(got.vertices.min(axis=0), [1 - 1.0, 2 - 0.5, 3 - 1.5], atol=1e-12)
    assert np.allclose(got.vertices.max(axis=0), [1 + 1.0, 2 + 0.5, 3 + 1.5], atol=1e-12)


def test_a_nan_vertex_in_a_ply_is_refused(tmp_path):
    path = tmp_path / "bad.ply"
    path.write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                    "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                    "end_header\n0 0 0\n1 0 0\nnan 1 0\n3 0 1 2\n")
    with pytest.raises(InputError, match=r"deck.inp:4: bad.ply: vertex 2 is not finite"):
        read_wall_mesh(path, where="deck.inp:4")


def test_degenerate_triangles_are_dropped_with_their_count(tmp_path):
    """A zero-area triangle adds no surface: dropped, the warning gives how many; its vertex
    that no other triangle uses goes with it. A file of such triangles only is refused."""
    mesh = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [3, 0, 0]],
                           [[0, 1, 2], [0, 1, 3], [1, 2, 4]], process=False)
    path = tmp_path / "flat.ply"
    mesh.export(path)
    got = read_wall_mesh(path)
    assert got.faces.shape == (1, 3) and got.vertices.shape == (3, 3)
    assert got.warnings == ["flat.ply: 2 degenerate triangles (zero area, their vertices on a "
                            "line) dropped"]
    line = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [2, 0, 0]], [[0, 1, 2]], process=False)
    line.export(tmp_path / "line.ply")
    with pytest.raises(InputError, match=r"deck.inp:3: line.ply: all its 1 triangles are "
                                         r"degenerate"):
        read_wall_mesh(tmp_path / "line.ply", where="deck.inp:3")


def test_duplicate_vertices_are_merged_without_a_warning(tmp_path):
    """An OBJ whose two triangles each repeat the shared vertices: one square of 4 vertices,
    its diagonal shared, no warning."""
    path = tmp_path / "square.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 0 0\nv 1 1 0\nv 0 1 0\n"
                    "f 1 2 3\nf 4 5 6\n")
    got = read_wall_mesh(path)
    assert got.vertices.shape == (4, 3) and got.warnings == []
    assert len(set(map(int, got.faces[0])) & set(map(int, got.faces[1]))) == 2


def test_non_manifold_and_duplicate_triangles_warn(tmp_path):
    verts = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1]]
    mesh = trimesh.Trimesh(verts, [[0, 1, 2], [0, 1, 3], [0, 1, 4], [0, 1, 4]], process=False)
    path = tmp_path / "fan.ply"
    mesh.export(path)
    got = read_wall_mesh(path)
    text = " ".join(got.warnings)
    assert "shared by more than two triangles" in text and "duplicate triangles" in text
    with pytest.raises(InputError, match=r"deck.inp:9: fan.ply: 1 edges are shared by more "
                                         r"than two triangles .*one-sided wall needs a front"):
        read_wall_mesh(path, where="deck.inp:9", one_sided=True)


def test_a_one_sided_mesh_whose_fronts_disagree_is_warned_of(tmp_path):
    """Two triangles of a square whose vertex orders make their fronts face opposite ways:
    a warning for a one-sided wall (part of it faces away), none for a two-sided shell."""
    mesh = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]],
                           [[0, 1, 2], [0, 3, 2]], process=False)
    path = tmp_path / "flipped.ply"
    mesh.export(path)
    assert read_wall_mesh(path).warnings == []
    (text,) = read_wall_mesh(path, one_sided=True).warnings
    assert text.startswith("flipped.ply: 1 edges join triangles whose fronts")


@pytest.mark.parametrize("make, match", [
    (lambda d: d / "none.stl", "no such mesh file"),
    (lambda d: (d / "folder.stl").mkdir() or d / "folder.stl", "is a folder"),
    (lambda d: d / "drum.step", "is not a mesh file"),
    (lambda d: (d / "empty.stl").write_text("solid x\nendsolid x\n") and d / "empty.stl",
     "holds no triangles|cannot read"),
])
def test_bad_paths_say_what_is_wrong(tmp_path, make, match):
    with pytest.raises(InputError, match=match):
        read_wall_mesh(make(tmp_path))


def test_size_mismatch_flags_millimetres():
    assert "millimetres" in size_mismatch(500.0, 0.01, "drum.stl")
    assert "smaller than one particle" in size_mismatch(0.005, 0.01, "drum.stl")
    assert size_mismatch(0.5, 0.01, "drum.stl") is None


def test_an_unchanged_file_is_read_once_and_a_changed_one_again(tmp_path, monkeypatch):
    """The deck's parse, the solver and the writers read a mesh file in turn: the file is read
    once while it stays the same, each caller gets its own arrays, placed its own way."""
    from nurbsdem.io import meshfile
    reads, read = [], meshfile._read

    def counted(path, where):
        reads.append(path)
        return read(path, where)
    monkeypatch.setattr(meshfile, "_read", counted)
    path = tmp_path / "box.stl"
    trimesh.creation.box(extents=(2.0, 4.0, 6.0)).export(path)
    first = read_wall_mesh(path)
    first.vertices[:] = 0.0                               # a caller's own copy
    moved = read_wall_mesh(path, scale=0.5, position=(1, 2, 3))
    assert len(reads) == 1
    assert np.allclose(moved.vertices.max(axis=0), [1.5, 3.0, 4.5], atol=1e-12)
    trimesh.creation.box(extents=(1.0, 1.0, 1.0)).export(path)     # as long a file
    os.utime(path, ns=(path.stat().st_atime_ns, path.stat().st_mtime_ns + 10**9))
    assert np.allclose(read_wall_mesh(path).vertices.max(axis=0), 0.5, atol=1e-12)
    assert len(reads) == 2
