#!/usr/bin/env python
"""Fit Beverloo's law to the discharge rates of a hopper or silo.

Beverloo's law for the steady mass flow rate W (kg/s) of grains of size d (m) through an
orifice of diameter D (m) is

    W = C rho_b sqrt(g) (D - k d)^(5/2)

with rho_b the bulk density (kg/m^3) and g the gravity (m/s^2); for spheres the published
ranges are C about 0.5-0.7 and k about 1-2.  To test a simulation against it, the exponent
is fitted too: W = A (D - k d)^n by non-linear least squares (scipy's ``curve_fit``, started
from n = 2.5, k = 1.5), then C = A / (rho_b sqrt(g)).  The fit needs three orifices at least
(three parameters).

Usage::

    python postproc/beverloo.py RATES.csv --d 0.004 --rho-b 1500 [--g 9.81]

where RATES.csv has the columns ``D,W`` (one line per orifice).
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass

import numpy as np
from scipy.optimize import curve_fit


@dataclass(frozen=True)
class BeverlooFit:
    """The fitted exponent n, shift k (in grain sizes) and coefficient C, and the RMS of the
    relative residuals of W."""

    n: float
    k: float
    C: float
    rms: float


def fit_beverloo(D, W, d: float, rho_b: float, g: float = 9.81) -> BeverlooFit:
    """Fit W = A (D - k d)^n to orifice diameters D (m) and mass flow rates W (kg/s)
    (module docstring); ValueError with fewer than three orifices or a non-positive rate."""
    D, W = np.asarray(D, float), np.asarray(W, float)
    if len(D) < 3 or len(D) != len(W):
        raise ValueError("the fit needs the rates of three orifices at least")
    if not np.all(W > 0):
        raise ValueError("every mass flow rate must be positive")

    def model(Dv, A, k, n):
        return A * np.maximum(Dv - k * d, 1e-12) ** n

    k0 = 1.5
    A0 = float(np.median(W / np.maximum(D - k0 * d, 1e-12) ** 2.5))
    (A, k, n), _ = curve_fit(model, D, W, p0=(A0, k0, 2.5), sigma=W, maxfev=20000)
    rms = float(np.sqrt(np.mean((model(D, A, k, n) / W - 1.0) ** 2)))
    return BeverlooFit(float(n), float(k), float(A / (rho_b * np.sqrt(g))), rms)


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
    print(f"exponent {fit.n:.3f}, k {fit.k:.3f}, C {fit.C:.3f} (rms of W {fit.rms:.2%})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
