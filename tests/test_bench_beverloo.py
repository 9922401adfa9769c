"""The silo floor of benchmarks/bench_beverloo.py: a valid mesh wall, the square less the
orifice's polygon exactly (its area, its rim on the circle of diameter D, its fronts +z)."""
import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import bench_beverloo  # noqa: E402

from nurbsdem.io.meshfile import edge_use, read_wall_mesh  # noqa: E402


@pytest.mark.parametrize("segments", [8, 64])
def test_floor_with_orifice(tmp_path, segments):
    side, D = 0.1, 0.026
    path = tmp_path / "floor.stl"
    bench_beverloo.write_floor(path, side, D, segments)
    mesh = read_wall_mesh(path, one_sided=True)
    assert mesh.warnings == []
    v, f = mesh.vertices, mesh.faces
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    normal = np.cross(b - a, c - a)
    assert np.all(normal[:, 2] > 0) and np.allclose(v[:, 2], 0.0)
    polygon = 0.5 * segments * (D / 2) ** 2 * math.sin(2 * math.pi / segments)
    # the area, to the float32 of an STL
    assert 0.5 * normal[:, 2].sum() == pytest.approx(side * side - polygon, rel=1e-6)
    edges, counts, _ = edge_use(f)
    rim = edges[counts == 1]                      # the boundary: the orifice and the square
    r = np.linalg.norm(v[:, :2], axis=1)
    inner = np.all(np.isclose(r[rim], D / 2, rtol=1e-6), axis=1)
    outer = np.all(np.isclose(np.abs(v[rim][:, :, :2]).max(axis=2), side / 2, rtol=1e-6),
                   axis=1)
    assert inner.sum() == segments and np.all(inner | outer)
    outside = r > D / 2 * (1 + 1e-6)                # the other vertices lie on the square
    assert np.abs(v[outside, :2]).max(axis=1) == pytest.approx(side / 2, rel=1e-6)
    with pytest.raises(ValueError):
        bench_beverloo.write_floor(path, side, D, 12)


@pytest.mark.parametrize("shape", bench_beverloo.SHAPES)
def test_the_grains_of_each_shape_have_the_spheres_volumes(tmp_path, shape):
    """The fill and discharge decks of each grain parse, and their three shapes have the
    volumes of the spheres of radii RADII (the paper's particles scaled to them)."""
    from nurbsdem.io.deck import parse_deck
    if shape == "paper":
        bench_beverloo.write_paper_shapes(tmp_path)
    bench_beverloo.write_floor(tmp_path / "floor.stl", 0.06, 0.024)
    fill, _ = bench_beverloo.fill_deck(0.06, 0.036, 300, shape)
    for name, text in (("fill", fill), ("discharge", bench_beverloo.discharge_deck(
            0.036, 0.06, 0.15, shape)), ("warm", bench_beverloo.warm_deck(shape))):
        (tmp_path / f"{name}.inp").write_text(text)
        model = parse_deck(tmp_path / f"{name}.inp", place=name != "discharge")
        volumes = [model.shapes[k].volume for k in sorted(model.shapes)]
        np.testing.assert_allclose(volumes, [4 / 3 * math.pi * r ** 3
                                             for r in bench_beverloo.RADII], rtol=1e-9)


def test_the_fills_combined_give_beverloo_back_from_rates_that_scatter_about_it(tmp_path):
    """``combine``: two fills whose rates lie 3 % above and below Beverloo's law (n 2.5, k 1.5,
    C 0.6) and whose bulk densities differ give the mean rates, their standard errors and the
    law's n, k and C back; runs with other orifices are refused."""
    import json
    d, rho, g = bench_beverloo.D_GRAIN, 1570.0, bench_beverloo.G
    ratios = (6.0, 8.0, 11.0, 15.0)
    law = [0.6 * rho * math.sqrt(g) * ((x - 1.5) * d) ** 2.5 for x in ratios]
    paths = []
    for seed, sign in ((3, 1.0), (4, -1.0)):
        run = dict(seed=seed, d=d, T=0.4, fill=dict(rho_b=rho * (1 + 0.01 * sign), top=0.096),
                   orifices=[dict(ratio=x, D=x * d, W=w * (1 + 0.03 * sign))
                             for x, w in zip(ratios, law)])
        paths.append(tmp_path / f"seed{seed}.json")
        paths[-1].write_text(json.dumps(run))
    out = bench_beverloo.combine(paths, tmp_path / "fills.json")
    assert json.loads((tmp_path / "fills.json").read_text())["seeds"] == [3, 4]
    for row, w in zip(out["orifices"], law):
        assert row["W"] == pytest.approx(w, rel=1e-12)
        assert row["sem"] == pytest.approx(0.03 * w, rel=1e-9)
    assert out["fit"]["n"] == pytest.approx(2.5, abs=1e-5)
    assert out["fit"]["k"] == pytest.approx(1.5, abs=1e-4)
    assert out["fit"]["C"] == pytest.approx(0.6, rel=1e-4)
    assert out["fit_n25"]["C"] == pytest.approx(0.6, rel=1e-9)
    other = json.loads(paths[1].read_text())
    other["orifices"] = other["orifices"][:3]
    paths[1].write_text(json.dumps(other))
    with pytest.raises(SystemExit, match="other orifices"):
        bench_beverloo.combine(paths, tmp_path / "fills.json")


def test_runs_of_other_orifices_join_their_fill_and_the_fit_from_8_d(tmp_path):
    """``combine`` joins a seed's run of other orifices (``--orifices``) to that seed's
    default run: two fills of six orifices on Beverloo's law (n 2.5, k 1.5, C 0.6) 2 % above
    and below it, each fill split over two runs, give the mean rates of all six orifices in
    order, and the fit over the five of at least 8 d gives the law back; a run of the same
    seed whose fill differs is refused, and ``--orifices`` outside the silo's range too."""
    import json
    d, rho, g = bench_beverloo.D_GRAIN, 1570.0, bench_beverloo.G
    ratios = (6.0, 8.0, 9.5, 11.0, 13.0, 15.0)
    law = {x: 0.6 * rho * math.sqrt(g) * ((x - 1.5) * d) ** 2.5 for x in ratios}
    paths = []
    for seed, sign in ((3, 1.0), (4, -1.0)):
        fill = dict(rho_b=rho * (1 + 0.01 * sign), top=0.096, count=37917)
        for part in ((6.0, 8.0, 11.0, 15.0), (9.5, 13.0)):
            run = dict(seed=seed, d=d, T=0.4, fill=fill,
                       orifices=[dict(ratio=x, D=x * d, W=law[x] * (1 + 0.02 * sign))
                                 for x in part])
            paths.append(tmp_path / f"seed{seed}_{len(part)}.json")
            paths[-1].write_text(json.dumps(run))
    out = bench_beverloo.combine(paths[::-1], tmp_path / "fills.json")
    assert [o["ratio"] for o in out["orifices"]] == list(ratios)
    for row in out["orifices"]:
        assert row["W"] == pytest.approx(law[row["ratio"]], rel=1e-12)
    assert out["from"] == 8.0
    assert out["fit_from"]["n"] == pytest.approx(2.5, abs=1e-5)
    assert out["fit_from"]["k"] == pytest.approx(1.5, abs=1e-4)
    assert out["fit_n25_from"]["C"] == pytest.approx(0.6, rel=1e-9)
    other = json.loads(paths[1].read_text())
    other["fill"]["rho_b"] *= 1.001
    paths[1].write_text(json.dumps(other))
    with pytest.raises(SystemExit, match="not the same fill"):
        bench_beverloo.combine(paths, tmp_path / "fills.json")
    with pytest.raises(SystemExit, match="outside 6 to 15 d"):
        bench_beverloo.main(["--orifices", "16"])


def _synthetic_run(seed: int, ratios, sign: float, yade_at=None) -> dict:
    """A run's JSON as bench_beverloo writes it, its rates on Beverloo's law (n 2.5, k 1.5,
    C 0.6) times 1 + 0.02 sign, Yade's rate at ``yade_at`` 1 % below nurbsdem's."""
    d, rho, g = bench_beverloo.D_GRAIN, 1570.0, bench_beverloo.G
    rows = [dict(ratio=x, D=x * d, W=0.6 * rho * math.sqrt(g) * ((x - 1.5) * d) ** 2.5
                 * (1 + 0.02 * sign), halves=[1.0, 1.0], C_mid=0.6, top_end=0.08, loop=700.0,
                 flow=30.0, dt=6.5e-5, cpu=700.0) for x in ratios]
    fill = dict(rho_b=rho, top=0.096, count=37917, flow=15.0, loop=400.0)
    run = dict(quick=False, seed=seed, d=d, T=0.4, side=0.15, count=37917,
               radii=list(bench_beverloo.RADII), fill=fill, orifices=rows, flow_share=0.045,
               yade="Yade is compared on the default orifices only")
    if yade_at is not None:
        o = next(o for o in rows if o["ratio"] == yade_at)
        run.update(yade_at=yade_at, ratio=1.5, cpu_ratio=1.4,
                   yade=dict(wall=o["loop"] / 1.5, cpu=500.0, W=o["W"] / 1.01,
                             halves=[1.0, 1.0]))
    bench_beverloo._fit(run)
    return run


def test_the_report_gives_the_fit_from_8_d_and_yade_through_other_orifices(tmp_path,
                                                                          monkeypatch):
    """The report's silo section (``report_peers.section_beverloo``) on the JSONs of two
    fills, each with a run of other orifices, and Yade runs through 8, 11 and 15 d: the mean
    rates' fits over all orifices and over those of at least 8 d, Yade's rows, and both
    codes' fits on the bed of Yade's four orifices (Yade's rates 1 % lower: the same n and k,
    C 1 % lower; the rates 2 % above the law); the headline has both exponents and k, C at n 2.5."""
    import json

    import report_peers
    from report_base import Report
    cache = tmp_path / "benchmarks" / ".cache"
    cache.mkdir(parents=True)
    default, extra = (6.0, 8.0, 11.0, 15.0), (9.5, 13.0)
    (cache / "beverloo.json").write_text(json.dumps(_synthetic_run(3, default, 1.0, 6.0)))
    for x in (8.0, 11.0, 15.0):
        (cache / f"beverloo_D{x:g}.json").write_text(json.dumps(_synthetic_run(3, (x,), 1.0, x)))
    paths = []
    for seed, sign in ((3, 1.0), (4, -1.0)):
        for part in (default, extra):
            paths.append(tmp_path / f"s{seed}_{len(part)}.json")
            paths[-1].write_text(json.dumps(_synthetic_run(seed, part, sign)))
    bench_beverloo.combine(paths, cache / "beverloo_fills.json")
    monkeypatch.setattr(report_peers, "REPO", tmp_path)
    rep = Report(tmp_path / "out", {}, quick=False)
    report_peers.section_beverloo(rep)
    text = "".join(rep.parts)
    assert "Over the 5 orifices of at least 8 d (8, 9.5, 11, 13, 15 d): exponent 2.50" in text
    assert "| 15 | " in text and "| +1.0 | 1.50 |" in text
    assert text.index("| 8 | ") < text.index("| 11 | ") < text.index("| 15 | ")
    fits = text[text.index("Beverloo's fits on this bed through 6, 8, 11, 15 d"):].split("\n")[0]
    assert "nurbsdem's rates exponent 2.50 ±" in fits and "k 1.50, C 0.612;" in fits
    assert "Yade's rates exponent 2.50 ±" in fits and f"C {0.612 / 1.01:.3f}" in fits
    head = rep.headline["beverloo_fills"]
    assert head["n"] == pytest.approx(2.5, abs=1e-4)
    assert head["n_from"] == pytest.approx(2.5, abs=1e-4)
    assert head["C"] == pytest.approx(0.6, rel=1e-9) and head["start"] == 8.0


def test_a_longer_discharge_of_a_fill_gives_that_orifices_rate(tmp_path, monkeypatch):
    """``combine`` takes each orifice's rate of a fill from its longest discharge
    (``--discharge``): the default runs' 6 and 8 d rates lie 10 % off Beverloo's law, the
    0.8 s runs' on it (2 % above and below), so the mean rates and the fit give the law back,
    and the report's fills table gives each fill's discharge time; ``--discharge`` beyond
    the bed's reach is refused."""
    import json

    import report_peers
    from report_base import Report
    cache = tmp_path / "benchmarks" / ".cache"
    cache.mkdir(parents=True)
    paths = []
    for seed, sign in ((3, 1.0), (4, -1.0)):
        short = _synthetic_run(seed, (6.0, 8.0, 11.0, 15.0), sign)
        for o in short["orifices"][:2]:
            o["W"] *= 1.1
        long = _synthetic_run(seed, (6.0, 8.0), sign)
        long["T"] = 0.8
        for name, run in (("short", short), ("long", long)):
            paths.append(tmp_path / f"s{seed}_{name}.json")
            paths[-1].write_text(json.dumps(run))
    out = bench_beverloo.combine(paths[::-1], cache / "beverloo_fills.json")
    assert [o["T_fills"] for o in out["orifices"]] == [[0.8, 0.8]] * 2 + [[0.4, 0.4]] * 2
    assert out["fit"]["n"] == pytest.approx(2.5, abs=1e-5)
    assert out["fit_n25"]["C"] == pytest.approx(0.6, rel=1e-9)
    (cache / "beverloo.json").write_text(json.dumps(_synthetic_run(3, (6.0, 8.0, 11.0, 15.0),
                                                                   1.0)))
    monkeypatch.setattr(report_peers, "REPO", tmp_path)
    rep = Report(tmp_path / "out", {}, quick=False)
    report_peers.section_beverloo(rep)
    text = "".join(rep.parts)
    assert "discharge of each fill s |" in text and "| 0.8, 0.8 |" in text
    assert "| 0.4, 0.4 |" in text
    with pytest.raises(SystemExit, match="outside 0.2 to 0.8 s"):
        bench_beverloo.main(["--discharge", "1.2"])


def test_resampling_the_fills_gives_the_exponents_spread():
    """``bootstrap_exponent``: four fills whose rates lie on Beverloo's law (n 2.5) times
    independent factors 1 ± 2 % give a spread of the free exponent about 2.5 that narrows
    with 1 % factors; fewer than three fills give none."""
    rng = np.random.default_rng(7)
    d, rho = bench_beverloo.D_GRAIN, 1570.0
    ratios = np.array([6.0, 8.0, 9.5, 11.0, 13.0, 15.0])
    law = 0.6 * rho * math.sqrt(bench_beverloo.G) * ((ratios - 1.5) * d) ** 2.5
    noise = rng.normal(size=(4, ratios.size))
    spreads = []
    for scale in (0.02, 0.01):
        b = bench_beverloo.bootstrap_exponent(law * (1 + scale * noise), ratios * d, d, rho,
                                              draws=400)
        assert b["draws"] == 400 and b["p16"] < b["p50"] < b["p84"]
        assert abs(b["p50"] - 2.5) < 0.5 and 0.0 <= b["inside"] <= 1.0
        spreads.append(b["p84"] - b["p16"])
    assert spreads[1] < spreads[0]
    assert bench_beverloo.bootstrap_exponent(law[None, :].repeat(2, 0), ratios * d, d,
                                             rho) is None


def test_the_report_gives_the_exponents_spread_over_three_fills(tmp_path, monkeypatch):
    """With three fills the report's silo section gives the free exponent's spread over the
    fills resampled, and its headline the 16th and 84th percentiles."""
    import json

    import report
    import report_peers
    from report_base import Report
    cache = tmp_path / "benchmarks" / ".cache"
    cache.mkdir(parents=True)
    ratios = (6.0, 8.0, 9.5, 11.0, 13.0, 15.0)
    paths = []
    for seed, sign in ((3, 1.0), (4, -1.0), (5, 0.5)):
        run = _synthetic_run(seed, ratios, sign)
        for i, o in enumerate(run["orifices"]):
            o["W"] *= 1 + 0.01 * sign * (-1) ** i
        paths.append(tmp_path / f"s{seed}.json")
        paths[-1].write_text(json.dumps(run))
    bench_beverloo.combine(paths, cache / "beverloo_fills.json")
    (cache / "beverloo.json").write_text(json.dumps(_synthetic_run(3, ratios, 1.0)))
    monkeypatch.setattr(report_peers, "REPO", tmp_path)
    info = dict(cpu="a CPU", cores=2, nurbsdem="0", date="today")
    rep = Report(tmp_path / "out", info, quick=False)
    report_peers.section_beverloo(rep)
    text = "".join(rep.parts)
    assert "Resampling the fills (2000 draws with replacement" in text
    head = rep.headline["beverloo_fills"]
    assert head["p16"] <= head["p84"]
    line = next(x for x in report._headline_md(rep).split("\n") if "Silo discharge" in x)
    assert f"({head['p16']:.2f}–{head['p84']:.2f} over the fills resampled)" in line
