"""Shape files: strict YAML loading, exact round trip, one-line errors naming file and patch."""
from __future__ import annotations

import textwrap

import numpy as np
import pytest

from nurbsdem.errors import InputError
from nurbsdem.geometry import generators as gen
from nurbsdem.geometry.nurbs import Patch
from nurbsdem.io.shapefile import load_shape, load_yaml, read_patches, save_shape


def _write(tmp_path, text, name="s.yaml"):
    f = tmp_path / name
    f.write_text(textwrap.dedent(text))
    return f


def test_every_float_notation_is_a_float(tmp_path):
    f = _write(tmp_path, """\
        a: 1e-3
        b: 1E+3
        c: .5
        d: -2.5e-7
        e: 1.0
        f: 1e3
        g: +4.
        h: -.25E-2
        i: 3
        j: [1e-3, .5, 2]
        """)
    d = load_yaml(f)
    expect = {"a": 1e-3, "b": 1e3, "c": 0.5, "d": -2.5e-7, "e": 1.0, "f": 1e3, "g": 4.0,
              "h": -0.25e-2}
    for k, v in expect.items():
        assert type(d[k]) is float and d[k] == v, k
    assert type(d["i"]) is int and d["i"] == 3
    assert [type(x) for x in d["j"]] == [float, float, int]


def test_float_notations_in_a_shape_file(tmp_path):
    f = _write(tmp_path, """\
        patches:
          - degree_u: 1
            degree_v: 1
            knots_u: [0, 0, 1E+0, 1.]
            knots_v: [.0, 0e0, 1e0, 1]
            control_points:
              - [[0, 0, 0], [0, 1e-3, 0]]
              - [[1E-3, 0, 0], [.001, 1.0e-3, -2.5e-7]]
        """)
    (p,), name = read_patches(f)
    assert name is None
    assert p.control_points[1, 1].tolist() == [0.001, 0.001, -2.5e-7]
    assert np.all(p.weights == 1)


def test_duplicate_key_names_the_line(tmp_path):
    f = _write(tmp_path, """\
        name: s
        patches:
          - degree_u: 1
            degree_v: 1
            degree_u: 2
        """)
    with pytest.raises(InputError) as ei:
        load_yaml(f)
    assert str(ei.value) == f"{f}:5: duplicate key 'degree_u'"
    assert ei.value.line == 5


def test_yaml_syntax_error_names_the_line(tmp_path):
    f = _write(tmp_path, "patches:\n  - [1, 2\n  - 3\n")
    with pytest.raises(InputError, match=rf"^{f}:\d+: ") as ei:
        load_yaml(f)
    assert "\n" not in str(ei.value)


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match=r"nope\.yaml: cannot read file"):
        load_shape(tmp_path / "nope.yaml")


def _bits(a):
    return np.ascontiguousarray(a, dtype=float).view(np.uint64)


def test_round_trip_is_bit_exact(tmp_path):
    rng = np.random.default_rng(1)
    specials = [0.1, 1 / 3, -0.0, 5e-324, 2.2250738585072014e-308, 1.7976931348623157e308,
                -1e-300, 1e17, 123456789.123456789, np.nextafter(1.0, 2.0)]
    cp = rng.normal(size=(4, 3, 3)) * 10.0 ** rng.integers(-8, 8, size=(4, 3, 3))
    cp.flat[: len(specials)] = specials
    w = rng.uniform(0.1, 3.0, size=(4, 3))
    w[0, 0] = 5e-324
    p = Patch(2, 1, [0, 0, 0, 1 / 3, 1, 1, 1], [0.1, 0.1, 1.5, np.pi, np.pi], cp, w)
    patches = gen.sphere_patches(0.123456789) + [p]
    f = tmp_path / "rt.yaml"
    save_shape(f, patches, name="round trip")
    back, name = read_patches(f)
    assert name == "round trip"
    for a, b in zip(patches, back):
        assert (a.degree_u, a.degree_v) == (b.degree_u, b.degree_v)
        for x, y in ((a.knots_u, b.knots_u), (a.knots_v, b.knots_v),
                     (a.control_points, b.control_points), (a.weights, b.weights)):
            assert np.array_equal(_bits(x), _bits(y))
    # a second write gives the same text
    f2 = tmp_path / "rt2.yaml"
    save_shape(f2, back, name="round trip")
    assert f.read_text() == f2.read_text()


def test_shape_round_trip_keeps_properties(tmp_path):
    sh = gen.sphere(0.01)
    save_shape(tmp_path / "s.yaml", sh)
    back = load_shape(tmp_path / "s.yaml")
    assert back.name == sh.name and back.source == str(tmp_path / "s.yaml")
    assert back.volume == sh.volume
    assert np.array_equal(back.connectivity.neighbours, sh.connectivity.neighbours)


# ---------------------------------------------------------------------- bad patches
_GOOD = """\
    degree_u: {du}
    degree_v: 1
    knots_u: {ku}
    knots_v: [0, 0, 1, 1]
    control_points: {cp}
    weights: {w}
"""
_CP = "[[[0, 0, 0], [0, 1, 0]], [[1, 0, 0], [1, 1, 0]]]"


def _patch_text(du=1, ku="[0, 0, 1, 1]", cp=_CP, w="[[1, 1], [1, 1]]"):
    body = textwrap.indent(textwrap.dedent(_GOOD).format(du=du, ku=ku, cp=cp, w=w), "    ")
    return "  - " + body.lstrip()


def _file_with_bad_second_patch(tmp_path, **bad):
    text = "name: bad\npatches:\n" + _patch_text() + _patch_text(**bad)
    return _write(tmp_path, text)


BAD_CASES = {
    "degree < 1": (dict(du=0, ku="[0, 1]", cp="[[[0, 0, 0], [0, 1, 0]]]", w="[[1, 1]]"),
                   "degree_u must be an integer >= 1"),
    "degree not an integer": (dict(du=1.5), "degree_u must be an integer"),
    "non-monotone knots": (dict(du=1, ku="[0, 0, 1, 0.5, 1, 1]",
                                cp="[[[0,0,0],[0,1,0]],[[1,0,0],[1,1,0]],[[2,0,0],[2,1,0]],"
                                   "[[3,0,0],[3,1,0]]]", w="[[1,1],[1,1],[1,1],[1,1]]"),
                           "knots_u is not non-decreasing at index 3"),
    "unclamped": (dict(ku="[0, 0.5, 1, 1]"), "knots_u is not clamped"),
    "wrong knot count": (dict(ku="[0, 0, 1, 1, 1]"), "knots_u has 5 knots, expected"),
    "wrong weights shape": (dict(w="[[1, 1, 1], [1, 1, 1]]"), "weights must have shape (2, 2)"),
    "ragged control points": (dict(cp="[[[0, 0, 0], [0, 1, 0]], [[1, 0, 0]]]"),
                              "control_points has rows of different lengths"),
    "quoted number": (dict(ku="[0, 0, '1', 1]"), "knots_u must contain only numbers"),
    "boolean": (dict(cp="[[[0, 0, true], [0, 1, 0]], [[1, 0, 0], [1, 1, 0]]]"),
                "control_points must contain only numbers"),
    "points not 3-D": (dict(cp="[[[0, 0], [0, 1]], [[1, 0], [1, 1]]]"),
                       "control_points must be n_u rows of n_v [x, y, z] points"),
    "non-finite point": (dict(cp="[[[0, 0, .nan], [0, 1, 0]], [[1, 0, 0], [1, 1, 0]]]"),
                         "control_points contains a non-finite number"),
    "infinite knot": (dict(ku="[0, 0, .inf, .inf]"), "knots_u contains a non-finite number"),
    "zero weight": (dict(w="[[1, 1], [0.0, 1]]"), "weight [1][0] = 0.0 is not > 0"),
    "negative weight": (dict(w="[[1, -2e-3], [1, 1]]"), "weight [0][1] = -0.002 is not > 0"),
    "text in numbers": (dict(w="[[1, one], [1, 1]]"), "weights must contain only numbers"),
}


@pytest.mark.parametrize("case", sorted(BAD_CASES))
def test_bad_patch_is_one_line_naming_file_and_patch(tmp_path, case):
    bad, msg = BAD_CASES[case]
    f = _file_with_bad_second_patch(tmp_path, **bad)
    with pytest.raises(InputError) as ei:
        read_patches(f)
    text = str(ei.value)
    assert text.startswith(f"{f}: patch 1: "), text
    assert msg in text
    assert "\n" not in text


@pytest.mark.parametrize("text, msg", [
    ("name: x\n", "a shape file must be a mapping with a 'patches' list"),
    ("patches: []\n", "'patches' must be a non-empty list"),
    ("patches: [1]\n", "patch 0: a patch must be a mapping"),
    ("patches:\n  - degree_u: 1\n", "patch 0: missing key"),
    ("colour: red\npatches: [1]\n", "unknown key 'colour'"),
])
def test_bad_structure(tmp_path, text, msg):
    f = _write(tmp_path, text)
    with pytest.raises(InputError, match=rf"^{f}: .*{msg}"):
        read_patches(f)


def test_unknown_patch_key(tmp_path):
    f = _write(tmp_path, "patches:\n" + _patch_text() + "    colour: red\n")
    with pytest.raises(InputError, match=rf"^{f}: patch 0: unknown key 'colour'"):
        read_patches(f)
