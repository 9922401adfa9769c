"""postproc/beverloo.py recovers Beverloo's parameters from rates made with known ones."""
import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

spec = importlib.util.spec_from_file_location(
    "beverloo", Path(__file__).resolve().parents[1] / "postproc" / "beverloo.py")
beverloo = importlib.util.module_from_spec(spec)
sys.modules["beverloo"] = beverloo          # dataclasses look their module up there
spec.loader.exec_module(beverloo)


@pytest.mark.parametrize("n, k, C", [(2.5, 1.4, 0.58), (2.3, 1.9, 0.66), (2.7, 1.1, 0.52)])
def test_fit_recovers_known_parameters(n, k, C):
    d, rho_b, g = 0.004, 1500.0, 9.81
    D = np.array([6, 8, 10, 13, 16]) * d
    W = C * rho_b * np.sqrt(g) * (D - k * d) ** n
    fit = beverloo.fit_beverloo(D, W, d, rho_b, g)
    assert (fit.n, fit.k, fit.C) == (pytest.approx(n, rel=1e-6), pytest.approx(k, rel=1e-6),
                                     pytest.approx(C, rel=1e-6))
    noisy = W * (1 + 0.01 * np.random.default_rng(1).standard_normal(len(W)))
    fit = beverloo.fit_beverloo(D, noisy, d, rho_b, g)
    assert abs(fit.n - n) < 0.3 and 0.01 > fit.rms > 0


def test_command_line(tmp_path, capsys):
    path = tmp_path / "rates.csv"
    D = np.array([6, 8, 10, 13]) * 0.004
    W = 0.6 * 1500 * np.sqrt(9.81) * (D - 1.5 * 0.004) ** 2.5
    path.write_text("D,W\n" + "".join(f"{a},{b}\n" for a, b in zip(D, W)))
    assert beverloo.main([str(path), "--d", "0.004", "--rho-b", "1500"]) == 0
    assert "exponent 2.500, k 1.500, C 0.600" in capsys.readouterr().out
    path.write_text("D,W\n0.1,1\n0.2,2\n")
    assert beverloo.main([str(path), "--d", "0.004", "--rho-b", "1500"]) == 2
