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


def test_given_exponent_and_standard_errors():
    d, rho_b, g = 0.004, 1500.0, 9.81
    D = np.array([6, 7, 8, 9.5]) * d
    W = 0.6 * rho_b * np.sqrt(g) * (D - 1.3 * d) ** 2.5
    fit = beverloo.fit_beverloo(D[:2], W[:2], d, rho_b, g, n=2.5)    # two orifices suffice
    assert (fit.n, fit.k, fit.C, fit.sd_n) == (2.5, pytest.approx(1.3, rel=1e-6),
                                               pytest.approx(0.6, rel=1e-6), 0.0)
    assert np.isnan(beverloo.fit_beverloo(D[:3], W[:3], d, rho_b, g).sd_n)   # no spare one
    with pytest.raises(ValueError):
        beverloo.fit_beverloo(D[:1], W[:1], d, rho_b, g, n=2.5)
    # noisy rates: the standard errors cover the errors of the parameters, and the free
    # exponent's is much larger than k's and C's with n given (the narrow range of D)
    rng = np.random.default_rng(3)
    errors = []
    for _ in range(40):
        noisy = W * (1 + 0.01 * rng.standard_normal(len(W)))
        free = beverloo.fit_beverloo(D, noisy, d, rho_b, g)
        fixed = beverloo.fit_beverloo(D, noisy, d, rho_b, g, n=2.5)
        errors.append((abs(free.n - 2.5) / free.sd_n, abs(fixed.k - 1.3) / fixed.sd_k,
                       abs(fixed.C - 0.6) / fixed.sd_C, free.sd_k / fixed.sd_k))
    errors = np.array(errors)
    assert np.all(np.median(errors[:, :3], axis=0) < 2.0)
    assert np.median(errors[:, 3]) > 3.0
