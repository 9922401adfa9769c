#!/usr/bin/env python
"""Fit Beverloo's law to the discharge rates of a hopper or silo.

Beverloo's law for the steady mass flow rate W (kg/s) of grains of size d (m) through an
orifice of diameter D (m) is

    W = C rho_b sqrt(g) (D - k d)^(5/2)

with rho_b the bulk density (kg/m^3) and g the gravity (m/s^2); for spheres the published
ranges are C about 0.5-0.7 and k about 1-2.  To test a simulation against it, the exponent
is fitted too: W = A (D - k d)^n by non-linear least squares on the relative residuals
(scipy's ``curve_fit``, started from n = 2.5, k = 1.5), then C = A / (rho_b sqrt(g)).  The
fit needs three orifices at least (three parameters); with the exponent given (``n``), k and
C alone are fitted (two orifices at least).  Each fitted parameter comes with its standard
error (the covariance of ``curve_fit``, scaled by the residuals; NaN without a spare
orifice): over a narrow range of D, n and k trade off against each other, and a rate error
of 1 % can move n by a few tenths.

Usage::

    python postproc/beverloo.py RATES.csv --d 0.004 --rho-b 1500 [--g 9.81]

where RATES.csv has the columns ``D,W`` (one line per orifice).
"""
from __future__ import annotations

import argparse
import sys
import warnings
from dataclasses import dataclass

import numpy as np
from scipy.optimize import OptimizeWarning, curve_fit


@dataclass(frozen=True)
class BeverlooFit:
    """The fitted exponent n, shift k (in grain sizes) and coefficient C, the RMS of the
    relative residuals of W, and the standard errors of n, k and C (sd_n 0 when n was
    given; NaN without a spare orifice)."""

    n: float
    k: float
    C: float
    rms: float
    sd_n: float = float("nan")
    sd_k: float = float("nan")
    sd_C: float = float("nan")


def fit_beverloo(D, W, d: float, rho_b: float, g: float = 9.81,
                 n: float | None = None) -> BeverlooFit:
    """Fit W = A (D - k d)^n to orifice diameters D (m) and mass flow rates W (kg/s), the
    exponent too unless ``n`` is given (module docstring); ValueError with too few orifices
    (three, two with ``n`` given) or a non-positive rate."""
    D, W = np.asarray(D, float), np.asarray(W, float)
    need = 3 if n is None else 2
    if len(D) < need or len(D) != len(W):
        raise ValueError(f"the fit needs the rates of {'three' if need == 3 else 'two'} "
                         "orifices at least")
    if not np.all(W > 0):
        raise ValueError("every mass flow rate must be positive")

    def model(Dv, A, k, m):
        return A * np.maximum(Dv - k * d, 1e-12) ** m

    k0 = 1.5
    A0 = float(np.median(W / np.maximum(D - k0 * d, 1e-12) ** (2.5 if n is None else n)))
    with warnings.catch_warnings():            # no spare orifice: no covariance (NaN)
        warnings.simplefilter("ignore", OptimizeWarning)
        if n is None:
            p, cov = curve_fit(model, D, W, p0=(A0, k0, 2.5), sigma=W, maxfev=20000)
        else:
            p, cov = curve_fit(lambda Dv, A, k: model(Dv, A, k, n), D, W, p0=(A0, k0),
                               sigma=W, maxfev=20000)
            p, cov = np.append(p, n), np.pad(cov, ((0, 1), (0, 1)))
    A, k, m = (float(x) for x in p)
    sd = np.sqrt(np.abs(np.diag(cov))) if np.all(np.isfinite(cov)) else np.full(3, np.nan)
    if n is not None:
        sd[2] = 0.0                            # the exponent was given
    rms = float(np.sqrt(np.mean((model(D, A, k, m) / W - 1.0) ** 2)))
    scale = rho_b * np.sqrt(g)
    return BeverlooFit(m, k, float(A / scale), rms, float(sd[2]), float(sd[1]),
                       float(sd[0] / scale))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("rates", help="CSV with the columns D,W")
    parser.add_argument("--d", type=float, required=True, help="grain size (m)")
    parser.add_argument("--rho-b", type=float, required=True, help="bulk density (kg/m^3)")
    parser.add_argument("--g", type=float, default=9.81, help="gravity (m/s^2)")
    args = parser.parse_args(argv)
    data = np.genfromtxt(args.rates, delimiter=",", names=True)
    try:
        fit = fit_beverloo(data["D"], data["W"], args.d, args.rho_b, args.g)
    except (ValueError, RuntimeError) as exc:
        print(f"beverloo: {args.rates}: {exc}", file=sys.stderr)
        return 2
    print(f"exponent {fit.n:.3f}, k {fit.k:.3f}, C {fit.C:.3f} (rms of W {fit.rms:.2%}; "
          f"standard errors {fit.sd_n:.2g}, {fit.sd_k:.2g}, {fit.sd_C:.2g})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
