"""Result writers (ParaView series, CSV monitors, results.h5), checkpoints, post-processing."""
from __future__ import annotations

import os
import py_compile
import signal
import subprocess
import sys
import textwrap
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import h5py
import meshio
import numpy as np
import pytest

import nurbsdem
from nurbsdem import shapes
from nurbsdem.geometry.generators import box_walls, flat_wall
from nurbsdem.errors import InputError
from nurbsdem.io.checkpoint import load_checkpoint, save_checkpoint
from nurbsdem.io.monitors import CONTACT_COLUMNS, ENERGY_COLUMNS, WALL_COLUMNS, MonitorWriter
from nurbsdem.io.paraview import ParaViewWriter, read_pvd
from nurbsdem.io.results import ResultsWriter, read_results_sample, read_results_times
from nurbsdem.io.writers import OutputWriters
from nurbsdem.geometry.rotation import quat_from_rotvec, quat_to_matrix
from nurbsdem.model import Bodies, WallSpec

ROOT = Path(__file__).resolve().parents[1]


def _bodies(n: int = 3, seed: int = 0) -> Bodies:
    rng = np.random.default_rng(seed)
    return Bodies(id=np.arange(1, n + 1), shape_id=(np.arange(n) % 2) + 1,
                  material_id=np.ones(n), position=rng.uniform(0, 1, (n, 3)),
                  quaternion=quat_from_rotvec(rng.normal(size=(n, 3))),
                  velocity=rng.normal(size=(n, 3)), angular_velocity=rng.normal(size=(n, 3)),
                  line=np.ones(n))


@pytest.fixture(scope="module")
def shape_map():
    return {1: shapes.sphere(0.05), 2: shapes.ellipsoid(0.05, 0.03, 0.02)}


def _walls() -> list[WallSpec]:
    ws = [WallSpec(k + 1, name, p, "box") for k, (name, p) in
          enumerate(box_walls([0, 0, 0], [1, 1, 1]).items())]
    ws.append(WallSpec(6, "lid", flat_wall([0.5, 0.5, 1], [0, 0, -1], (1, 1)), "wall"))
    return ws


def _contacts(k: int) -> dict:
    rng = np.random.default_rng(k)
    return {"point_a": rng.uniform(size=(k, 3)), "point_b": rng.uniform(size=(k, 3)),
            "force_normal": rng.normal(size=(k, 3)), "force_tangential": rng.normal(size=(k, 3)),
            "penetration": rng.uniform(size=k) * 1e-3, "degenerated": np.arange(k) % 3,
            "body_a": np.zeros(k, int), "body_b": np.arange(k)}


def test_paraview_round_trip(tmp_path, shape_map):
    pv = ParaViewWriter(tmp_path, shape_map, _walls(), resolution=4)
    b = _bodies(3)
    for i, t in enumerate([0.0, 0.01, 0.02]):
        disp = np.zeros((6, 3))
        disp[5, 2] = -0.01 * i
        pv.write(t, b, wall_displacement=disp, contacts=_contacts(i))
    pv.sync()                        # the .pvd lists every sample written (PVD_INTERVAL)
    for name in ("particles", "walls", "contacts"):
        entries = read_pvd(tmp_path / f"{name}.pvd")
        assert [t for t, _ in entries] == [0.0, 0.01, 0.02]
        assert [f for _, f in entries] == [f"vtk/{name}_{k:06d}.vtu" for k in range(3)]
        for _, f in entries:
            assert (tmp_path / f).is_file()
    mesh = meshio.read(tmp_path / "vtk" / "particles_000002.vtu")
    assert mesh.cells[0].type == "quad"
    pd = mesh.point_data
    assert set(pd) >= {"particle_id", "shape_id", "velocity", "angular_velocity"}
    assert sorted(set(pd["particle_id"].tolist())) == [1, 2, 3]
    # body 1 is the sphere (shape 1): its points lie at 0.05 from its centroid
    R = quat_to_matrix(b.quaternion)
    pts = mesh.points[pd["particle_id"] == 1]
    # written as float32 (what ParaView renders with): ~1e-7 relative
    np.testing.assert_allclose(np.linalg.norm(pts - b.position[0], axis=1), 0.05, rtol=2e-6)
    sel = pd["particle_id"] == 2
    np.testing.assert_allclose(pd["velocity"][sel], np.broadcast_to(b.velocity[1], (sel.sum(), 3)))
    # ellipsoid: back in its file frame the points satisfy (x/a)^2 + (y/b)^2 + (z/c)^2 = 1
    local = (mesh.points[sel] - b.position[1]) @ R[1]
    np.testing.assert_allclose(((local / [0.05, 0.03, 0.02]) ** 2).sum(1), 1.0, rtol=1e-5)  # float32
    walls = meshio.read(tmp_path / "vtk" / "walls_000002.vtu")
    lid = walls.points[walls.point_data["wall_id"] == 6]
    np.testing.assert_allclose(lid[:, 2], 0.98)
    c = meshio.read(tmp_path / "vtk" / "contacts_000002.vtu")
    cc = _contacts(2)
    np.testing.assert_allclose(c.points, 0.5 * (cc["point_a"] + cc["point_b"]))
    np.testing.assert_allclose(c.point_data["force_normal"], cc["force_normal"])
    np.testing.assert_allclose(c.point_data["penetration"], cc["penetration"])
    # zero contacts: a valid, empty grid
    root = ET.parse(tmp_path / "vtk" / "contacts_000000.vtu").getroot()
    assert root.find(".//Piece").get("NumberOfPoints") == "0"


def test_paraview_restart_drops_later_samples(tmp_path, shape_map):
    pv = ParaViewWriter(tmp_path, shape_map, _walls(), resolution=2)
    for t in (0.0, 0.01, 0.02, 0.03):
        pv.write(t, _bodies(2))
    pv.sync()                        # a checkpoint: every sample so far is listed ...
    pv.write(0.04, _bodies(2))       # ... and one written after it is not yet
    assert [t for t, _ in read_pvd(tmp_path / "particles.pvd")] == [0.0, 0.01, 0.02, 0.03]
    assert (tmp_path / "vtk" / "particles_000004.vtu").exists()
    pv2 = ParaViewWriter(tmp_path, shape_map, _walls(), resolution=2, restart_time=0.01)
    assert [t for t, _ in read_pvd(tmp_path / "particles.pvd")] == [0.0, 0.01]
    assert not (tmp_path / "vtk" / "particles_000002.vtu").exists()
    assert not (tmp_path / "vtk" / "particles_000004.vtu").exists()   # unlisted: removed
    pv2.write(0.02, _bodies(2))
    pv2.close()
    entries = read_pvd(tmp_path / "particles.pvd")
    assert entries[-1] == (0.02, "vtk/particles_000002.vtu")
    # a fresh start empties the series
    ParaViewWriter(tmp_path, shape_map, _walls(), resolution=2)
    assert read_pvd(tmp_path / "particles.pvd") == []
    assert not list((tmp_path / "vtk").glob("particles_*.vtu"))


def _rows(path: Path) -> list[str]:
    return path.read_text().splitlines()


def test_monitor_headers_and_rows(tmp_path):
    m = MonitorWriter(tmp_path, ["bottom", "lid"])
    err = m.energy(0.0, kinetic=1.0, potential=2.0, elastic=0.5, dissipated=0.0, external_work=0.0)
    assert err == 0.0
    err = m.energy(0.001, kinetic=0.5, potential=2.0, elastic=0.5, dissipated=0.25, external_work=0.0)
    assert err == pytest.approx(-0.25)
    m.contacts(0.001, 10, 4, 1, 0)
    m.wall("lid", 0.001, [0, 0, -0.001], [0, 0, 12.5], [0.5, -0.25, 0], 0.125)
    m.wall("lid", 0.003, [0, 0, -0.002], [0, 0, 12.5], [0.5, -0.25, 0], 0.25)
    d = tmp_path / "monitors"
    assert _rows(d / "energy.csv")[0] == \
        "time,kinetic,potential,elastic,dissipated,external_work,mechanical,balance_error"
    assert _rows(d / "contacts.csv")[0] == "time,monitored,active,degenerated,failed"
    for name in ("bottom", "lid"):
        assert _rows(d / f"wall_{name}.csv")[0] == ("time,displacement_x,displacement_y,"
                                                    "displacement_z,reaction_x,reaction_y,reaction_z,"
                                                    "torque_x,torque_y,torque_z,work,power")
    assert ",".join(ENERGY_COLUMNS) == _rows(d / "energy.csv")[0]
    assert ",".join(CONTACT_COLUMNS) == _rows(d / "contacts.csv")[0]
    assert ",".join(WALL_COLUMNS) == _rows(d / "wall_lid.csv")[0]
    # rows are flushed as written (readable before close)
    assert _rows(d / "contacts.csv")[1] == "0.001,10,4,1,0"
    assert _rows(d / "energy.csv")[2] == "0.001,0.5,2.0,0.5,0.25,0.0,3.0,-0.25"
    # the power: the work's mean rate since the wall's previous row (0 on the first)
    assert _rows(d / "wall_lid.csv")[1] == \
        "0.001,0.0,0.0,-0.001,0.0,0.0,12.5,0.5,-0.25,0.0,0.125,0.0"
    assert _rows(d / "wall_lid.csv")[2] == \
        "0.003,0.0,0.0,-0.002,0.0,0.0,12.5,0.5,-0.25,0.0,0.25,62.5"
    data = np.genfromtxt(d / "energy.csv", delimiter=",", names=True)
    assert data["mechanical"][0] == 3.5
    m.close()


def test_monitor_restart_truncates(tmp_path):
    m = MonitorWriter(tmp_path, ["lid"])
    for k in range(5):
        t = k * 0.001
        m.energy(t, 1.0 + k, 0.0, 0.0, 0.0, 0.0)
        m.contacts(t, k, k, 0, 0)
    m.close()
    with open(tmp_path / "monitors" / "contacts.csv", "a") as fh:
        fh.write("0.005,7,")  # a row cut by a crash
    m2 = MonitorWriter(tmp_path, ["lid"], restart_time=0.002)
    assert _rows(tmp_path / "monitors" / "contacts.csv")[1:] == \
        ["0.0,0,0,0,0", "0.001,1,1,0,0", "0.002,2,2,0,0"]
    # the balance reference survives the restart: first row had total 1.0
    assert m2.energy(0.003, 1.0, 0.0, 0.0, 0.0, 0.0) == 0.0
    m2.contacts(0.003, 3, 3, 0, 0)
    m2.close()
    rows = _rows(tmp_path / "monitors" / "contacts.csv")
    assert rows[-1] == "0.003,3,3,0,0" and len(rows) == 5
    m3 = MonitorWriter(tmp_path, ["lid"], restart_time=10.0)
    m3.contacts(0.004, 4, 4, 0, 0)
    m3.close()
    assert len(_rows(tmp_path / "monitors" / "contacts.csv")) == 6


def test_a_restart_keeps_the_rows_of_a_wall_monitor_without_the_work_columns(tmp_path):
    """A wall monitor written before the work and power columns existed: its rows up to the
    restart stay, those columns NaN; the power of the first new row is NaN too (no work
    before it), the next one's is the work's rate."""
    d = tmp_path / "monitors"
    d.mkdir()
    old = ",".join(WALL_COLUMNS[:-2])
    (d / "wall_lid.csv").write_text(old + "\n" + "".join(
        f"{0.001 * k!r},0.0,0.0,0.0,0.0,0.0,{k}.0,0.0,0.0,0.0\n" for k in range(4)))
    m = MonitorWriter(tmp_path, ["lid"], restart_time=0.002)
    m.wall("lid", 0.003, [0, 0, 0], [0, 0, 3.0], [0, 0, 0], 1.0)
    m.wall("lid", 0.004, [0, 0, 0], [0, 0, 4.0], [0, 0, 0], 1.5)
    m.close()
    rows = _rows(d / "wall_lid.csv")
    assert rows[0] == ",".join(WALL_COLUMNS)
    assert rows[1:4] == [f"{0.001 * k!r},0.0,0.0,0.0,0.0,0.0,{k}.0,0.0,0.0,0.0,nan,nan"
                         for k in range(3)]
    assert rows[4].endswith(",1.0,nan")
    data = np.genfromtxt(d / "wall_lid.csv", delimiter=",", names=True)
    assert data["power"][-1] == pytest.approx(500.0, rel=1e-12)


def test_results_h5(tmp_path):
    path = tmp_path / "results.h5"
    w = ResultsWriter(path, deck_text="Materials\n  Material 1 Density 1\n", deck_path="x.inp",
                      flush_every=2)
    b3, b5 = _bodies(3, 1), _bodies(5, 2)
    w.append(0.0, b3)
    w.append(0.01, b3)   # flushed here
    w.append(0.02, b5)   # N changes (Replicate)
    with h5py.File(path, "r") as f:
        assert f["time"].shape == (2,)
    w.close()
    with h5py.File(path, "r") as f:
        assert f.attrs["deck"] == "Materials\n  Material 1 Density 1\n"
        assert f.attrs["nurbsdem_version"] == nurbsdem.__version__
        assert f.attrs["deck_path"] == "x.inp"
        np.testing.assert_array_equal(f["count"][:], [3, 3, 5])
        np.testing.assert_array_equal(f["offset"][:], [0, 3, 6, 11])
    np.testing.assert_array_equal(read_results_times(path), [0.0, 0.01, 0.02])
    s = read_results_sample(path, -1)
    assert s["time"] == 0.02
    np.testing.assert_array_equal(s["position"], b5.position)
    np.testing.assert_array_equal(s["quaternion"], b5.quaternion)
    np.testing.assert_array_equal(s["particle_id"], b5.id)
    np.testing.assert_array_equal(read_results_sample(path, 1)["angular_velocity"],
                                  b3.angular_velocity)
    # restart at 0.01 drops the last sample
    w2 = ResultsWriter(path, restart_time=0.01)
    np.testing.assert_array_equal(read_results_times(path), [0.0, 0.01])
    w2.append(0.015, b5)
    w2.close()
    np.testing.assert_array_equal(read_results_times(path), [0.0, 0.01, 0.015])
    with h5py.File(path, "r") as f:
        assert f["position"].shape == (11, 3)
        assert f.attrs["deck"].startswith("Materials")


@pytest.mark.skipif(not (ROOT / "inputs/shapes/A.yaml").is_file(), reason="paper shapes missing")
def test_output_writers_from_paper_model(tmp_path):
    from nurbsdem.io.deck import parse_deck
    m = parse_deck(ROOT / "inputs" / "paper" / "compaction.inp")
    m.output.directory = tmp_path / "results"
    out = OutputWriters(m)
    out.paraview.write(0.0, m.bodies, np.zeros((6, 3)), None)
    out.monitors.energy(0.0, 0, 1, 0, 0, 0)
    out.monitors.wall("lid", 0.0, [0, 0, 0], [0, 0, 0], [0, 0, 0], 0.0)
    out.results.append(0.0, m.bodies)
    out.sync()
    out.close()
    d = tmp_path / "results"
    assert sorted(p.name for p in (d / "monitors").iterdir()) == sorted(
        ["energy.csv", "contacts.csv"] + [f"wall_{n}.csv" for n in m.wall_names])
    mesh = meshio.read(d / "vtk" / "particles_000000.vtu")
    from nurbsdem.geometry.tessellate import tessellate_shape
    per_shape = {k: len(tessellate_shape(e.shape, 8)[1]) for k, e in m.shapes.items()}
    assert len(mesh.cells[0].data) == sum(per_shape[int(s)] for s in m.bodies.shape_id)
    assert read_results_sample(d / "results.h5", 0)["position"].shape == (14, 3)
    # a second sample, then a restart from t = 0 drops it everywhere
    out = OutputWriters(m, restart_time=0.0)
    for name in ("particles", "walls", "contacts"):
        assert len(read_pvd(d / f"{name}.pvd")) == 1
    out.paraview.write(0.01, m.bodies, None, None)
    out.monitors.energy(0.01, 0, 1, 0, 0, 0)
    out.results.append(0.01, m.bodies)
    out.close()
    out = OutputWriters(m, restart_time=0.0)
    out.close()
    np.testing.assert_array_equal(read_results_times(d / "results.h5"), [0.0])
    assert len(_rows(d / "monitors" / "energy.csv")) == 2
    assert [t for t, _ in read_pvd(d / "particles.pvd")] == [0.0]


# ---------------------------------------------------------------------------- checkpoint


def _state() -> dict:
    return {
        "time": 1.25, "step": 7, "name": "Step 3", "flag": True, "none": None,
        "bodies": {"position": np.arange(12.0).reshape(4, 3),
                   "id": np.arange(4, dtype=np.int64), "mask": np.array([True, False]),
                   "small": np.arange(3, dtype=np.int8), "f32": np.float32(0.5),
                   "big_endian": np.arange(3, dtype=">f8")},
        "history": {17: np.zeros(3), 42: np.ones(3)},
        "empty": np.zeros((0, 3)), "labels": np.array(["lid", "bottom"]),
        "pairs": [(1, 2), (3, 4)], "blob": b"\x00\x01", "huge": 2 ** 80, "z": 1 - 2j,
        "nested": {"a": {"b": {"c": np.array(3.0)}}}, "empty_dict": {}, "empty_list": [],
    }


def _assert_same(a, b, where="state"):
    assert type(a) is type(b), f"{where}: {type(a)} vs {type(b)}"
    if isinstance(a, dict):
        assert list(a) == list(b), where
        for k in a:
            _assert_same(a[k], b[k], f"{where}/{k}")
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b)
        for i, (x, y) in enumerate(zip(a, b)):
            _assert_same(x, y, f"{where}[{i}]")
    elif isinstance(a, (np.ndarray, np.generic)):
        assert a.dtype == b.dtype and np.shape(a) == np.shape(b), where
        assert np.asarray(a).tobytes() == np.asarray(b).tobytes(), where
    else:
        assert a == b, where


def test_checkpoint_round_trip(tmp_path):
    st = _state()
    save_checkpoint(tmp_path / "ck.h5", st)
    _assert_same(st, load_checkpoint(tmp_path / "ck.h5"))
    with h5py.File(tmp_path / "ck.h5", "r") as f:
        assert f.attrs["nurbsdem_version"] == nurbsdem.__version__


def test_checkpoint_reads_format_1(tmp_path):
    """A checkpoint of the earlier layout (a dataset per value; tests/data, written by the
    version before format 2 from this state) still loads exactly."""
    data = Path(__file__).parent / "data" / "checkpoint_format1.h5"
    with h5py.File(data, "r") as f:
        assert f.attrs["format"] == "nurbsdem-checkpoint-1"
    _assert_same(_state(), load_checkpoint(data))


def test_checkpoint_is_two_datasets_whatever_it_holds(tmp_path):
    """Format 2 packs every value into one data set and a manifest (HDF5 objects cost ~0.2 ms
    each to create: the reason for the packing)."""
    state = {f"v{i}": {"a": np.full(i, float(i)), "s": "x" * i, "n": i} for i in range(60)}
    save_checkpoint(tmp_path / "ck.h5", state)
    with h5py.File(tmp_path / "ck.h5", "r") as f:
        assert sorted(f.keys()) == ["data", "manifest"]
        assert f.attrs["format"] == "nurbsdem-checkpoint-2"
    _assert_same(state, load_checkpoint(tmp_path / "ck.h5"))


def test_checkpoint_with_a_damaged_manifest_is_an_input_error(tmp_path):
    path = tmp_path / "ck.h5"
    save_checkpoint(path, {"a": np.arange(4.0), "b": b"xyz"})
    for damage in (b'{"dict":[["a",{"ndarray":["<f8",[4],0,320]}]]}', b"{not json",
                   b'{"nothing":1}'):
        with h5py.File(path, "r+") as f:
            del f["manifest"]
            f["manifest"] = np.frombuffer(damage, np.uint8)
        with pytest.raises(InputError, match="corrupted checkpoint"):
            load_checkpoint(path)


def test_checkpoint_rejects_unstorable(tmp_path):
    with pytest.raises(TypeError):
        save_checkpoint(tmp_path / "ck.h5", {"x": object()})
    with pytest.raises(TypeError):
        save_checkpoint(tmp_path / "ck.h5", {"x": np.array([None, 1], dtype=object)})
    with pytest.raises(ValueError):
        save_checkpoint(tmp_path / "ck.h5", {"a/b": 1})
    assert not list(tmp_path.iterdir())  # nothing left behind


def test_checkpoint_failure_mid_write_keeps_old_file(tmp_path):
    path = tmp_path / "ck.h5"
    save_checkpoint(path, {"version": 1, "data": np.arange(10.0)})

    class Boom:
        pass

    # the second value cannot be stored: the write fails after the first was written
    with pytest.raises(TypeError):
        save_checkpoint(path, {"version": 2, "data": np.zeros(10), "bad": Boom()})
    old = load_checkpoint(path)
    assert old["version"] == 1
    np.testing.assert_array_equal(old["data"], np.arange(10.0))
    assert [p.name for p in tmp_path.iterdir()] == ["ck.h5"]


_WRITER = textwrap.dedent("""
    import sys, numpy as np
    from nurbsdem.io.checkpoint import save_checkpoint
    path = sys.argv[1]
    v = 0
    while True:
        v += 1
        save_checkpoint(path, {"version": v, "data": np.full(300_000, float(v)),
                               "more": {"x": np.full((200, 100), v, np.int64)}})
        print(v, flush=True)
""")


def test_checkpoint_survives_kill(tmp_path):
    """SIGKILL a process that rewrites a checkpoint in a loop: the file is always whole."""
    path = tmp_path / "ck.h5"
    script = tmp_path / "writer.py"
    script.write_text(_WRITER)
    rng = np.random.default_rng(0)
    for _ in range(4):
        proc = subprocess.Popen([sys.executable, str(script), str(path)],
                                stdout=subprocess.PIPE, text=True)
        try:
            assert proc.stdout.readline().strip()  # at least one complete save
            time.sleep(float(rng.uniform(0.0, 0.15)))
        finally:
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait()
            proc.stdout.close()
        st = load_checkpoint(path)
        v = st["version"]
        assert v >= 1
        np.testing.assert_array_equal(st["data"], np.full(300_000, float(v)))
        np.testing.assert_array_equal(st["more"]["x"], np.full((200, 100), v))
    # a later save cleans temporaries left by killed writers
    save_checkpoint(path, {"version": 0})
    assert [p.name for p in tmp_path.iterdir() if p.name.endswith(".tmp")] == []


# ---------------------------------------------------------------------------- post-processing


def test_postproc_scripts_compile():
    for name in ("plot_monitors.py", "paraview_view.py"):
        py_compile.compile(str(ROOT / "postproc" / name), doraise=True)


def test_plot_monitors(tmp_path):
    pytest.importorskip("matplotlib")
    m = MonitorWriter(tmp_path, ["bottom", "lid"])
    for k in range(50):
        t = k * 0.01
        m.energy(t, np.exp(-t), -t, 0.1, t / 2, 0.0)
        m.contacts(t, 20 + k, 10 + k // 2, k // 10, 0)
        m.wall("bottom", t, [0, 0, 0], [0, 0, 5.0], [0, 0, 0], 0.0)
        dz = -0.08 * min(k, 25) / 25 + 0.08 * max(k - 25, 0) / 25
        m.wall("lid", t, [0, 0, dz], [0, 0, 100 * -dz + (5 if k < 25 else 0)], [0, 0, 0], 0.0)
    m.close()
    res = subprocess.run([sys.executable, str(ROOT / "postproc" / "plot_monitors.py"),
                          str(tmp_path)], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    for png in ("energy.png", "contacts.png", "lid_reaction.png"):
        assert (tmp_path / png).stat().st_size > 1000
    assert not (tmp_path / "bottom_reaction.png").exists()  # the bottom does not move


def test_plot_wall_skips_tocontact_jump():
    import importlib.util
    spec = importlib.util.spec_from_file_location("plot_monitors", ROOT / "postproc" / "plot_monitors.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    s = np.concatenate([np.zeros(5), [0.05] * 3, 0.05 + 0.001 * np.arange(1, 81)])
    assert mod.continuous_start(s) == 5
    assert mod.continuous_start(0.001 * np.arange(50)) == 0
