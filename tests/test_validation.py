"""Every bad input gets one clear answer: whole-scene validation at check time,
numbers in range with the reason, files that are not what they claim, the error path of
the command line, restart checks, and the regression corpus of defect-finding inputs."""
from __future__ import annotations

import warnings
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from nurbsdem.cli import EXIT_INTERNAL_ERROR, main
from nurbsdem.errors import InputError
from nurbsdem.geometry import generators as gen
from nurbsdem.io.checkpoint import load_checkpoint, restart_state, save_checkpoint
from nurbsdem.io.deck import build_model, parse_deck
from nurbsdem.io.giraffe import giraffe_text, import_giraffe
from nurbsdem.io.shapefile import load_shape, save_shape
from nurbsdem.run_report import RunSummary

ROOT = Path(__file__).resolve().parent.parent

DECK = """Environment
  Gravity 0 0 -9.81
Materials
  Material 1 Density 2700
Shapes
  Shape 1 Sphere Radius 0.02
Particles
  Particle 1 Shape 1 Material 1 Position 0.05 0.10 0.10
  Particle 2 Shape 1 Material 1 Position 0.15 0.10 0.10
Walls
  Box 1 Min 0 0 0 Max 0.25 0.25 0.25
  Wall 6 Name lid Point 0.125 0.125 0.25 Normal 0 0 -1 Size 0.25 0.25
Contact
  Interface 1 NormalPenalty 1e5 TangentialPenalty 1e4 NormalDamping 10 Friction 0.5
Steps
  Step 1 Dynamic Duration 0.01 TimeStep 1e-3
  Step 2 Replicate Layers 2 Height 0.08
Output
  Directory results
  VTK Every 0.01 Resolution 4
"""


def _deck(tmp_path: Path, text: str, name: str = "case.inp") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def _refusal(tmp_path: Path, old: str, new: str) -> tuple[str, int | None]:
    assert old in DECK, old
    path = _deck(tmp_path, DECK.replace(old, new, 1))
    with pytest.raises(InputError) as info:
        parse_deck(path)
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith(str(path))
    return msg, info.value.line


P2 = "Particle 2 Shape 1 Material 1 Position 0.15 0.10 0.10"

#: The regression corpus: (what is replaced, by what, a fragment of the answer, its line).
CORPUS = [
    # impossible scenes
    (P2, "Particle 2 Shape 1 Material 1 Position 0.05 0.10 0.10", "at the same place as particle 1", 9),
    (P2, "Particle 2 Shape 1 Material 1 Position 0.06 0.10 0.10", "overlaps particle 1 by 0.03", 9),
    (P2, "Particle 2 Shape 1 Material 1 Position 0.15 0.10 -1", "outside the box", 9),
    (P2, "Particle 2 Shape 1 Material 1 Position 0.15 0.10 0.01", "penetrates wall 'bottom' by 0.01", 9),
    (P2, "Particle 2 Shape 1 Material 1 Position 0.15 0.30 0.10", "outside the box", 9),
    ("Normal 0 0 -1", "Normal 0 0 1", "behind wall 'lid'", 8),
    ("Layers 2 Height 0.08", "Layers 2 Height 1e-300", "the copies would overlap", 17),
    ("Layers 2 Height 0.08", "Layers 3 Height 0.01", "the copies would overlap", 17),
    ("Step 2 Replicate Layers 2 Height 0.08", "Step 2 MoveWall lid ToContact Direction 0 0 1",
     "does not move wall 'lid' towards the particles", 17),
    ("Step 2 Replicate Layers 2 Height 0.08",
     "Step 2 MoveWall lid Displacement 0 0 -0.3 Duration 0.01 TimeStep 1e-3",
     "past wall 'bottom' that faces it 0.25 m away", 17),
    # overflow and degenerate numbers
    ("Max 0.25 0.25 0.25", "Max 1e300 1e300 1e300", "Max 1e+300 m is out of range", 11),
    ("TimeStep 1e-3", "TimeStep 1e-300", "TimeStep 1e-300 s is out of range", 16),
    ("TimeStep 1e-3", "TimeStep 1e-14", "below 1e-09 of the Duration", 16),
    ("TimeStep 1e-3", "TimeStep 3e-3", "is not a whole number of TimeStep", 16),
    ("Layers 2 Height 0.08", "Layers 100000000000000000000000 Height 1", "is too large", 17),
    ("Layers 2 Height 0.08", "Layers 10000000000 Height 1e5", "of memory; this machine has", 17),
    ("Density 2700", "Density 1e-300", "Density 1e-300 kg/m^3 is out of range", 4),
    ("Resolution 4", "Resolution 100000000000000000000000", "is too large", 20),
    ("Resolution 4", "Resolution 1000000", "Resolution 1000000 is out of range", 20),
    ("Resolution 4", "Resolution 9000", "lower Resolution", 20),
    ("Particle 2 ", "Particle 9223372036854775808 ", "is too large", 9),
    ("Sphere Radius 0.02", "Ellipsoid SemiAxes 1e300 1 1", "SemiAxes 1e+300 m is out of range", 6),
    ("Radius 0.02", "Radius 1e-300", "Radius 1e-300 m is out of range", 6),
    ("Radius 0.02", "Radius 1e-12", "out of range", 6),
    (P2, P2 + " Velocity 50 0 0", "no time step can resolve", 9),
    (P2, P2 + " AngularVelocity 1e6 0 0", "(centroid plus spin)", 9),
    ("Sphere Radius 0.02", "Ellipsoid SemiAxes 1e-6 0.02 0.02", "times longer than wide", 6),
    ("Sphere Radius 0.02", "Sphere Radius 0.02 Inertia 1e-30 1e-30 1e-30 0 0 0",
     "internal time steps", 14),
    ("Density 2700", "Density 2700" + "0" * 30, "out of range", 4),
    ("Friction 0.5", "Friction 1e300", "Friction 1e+300 is out of range", 14),
    ("Gravity 0 0 -9.81", "Gravity 0 0 -1e300", "out of range", 2),
    ("Normal 0 0 -1", "Normal 0 0 -1e300", "out of range", 12),
    ("Size 0.25 0.25", "Size 1e-300 0.25", "out of range", 12),
]


@pytest.mark.parametrize("old,new,fragment,line", CORPUS, ids=[c[2][:40] for c in CORPUS])
def test_corpus_is_refused_with_file_line_and_reason(tmp_path, old, new, fragment, line):
    msg, got_line = _refusal(tmp_path, old, new)
    assert fragment in msg
    assert got_line == line


def test_run_needing_too_many_internal_steps_is_refused(tmp_path):
    text = DECK.replace("NormalPenalty 1e5", "NormalPenalty 1e15").replace(
        "Duration 0.01 TimeStep 1e-3", "Duration 1e3 TimeStep 1e-3")
    with pytest.raises(InputError) as info:
        parse_deck(_deck(tmp_path, text))
    assert "internal time steps" in str(info.value) and info.value.line == 14


def test_the_base_deck_is_valid(tmp_path):
    model = parse_deck(_deck(tmp_path, DECK))
    assert len(model.bodies) == 2


def test_touching_bodies_and_walls_are_accepted(tmp_path):
    """Exactly touching (within the stated tolerance) is not an overlap."""
    text = DECK.replace(P2, "Particle 2 Shape 1 Material 1 Position 0.09 0.10 0.02")
    text = text.replace("Position 0.05 0.10 0.10", "Position 0.05 0.10 0.02")
    model = parse_deck(_deck(tmp_path, text))
    assert len(model.bodies) == 2


@pytest.mark.parametrize("deck", sorted((ROOT / "inputs").rglob("*.inp")), ids=lambda p: p.name)
def test_shipped_decks_pass_validation(deck):
    assert parse_deck(deck).bodies is not None


def test_empty_deck_is_refused(tmp_path):
    for text in ("", "# only a comment\n", DECK.split("Steps")[0]):
        with pytest.raises(InputError, match="nothing to solve"):
            parse_deck(_deck(tmp_path, text))


def test_deck_without_particles_is_refused(tmp_path):
    text = DECK.replace(P2 + "\n", "").replace(
        "  Particle 1 Shape 1 Material 1 Position 0.05 0.10 0.10\n", "")
    with pytest.raises(InputError, match="no particles"):
        parse_deck(_deck(tmp_path, text))


# ---------------------------------------------------------------------------- files


def test_deck_with_a_byte_order_mark_and_crlf_is_read(tmp_path):
    path = tmp_path / "bom.inp"
    path.write_bytes(b"\xef\xbb\xbf" + DECK.replace("\n", "\r\n").encode())
    assert len(parse_deck(path).bodies) == 2


def test_binary_deck_is_one_line(tmp_path):
    path = tmp_path / "bin.inp"
    path.write_bytes(DECK.encode()[:50] + b"\xff\xfe\x00" + DECK.encode()[50:])
    with pytest.raises(InputError, match="not a UTF-8 text file"):
        parse_deck(path)


def _sphere_yaml(tmp_path) -> Path:
    f = tmp_path / "s.yaml"
    save_shape(f, gen.sphere_patches(0.02), name="s")
    return f


@pytest.mark.parametrize("text,fragment", [
    ("a: " + "[" * 3000, "nested deeper"),
    ("patches: &a [*a]", "aliases"),
    ("patches:\n- degree_u: " + "9" * 5000 + "\n", "invalid value"),
])
def test_hostile_yaml_is_one_input_error(tmp_path, text, fragment):
    f = tmp_path / "h.yaml"
    f.write_text(text)
    with pytest.raises(InputError, match=fragment):
        load_shape(f)


def test_non_utf8_shape_file(tmp_path):
    f = tmp_path / "b.yaml"
    f.write_bytes(b"patches: \xff\xfe")
    with pytest.raises(InputError, match="not a UTF-8 text file"):
        load_shape(f)


def test_shape_file_with_huge_control_point(tmp_path):
    import yaml

    from nurbsdem.io.shapefile import shape_to_data
    data = shape_to_data(gen.sphere_patches(0.02))
    data["patches"][2]["control_points"][1][1][0] = 1e300
    f = tmp_path / "big.yaml"
    f.write_text(yaml.safe_dump(data))
    with pytest.raises(InputError, match="beyond 1e\\+06 m"):
        load_shape(f)


def test_shape_error_inside_a_deck_keeps_the_deck_line(tmp_path):
    f = _sphere_yaml(tmp_path)
    f.write_bytes(b"\xff")
    text = DECK.replace("Shape 1 Sphere Radius 0.02", f"Shape 1 File {f}")
    with pytest.raises(InputError) as info:
        parse_deck(_deck(tmp_path, text))
    assert info.value.line == 6 and "not a UTF-8 text file" in str(info.value)


def test_giraffe_reader_is_lenient_like_the_authors(tmp_path):
    """Integers written as reals and trailing text after the last record are accepted."""
    text = giraffe_text(gen.sphere_patches(0.02))
    text = text.replace("UOrder 4", "UOrder 4.0").replace("UDim 5", "UDim 5.0")
    text = text.replace("Subdivisions 1 1", "Subdivisions 1.0 1")
    f = tmp_path / "p.txt"
    f.write_text(text + "\nEND of file written by the CAD exporter\n")
    shape, warns = import_giraffe(f)
    assert len(shape.patches) == 6
    assert any("text after the last patch record ignored" in w for w in warns)


def test_giraffe_non_integer_real_is_still_refused(tmp_path):
    text = giraffe_text(gen.sphere_patches(0.02)).replace("UOrder 4", "UOrder 4.5", 1)
    f = tmp_path / "p.txt"
    f.write_text(text)
    with pytest.raises(InputError, match="must be an integer, got '4.5'"):
        import_giraffe(f)


# ---------------------------------------------------------------------------- the CLI


def test_info_refuses_a_negative_density(tmp_path):
    r = CliRunner().invoke(main, ["info", str(_sphere_yaml(tmp_path)), "--density", "-1"])
    assert r.exit_code == 2
    assert "--density must be a positive number" in r.output
    assert "mass:" not in r.output


def test_check_cli_one_line_exit_2(tmp_path):
    path = _deck(tmp_path, DECK.replace(P2, P2.replace("0.15", "0.05")))
    r = CliRunner().invoke(main, ["check", str(path)])
    assert r.exit_code == 2
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith(f"nurbsdem: error: {path}:9: ")


def test_internal_error_is_one_line_with_a_log_file(tmp_path, monkeypatch):
    import nurbsdem.io.deck as deck

    def broken(path, place=True):
        return 1 / 0
    monkeypatch.setattr(deck, "parse_deck", broken)
    log = tmp_path / "crash.log"
    monkeypatch.setenv("NURBSDEM_ERROR_LOG", str(log))
    r = CliRunner().invoke(main, ["check", str(_deck(tmp_path, DECK))])
    assert r.exit_code == EXIT_INTERNAL_ERROR
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1
    assert "internal error (a bug in nurbsdem" in lines[0] and str(log) in lines[0]
    assert "ZeroDivisionError" in log.read_text() and "Traceback" in log.read_text()


def test_runtime_warnings_are_not_shown(tmp_path, monkeypatch):
    import nurbsdem.io.deck as deck
    real = deck.parse_deck

    def noisy(path, place=True):
        np.float64(1.0) / np.float64(0.0)
        warnings.warn("noise", RuntimeWarning)
        return real(path, place)
    monkeypatch.setattr(deck, "parse_deck", noisy)
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        r = CliRunner().invoke(main, ["check", str(_deck(tmp_path, DECK))])
    assert r.exit_code == 0 and "Warning" not in r.output
    assert not [w for w in seen if issubclass(w.category, RuntimeWarning)]


# ---------------------------------------------------------------------------- messages


def test_summary_with_almost_no_energy_turned_over():
    text = RunSummary(balance_error=-3.5e-30, balance_scale=1e-56).text()
    assert "e+26" not in text and "only 1e-56 J of energy was turned over" in text
    assert "(8.00e-04 of the 212 J turned over)" in RunSummary(
        balance_error=0.1696, balance_scale=212.0).text()


# ---------------------------------------------------------------------------- restart


def _state(model) -> dict:
    return {"deck": model.text, "time": 0.0, "step_index": 0, "step_progress": 0}


def test_restart_accepts_a_deck_with_only_comments_changed(tmp_path):
    model = parse_deck(_deck(tmp_path, DECK), place=False)
    ck = tmp_path / "checkpoint.h5"
    save_checkpoint(ck, _state(model))
    edited = "# a comment\n" + DECK.replace("Environment", "Environment   // gravity")
    edited = edited.replace("Max 0.25 0.25 0.25", "Max 0.250 0.25 0.25e0")
    new = build_model(edited, model.path)
    assert restart_state(ck, new)["time"] == 0.0


def test_restart_refuses_a_physically_different_deck(tmp_path):
    model = parse_deck(_deck(tmp_path, DECK), place=False)
    ck = tmp_path / "checkpoint.h5"
    save_checkpoint(ck, _state(model))
    new = build_model(DECK.replace("Friction 0.5", "Friction 0.4"), model.path)
    with pytest.raises(InputError, match="differs in Contact"):
        restart_state(ck, new)


@pytest.mark.parametrize("kind", ["garbage", "truncated", "results", "empty-hdf5"])
def test_bad_checkpoint_is_one_input_error(tmp_path, kind):
    model = parse_deck(_deck(tmp_path, DECK), place=False)
    ck = tmp_path / "checkpoint.h5"
    if kind == "garbage":
        ck.write_bytes(b"not hdf5 at all" * 10)
    elif kind == "truncated":
        save_checkpoint(ck, _state(model))
        ck.write_bytes(ck.read_bytes()[:700])
    elif kind == "results":
        from nurbsdem.io.results import ResultsWriter
        ResultsWriter(ck, deck_text=model.text)
    else:
        with h5py.File(ck, "w"):
            pass
    with pytest.raises(InputError) as info:
        restart_state(ck, model)
    assert str(info.value).startswith(str(ck)) and "\n" not in str(info.value)


def test_checkpoint_round_trip_still_exact(tmp_path):
    ck = tmp_path / "c.h5"
    state = {"a": np.arange(5.0), "b": {"c": "text", "d": [1, 2.5, None]}}
    save_checkpoint(ck, state)
    back = load_checkpoint(ck)
    assert np.array_equal(back["a"], state["a"]) and back["b"] == state["b"]


@pytest.mark.parametrize("args,fragment", [
    (["sphere", "--radius", "1e300"], "--radius 1e+300 m is out of range"),
    (["sphere", "--radius", "1e-300"], "--radius 1e-300 m is out of range"),
    (["ellipsoid", "--semi-axes", "1e300", "1", "1"], "out of range"),
    (["sphere", "--radius", "nan"], "radius must be > 0"),
    (["sphere", "--radius", "inf"], "must be a positive number (m), got inf"),
])
def test_shape_command_refuses_sizes_out_of_range(tmp_path, args, fragment):
    r = CliRunner().invoke(main, ["shape", *args, "-o", str(tmp_path / "x.yaml")])
    assert r.exit_code == 2 and fragment in r.output
    assert not (tmp_path / "x.yaml").exists()


def test_import_scale_that_overflows_is_refused(tmp_path):
    f = tmp_path / "p.txt"
    f.write_text(giraffe_text(gen.sphere_patches(0.02)))
    r = CliRunner().invoke(main, ["import-giraffe", str(f), "-o", str(tmp_path / "y.yaml"),
                                  "--scale", "1e300"])
    assert r.exit_code == 2 and "--scale 1e+300: the scaled shape" in r.output


def test_output_directory_that_is_a_file(tmp_path):
    path = _deck(tmp_path, DECK)
    blocker = tmp_path / "blocker"
    blocker.write_text("a file")
    r = CliRunner().invoke(main, ["solve", str(path), "--quiet", "--output", str(blocker)])
    assert r.exit_code == 2 and "the output directory is a file" in r.output
    assert blocker.read_text() == "a file"


def test_replicating_onto_the_same_place_is_refused_at_run_time(tmp_path):
    """The run-time Replicate check catches coincident copies (the sampled test alone saw
    identical surfaces as touching)."""
    from nurbsdem.model import ReplicateStep
    from nurbsdem.placement import replicate_step
    model = parse_deck(_deck(tmp_path, DECK))
    step = ReplicateStep(9, 17, layers=3, height=1e-300)
    with pytest.raises(InputError, match="replicated layers overlap"):
        replicate_step(model, model.bodies, step)


def test_replicating_through_the_lid_is_refused_at_run_time(tmp_path):
    from nurbsdem.model import ReplicateStep
    from nurbsdem.placement import replicate_step
    model = parse_deck(_deck(tmp_path, DECK))
    step = ReplicateStep(9, 17, layers=2, height=0.3)
    with pytest.raises(InputError, match="after replication, particle 3 .* behind wall 'lid'"):
        replicate_step(model, model.bodies, step)


def test_random_group_beyond_jamming_is_refused_at_once(tmp_path):
    """100 000 spheres in a region far too small for them are refused at once (placing them
    would try for hours before failing)."""
    text = DECK.replace(P2, P2 + "\n  Random 3 Shapes 1 Counts 100000 Material 1 Region "
                        "0 0 0 0.25 0.25 0.25")
    with pytest.raises(InputError) as info:
        parse_deck(_deck(tmp_path, text))
    assert "random placement jams" in str(info.value) and info.value.line == 10


def test_replicated_copies_may_share_the_settled_penetration_of_their_originals(tmp_path):
    """A settled layer rests on penalty contacts, a little into the side walls: its copies
    inherit that penetration (the quick paper deck stopped at its Replicate step); a copy
    deeper into a wall than its original is still refused."""
    from nurbsdem.errors import InputError
    from nurbsdem.io.deck import parse_deck
    from nurbsdem.placement import replicate_step
    from nurbsdem.validation import check_bodies_against_walls

    deck = tmp_path / "rep.inp"
    deck.write_text("""Materials
  Material 1 Density 2700
Shapes
  Shape 1 Sphere Radius 0.02
Particles
  Particle 1 Shape 1 Material 1 Position 0.1 0.1 0.05
Walls
  Box 1 Min 0 0 0 Max 0.25 0.25 0.6
Contact
  Interface 1 NormalPenalty 1e5 NormalDamping 1e2
Steps
  Step 1 Replicate Layers 3 Height 0.2
""")
    model = parse_deck(deck)
    settled = model.bodies.copy()
    settled.position = np.array([[0.1, 0.25 - 0.02 + 1e-6, 0.05]])    # 1 µm into y_max
    out = replicate_step(model, settled, model.steps[0])
    assert len(out) == 3
    out.position[1, 1] += 4e-6                                        # a copy 5 µm deep
    with pytest.raises(InputError, match="penetrates wall 'y_max' by 5"):
        check_bodies_against_walls(model, out, index=[1, 2], reference=[0, 0])


def test_two_exact_spheres_overlap_by_their_centres_distance_without_an_lcp(monkeypatch):
    """The overlap check of two exact spheres is the closed form r_a + r_b - |c_a - c_b|,
    equal to the exact LCP's depth, and runs no LCP (a deck of spheres compiles none)."""
    import nurbsdem.contact as contact
    from nurbsdem.geometry.rotation import quat_to_matrix
    from nurbsdem.validation import pair_penetration

    a, b = gen.sphere(0.02), gen.sphere(0.03)
    R_a = quat_to_matrix(np.array([0.8, 0.36, 0.0, 0.48]))
    R_b = quat_to_matrix(np.array([0.6, 0.0, 0.8, 0.0]))
    pos_a, pos_b = np.array([0.01, 0.02, 0.03]), np.array([0.01, 0.02 + 0.045, 0.03 + 0.002])
    closed = 0.05 - float(np.hypot(0.045, 0.002))
    exact = contact.detect(a, (pos_a - R_a @ a.centroid, R_a), b, (pos_b - R_b @ b.centroid, R_b))
    assert not exact.failed and -exact.signed_distance == pytest.approx(closed, abs=1e-9)

    def no_lcp(*args, **kwargs):
        raise AssertionError("an LCP was run for two exact spheres")
    monkeypatch.setattr(contact, "detect", no_lcp)
    assert pair_penetration(a, pos_a, R_a, b, pos_b, R_b) == pytest.approx(closed, abs=1e-15)
    assert contact.detect is no_lcp
