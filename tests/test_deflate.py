"""nurbsdem.io.deflate: the zlib streams written for repeated rows without a search inflate
(by zlib itself, an independent inflater) to exactly ``np.repeat(values, counts, axis=0)``,
in VTK's block layout; a .vtu holding them reads back equal in meshio and in ParaView's own
VTK reader (``pvpython``, where installed)."""
from __future__ import annotations

import shutil
import subprocess
import textwrap
import zlib

import meshio
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from nurbsdem.io.deflate import encode_repeated
from nurbsdem.io.vtu import BLOCK, Repeated, encode, vtu_bytes


def _inflate(pieces: list[bytes]) -> tuple[np.ndarray, bytes]:
    """(header, the inflated bytes of all blocks) of one appended DataArray; every block is
    checked to inflate to the size the header gives (zlib checks its Adler-32)."""
    data = b"".join(pieces)
    n = int(np.frombuffer(data[:4], np.uint32)[0])
    header = np.frombuffer(data[:4 * (3 + n)], np.uint32)
    out, off = [], 4 * (3 + n)
    for k, size in enumerate(header[3:]):
        block = zlib.decompress(data[off:off + int(size)])
        assert len(block) == (header[2] if k == n - 1 else header[1])
        out.append(block)
        off += int(size)
    assert off == len(data)
    return header, b"".join(out)


DTYPES = (np.float32, np.float64, np.int64, np.int32, np.uint8)


@settings(max_examples=100, deadline=None)
@given(rows=st.integers(0, 30), comps=st.integers(1, 4), dtype=st.sampled_from(DTYPES),
       counts=st.lists(st.integers(0, 3000), min_size=30, max_size=30),
       block=st.sampled_from([BLOCK, 1000, 12, 7, 1]), seed=st.integers(0, 2**31))
def test_inflates_to_the_repeated_rows(rows, comps, dtype, counts, block, seed):
    """Any rows, counts (0 included), dtypes and block sizes (blocks that cut a row, blocks
    of one byte): the bytes inflated are the repeated array's, block sizes as in the
    header."""
    values = (np.random.default_rng(seed).normal(size=(rows, comps)) * 100).astype(dtype)
    c = np.array(counts[:rows], np.int64)
    header, raw = _inflate(encode_repeated(values, c, block))
    expect = np.repeat(values, c, axis=0).tobytes()
    assert raw == expect
    assert header[1] == block and header[0] == -(-len(expect) // block)


def test_header_as_zlibs_and_smaller():
    """The paper example's particles (112 bodies, 600 points each, float32 velocities): the
    same header fields as zlib's own blocks (vtu.encode) but the compressed sizes, and not
    larger than zlib at level 1 by more than a quarter (fixed Huffman codes: ~8.0 against
    7.0 kB, of a 1.2 MB sample)."""
    values = np.random.default_rng(3).normal(size=(112, 3)).astype(np.float32)
    counts = np.full(112, 600)
    ours = encode_repeated(values, counts)
    theirs = encode(np.repeat(values, counts, axis=0))
    h_ours, raw = _inflate(ours)
    h_theirs = np.frombuffer(theirs[0], np.uint32)
    assert raw == np.repeat(values, counts, axis=0).tobytes()
    np.testing.assert_array_equal(h_ours[:3], h_theirs[:3])
    assert sum(map(len, ours)) <= 1.25 * sum(map(len, theirs))


def test_bad_rows_and_counts():
    with pytest.raises(ValueError, match="one non-negative count per row"):
        encode_repeated(np.zeros((2, 3)), [1, -1])
    with pytest.raises(ValueError, match="one non-negative count per row"):
        encode_repeated(np.zeros((2, 3)), [1])
    with pytest.raises(ValueError, match="deflate reaches"):
        encode_repeated(np.zeros((1, 5000)), [2])


def test_a_vtu_with_repeated_point_data_reads_back(tmp_path):
    """Point data given as Repeated reads back in meshio as the spelled-out array (floats as
    Float32, like any point data)."""
    rng = np.random.default_rng(4)
    counts = rng.integers(1, 900, 40)
    n = int(counts.sum())
    pts = rng.normal(size=(n, 3))
    v = rng.normal(size=(40, 3))
    cells = [("vertex", np.arange(n, dtype=np.int64).reshape(-1, 1))]
    path = tmp_path / "r.vtu"
    path.write_bytes(vtu_bytes(pts, cells, {"velocity": Repeated(v, counts)}))
    mesh = meshio.read(path)
    np.testing.assert_array_equal(mesh.point_data["velocity"],
                                  np.repeat(v, counts, axis=0).astype(np.float32))
    np.testing.assert_array_equal(np.asarray(Repeated(v, counts)), np.repeat(v, counts, axis=0))


PV_READ = textwrap.dedent("""
    import sys
    import numpy as np
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader
    r = vtkXMLUnstructuredGridReader()
    r.SetFileName(sys.argv[1])
    r.Update()
    np.save(sys.argv[2], vtk_to_numpy(r.GetOutput().GetPointData().GetArray("velocity")))
""")


@pytest.mark.skipif(shutil.which("pvpython") is None,
                    reason="ParaView's pvpython is not installed (Debian: python3-paraview)")
def test_paraview_reads_the_repeated_rows(tmp_path):
    """ParaView's own reader (vtkXMLUnstructuredGridReader in pvpython) inflates the streams to
    the spelled-out array, bit for bit."""
    rng = np.random.default_rng(5)
    counts = rng.integers(1, 900, 40)
    n = int(counts.sum())
    v = rng.normal(size=(40, 3))
    path = tmp_path / "r.vtu"
    path.write_bytes(vtu_bytes(rng.normal(size=(n, 3)),
                               [("vertex", np.arange(n, dtype=np.int64).reshape(-1, 1))],
                               {"velocity": Repeated(v, counts)}))
    script = tmp_path / "read.py"
    script.write_text(PV_READ)
    subprocess.run(["pvpython", str(script), str(path), str(tmp_path / "got.npy")], check=True,
                   capture_output=True, timeout=300)
    np.testing.assert_array_equal(np.load(tmp_path / "got.npy"),
                                  np.repeat(v, counts, axis=0).astype(np.float32))
