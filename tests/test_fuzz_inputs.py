"""Property-based tests: any text given to the deck parser, the shape loader or the Giraffe
reader gives a model (shape) or one InputError, never another exception, and answers within
a time bound (a per-example alarm that signals a hang; no wall-clock assertions otherwise).

Example counts are bounded and the search is derandomized, so CI runs the same examples
every time in a few seconds. Inputs that found defects are kept as explicit cases in
``test_validation.py`` (the regression corpus) and as ``@example`` here.
"""
from __future__ import annotations

import os
import signal
from contextlib import contextmanager

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from nurbsdem.errors import InputError
from nurbsdem.geometry import generators as gen
from nurbsdem.io.deck import build_model, parse_deck
from nurbsdem.io.giraffe import giraffe_text, import_giraffe
from nurbsdem.io.shapefile import load_shape, save_shape
from nurbsdem.validation import check_model

#: Seconds one example may take before it counts as a hang.
HANG_SECONDS = 60

#: ``NURBSDEM_FUZZ_EXAMPLES=5000`` (and ``NURBSDEM_FUZZ_RANDOM=1``) for a long hunt.
_N = int(os.environ.get("NURBSDEM_FUZZ_EXAMPLES", "60"))
FUZZ = settings(max_examples=_N, deadline=None,
                derandomize=not os.environ.get("NURBSDEM_FUZZ_RANDOM"), database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                       HealthCheck.function_scoped_fixture])
FUZZ_SLOW = settings(FUZZ, max_examples=max(1, _N * 5 // 12))


class Hang(Exception):
    """An example ran longer than HANG_SECONDS."""


@contextmanager
def time_bound(seconds: int = HANG_SECONDS):
    """Raise :class:`Hang` if the block runs longer than ``seconds`` (SIGALRM)."""
    def on_alarm(signum, frame):
        raise Hang(f"no answer within {seconds} s")
    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def answers_or_input_error(call) -> None:
    """call() returns, or raises exactly one InputError whose text is one line."""
    with time_bound():
        try:
            call()
        except InputError as exc:
            assert "\n" not in str(exc) and str(exc).strip()


# ---------------------------------------------------------------------------- decks

BASE_DECK = """Environment
  Gravity 0 0 -9.81
Materials
  Material 1 Density 2700
Shapes
  Shape 1 Sphere Radius 0.02
  Shape 2 Ellipsoid SemiAxes 0.02 0.015 0.01
Particles
  Particle 1 Shape 1 Material 1 Position 0.05 0.10 0.10 Velocity 0.5 0 0
  Particle 2 Shape 2 Material 1 Position 0.15 0.10 0.10 Rotation 0 0 0.3
  Random 3 Shapes 1 2 Counts 1 1 Material 1 Region 0.0 0.0 0.15 0.25 0.25 0.25 Seed 2
Walls
  Box 1 Min 0 0 0 Max 0.25 0.25 0.30
  Wall 6 Name lid Point 0.125 0.125 0.30 Normal 0 0 -1 Size 0.25 0.25
Contact
  Interface 1 NormalPenalty 1e5 TangentialPenalty 1e4 NormalDamping 1e1 Friction 0.5
Steps
  Step 1 Dynamic Duration 0.01 TimeStep 1e-3
  Step 2 Replicate Layers 2 Height 0.05
  Step 3 MoveWall lid ToContact Gap 0.001
  Step 4 MoveWall lid Displacement 0 0 -0.001 Duration 0.01 TimeStep 1e-3
Output
  Directory results
  VTK Every 0.01 Resolution 4
"""

#: Tokens that found defects or sit on boundaries.
NASTY = ["0", "-0", "-1", "1e300", "-1e300", "1e-300", "1e23", "1e-14", "nan", "inf", "1e400",
         "9223372036854775808", "99999999999999999999999999", "1" * 5000, "6.0", "0.5",
         "1e-9", "2", "3", '"', '""', "#", "//", "\ufeff", "x", "Step", "Particles", "yes",
         "\u00e9", "1e6", "1e7"]


def _tokens(line: str) -> list[str]:
    return line.split(" ")


@st.composite
def mutated_decks(draw, base: str = BASE_DECK) -> str:
    """The base deck with a few tokens replaced, lines deleted or duplicated."""
    lines = base.splitlines()
    for _ in range(draw(st.integers(1, 3))):
        i = draw(st.integers(0, len(lines) - 1))
        op = draw(st.sampled_from(["token", "token", "token", "delete", "duplicate"]))
        if op == "delete":
            del lines[i]
        elif op == "duplicate":
            lines.insert(i, lines[i])
        else:
            toks = _tokens(lines[i])
            j = draw(st.integers(0, len(toks) - 1))
            toks[j] = draw(st.one_of(st.sampled_from(NASTY),
                                     st.floats(allow_nan=True, allow_infinity=True).map(repr),
                                     st.integers(-10 ** 30, 10 ** 30).map(str),
                                     st.text(max_size=6)))
            lines[i] = " ".join(toks)
        if not lines:
            break
    return "\n".join(lines) + "\n"


@FUZZ
@given(st.text(max_size=300))
@example("\ufeffEnvironment\n  Gravity 0 0 -9.81\n")
@example("Particles\n  Particle 9223372036854775808 Shape 1 Material 1 Position 0 0 0\n")
@example("Steps\n  Step 1 Replicate Layers " + "9" * 5000 + " Height 1\n")
def test_any_text_builds_a_model_or_one_input_error(text):
    answers_or_input_error(lambda: check_model(build_model(text, "fuzz.inp")))


@FUZZ
@given(mutated_decks())
def test_mutated_decks_build_or_refuse(text):
    answers_or_input_error(lambda: check_model(build_model(text, "fuzz.inp")))


@FUZZ_SLOW
@given(mutated_decks())
def test_mutated_decks_place_and_validate_or_refuse(tmp_path_factory, text):
    path = tmp_path_factory.mktemp("deck") / "fuzz.inp"
    path.write_text(text, encoding="utf-8")
    answers_or_input_error(lambda: parse_deck(path))


@FUZZ
@given(st.binary(max_size=200))
@example(b"\xff\xfe\x00E")
@example(b"\xef\xbb\xbfSteps\n")
def test_any_bytes_as_a_deck_file(tmp_path_factory, data):
    path = tmp_path_factory.mktemp("deck") / "bin.inp"
    path.write_bytes(data)
    answers_or_input_error(lambda: parse_deck(path))


# ---------------------------------------------------------------------------- shape files


@pytest.fixture(scope="module")
def sphere_yaml(tmp_path_factory) -> str:
    f = tmp_path_factory.mktemp("shape") / "s.yaml"
    save_shape(f, gen.sphere_patches(0.02), name="s")
    return f.read_text()


def _load_text(tmp_path_factory, text: str | bytes, name: str = "f.yaml"):
    path = tmp_path_factory.mktemp("shape") / name
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text, encoding="utf-8")
    return path


@FUZZ
@given(st.text(max_size=300))
@example("a: " + "[" * 3000)
@example("patches: &a [*a]")
@example("patches:\n- degree_u: " + "9" * 5000 + "\n")
def test_any_text_as_a_shape_file(tmp_path_factory, text):
    path = _load_text(tmp_path_factory, text)
    answers_or_input_error(lambda: load_shape(path))


@FUZZ
@given(st.binary(max_size=100))
@example(b"\xff\xfe patches")
def test_any_bytes_as_a_shape_file(tmp_path_factory, data):
    path = _load_text(tmp_path_factory, data)
    answers_or_input_error(lambda: load_shape(path))


@st.composite
def mutated_numbers(draw, text: str) -> str:
    """A text with a few of its numbers replaced by nasty ones."""
    import re
    spans = [m.span() for m in re.finditer(r"-?\d+(\.\d+)?(e-?\d+)?", text)]
    for _ in range(draw(st.integers(1, 3))):
        a, b = draw(st.sampled_from(spans))
        new = draw(st.one_of(st.sampled_from(NASTY), st.floats().map(repr),
                             st.integers(-10 ** 20, 10 ** 20).map(str)))
        text = text[:a] + new.ljust(b - a)[: max(b - a, len(new))] + text[b:]
        spans = [m.span() for m in re.finditer(r"-?\d+(\.\d+)?(e-?\d+)?", text)] or [(0, 0)]
    return text


@FUZZ_SLOW
@given(st.data())
def test_mutated_shape_files(tmp_path_factory, sphere_yaml, data):
    text = data.draw(mutated_numbers(sphere_yaml))
    path = _load_text(tmp_path_factory, text)
    answers_or_input_error(lambda: load_shape(path))


# ---------------------------------------------------------------------------- Giraffe files


@pytest.fixture(scope="module")
def sphere_giraffe() -> str:
    return giraffe_text(gen.sphere_patches(0.02))


@FUZZ
@given(st.text(max_size=300))
@example("ID 1 Subdivisions 1 1 Connectivity 0 0 0 0 UDim 1000000000 UOrder 3")
def test_any_text_as_a_giraffe_file(tmp_path_factory, text):
    path = _load_text(tmp_path_factory, text, "p.txt")
    answers_or_input_error(lambda: import_giraffe(path))


@FUZZ_SLOW
@given(st.data())
def test_mutated_giraffe_files(tmp_path_factory, sphere_giraffe, data):
    text = data.draw(mutated_numbers(sphere_giraffe))
    path = _load_text(tmp_path_factory, text, "p.txt")
    answers_or_input_error(lambda: import_giraffe(path))


def test_base_inputs_are_valid(tmp_path, sphere_yaml, sphere_giraffe):
    """The seeds of the mutations are themselves valid (so mutations test the checks)."""
    (tmp_path / "d.inp").write_text(BASE_DECK)
    assert len(parse_deck(tmp_path / "d.inp").bodies) == 4
    (tmp_path / "s.yaml").write_text(sphere_yaml)
    assert len(load_shape(tmp_path / "s.yaml").patches) == 6
    (tmp_path / "p.txt").write_text(sphere_giraffe)
    assert len(import_giraffe(tmp_path / "p.txt")[0].patches) == 6


def test_time_bound_signals_a_hang():
    import time
    with pytest.raises(Hang):
        with time_bound(1):
            time.sleep(5)
