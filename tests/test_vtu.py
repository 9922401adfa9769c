"""nurbsdem.io.vtu: the .vtu files read back by meshio (an independent reader; ParaView's own
reader in test_paraview.py) with every array equal, arrays reused while their key holds and
encoded again when it changes."""
from __future__ import annotations

import meshio
import numpy as np

from nurbsdem.io.vtu import BLOCK, Reuse, vtu_bytes


def _grid(rng, n_quads: int, ids_from: int):
    pts = rng.normal(size=(4 * n_quads, 3))
    quads = np.arange(4 * n_quads, dtype=np.int64).reshape(-1, 4)[:, ::-1].copy()
    pd = {"particle_id": np.repeat(np.arange(ids_from, ids_from + n_quads), 4),
          "velocity": rng.normal(size=(4 * n_quads, 3))}
    cd = {"patch_id": [np.arange(n_quads, dtype=np.int64) % 6]}
    return pts, quads, pd, cd


def _read(path, content):
    path.write_bytes(content)
    return meshio.read(path)


def _same(mesh, pts, quads, pd, cd):
    np.testing.assert_array_equal(mesh.points, pts.astype(np.float32))
    assert mesh.cells[0].type == "quad"
    np.testing.assert_array_equal(mesh.cells[0].data, quads)
    np.testing.assert_array_equal(mesh.point_data["particle_id"], pd["particle_id"])
    np.testing.assert_array_equal(mesh.point_data["velocity"], pd["velocity"].astype(np.float32))
    np.testing.assert_array_equal(mesh.cell_data["patch_id"][0], cd["patch_id"][0])


def test_a_grid_of_several_blocks_reads_back_equal(tmp_path):
    """20 000 quads: every array spans several zlib blocks of BLOCK bytes."""
    pts, quads, pd, cd = _grid(np.random.default_rng(1), 20000, 0)
    assert quads.nbytes > 10 * BLOCK
    _same(_read(tmp_path / "a.vtu", vtu_bytes(pts, [("quad", quads)], pd, cd)), pts, quads, pd, cd)


def test_reused_arrays_follow_their_key(tmp_path):
    """The same key reuses the encoded ids (the text is not encoded again); a new key (other
    bodies) encodes them anew, and each file reads back as its own arrays."""
    rng = np.random.default_rng(2)
    reuse = Reuse(("connectivity", "offsets", "types", "particle_id", "patch_id"))
    a = _grid(rng, 50, 0)
    _same(_read(tmp_path / "a.vtu", vtu_bytes(a[0], [("quad", a[1])], a[2], a[3], reuse, "A")), *a)
    kept = dict(reuse._encoded)
    a2 = (a[0] + 1.0, a[1], a[2], a[3])                  # the bodies moved: same key
    _same(_read(tmp_path / "a2.vtu", vtu_bytes(a2[0], [("quad", a2[1])], a2[2], a2[3], reuse,
                                               "A")), *a2)
    assert all(reuse._encoded[k] is kept[k] for k in kept)
    b = _grid(rng, 80, 100)                              # other bodies: a new key
    _same(_read(tmp_path / "b.vtu", vtu_bytes(b[0], [("quad", b[1])], b[2], b[3], reuse, "B")), *b)


def test_one_vertex_reads_back(tmp_path):
    """A contacts sample of one contact: vertex cells, arrays shorter than one block."""
    pts = np.array([[0.1, 0.2, 0.3]])
    mesh = _read(tmp_path / "c.vtu", vtu_bytes(pts, [("vertex", np.zeros((1, 1), np.int64))],
                                              {"penetration": np.array([1e-4]),
                                               "body_a": np.array([3])}))
    assert mesh.cells[0].type == "vertex" and len(mesh.points) == 1
    np.testing.assert_array_equal(mesh.point_data["penetration"], np.float32([1e-4]))
    np.testing.assert_array_equal(mesh.point_data["body_a"], [3])


def _appended_arrays(content: bytes) -> dict:
    """The arrays of a file of :func:`vtu_bytes`, decoded by hand from its AppendedData (raw
    UInt32 header + zlib blocks per array; meshio cannot read a grid without cells)."""
    import xml.etree.ElementTree as ET
    import zlib
    start = content.index(b"<AppendedData")
    data = content[content.index(b"_", start) + 1:]
    root = ET.fromstring(content[:start] + b"</VTKFile>")
    out = {}
    for da in root.iter("DataArray"):
        off = int(da.get("offset"))
        n = int(np.frombuffer(data[off:off + 4], np.uint32)[0])
        head = np.frombuffer(data[off:off + 4 * (3 + n)], np.uint32)
        pos, raw = off + 4 * (3 + n), b""
        for size in head[3:]:
            raw += zlib.decompress(data[pos:pos + int(size)])
            pos += int(size)
        dtype = {"Float32": np.float32, "Int64": np.int64, "UInt8": np.uint8}[da.get("type")]
        out[da.get("Name")] = (head[:3].tolist(), np.frombuffer(raw, dtype))
    return out


def test_arrays_without_rows_are_written_as_zero_blocks():
    """Points without cells: the empty connectivity and an empty (0, 3) cell array are
    written as zero blocks, and the points read back."""
    pts = np.array([[0.1, 0.2, 0.3], [0.4, 0.5, 0.6]])
    arrays = _appended_arrays(vtu_bytes(pts, [("quad", np.zeros((0, 4), np.int64))],
                                        {"velocity": np.ones((2, 3))},
                                        {"force": [np.zeros((0, 3))]}))
    assert arrays["force"][0] == [0, BLOCK, 0] and arrays["connectivity"][0] == [0, BLOCK, 0]
    np.testing.assert_array_equal(arrays["Points"][1], pts.astype(np.float32).ravel())
    np.testing.assert_array_equal(arrays["velocity"][1], np.ones(6, np.float32))
