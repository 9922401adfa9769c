#!/usr/bin/env python
"""Angles of repose measured from particle positions: a heap's, and a rotating drum's bed.

A heap poured onto a floor around a vertical axis has a conical flank.  Its free surface is
sampled by the highest particle top (centroid height + bounding radius) in each ring of the
radial distance r from the axis; the flank is the rings between ``inner`` and ``outer`` of
the heap's foot radius (the cap at the top and the toe at the foot are left out), and the
angle of repose is the slope of the straight line fitted to the ring tops there,

    angle = atan(−dz/dr)   (degrees),

with its standard error from the fit's residuals.  The axis is the horizontal centroid of the
particles unless given; the foot radius is the largest r of a particle resting near the floor
(within ``foot_band`` of the lowest particle top).

In a drum turning about a horizontal axis the bed is a circular segment whose free surface
(the chord) tilts by the dynamic angle of repose.  By symmetry the chord is the direction of
the major principal axis of the segment's cross-section, so :func:`bed_angle` takes the
angle of that axis of the particles' centroids projected onto the plane normal to the drum's
axis (their covariance), measured from the horizontal.

Usage::

    python postproc/repose.py RESULTS.h5 --size D [--time T] [--axis X Y] [--rings 12]

prints the angle for the results sample nearest T (default: the last one); D (m) is the
particles' largest bounding diameter.
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Repose:
    """Angle of repose (degrees) with its standard error, the flank's ring radii (m) and
    tops (m) it was fitted to, and the heap's foot radius (m)."""

    angle: float
    error: float
    r: np.ndarray
    top: np.ndarray
    foot: float = float("nan")


def ring_tops(x: np.ndarray, radius: np.ndarray, axis: np.ndarray, edges: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    """(ring centres (m), highest particle top (m) per ring) for the rings ``edges`` of the
    horizontal distance from ``axis`` (x, y); empty rings are left out."""
    r = np.hypot(x[:, 0] - axis[0], x[:, 1] - axis[1])
    top = x[:, 2] + radius
    ring = np.digitize(r, edges) - 1
    centres, tops = [], []
    for k in range(len(edges) - 1):
        inside = ring == k
        if inside.any():
            centres.append(0.5 * (edges[k] + edges[k + 1]))
            tops.append(top[inside].max())
    return np.array(centres), np.array(tops)


def angle_of_repose(x, radius, axis=None, rings: int = 12, inner: float = 0.25,
                    outer: float = 0.85, foot_band: float | None = None) -> Repose:
    """The heap's angle of repose (module docstring) from centroids x (N,3) m and bounding
    radii (N,) m, gravity along −z."""
    x = np.asarray(x, float)
    radius = np.broadcast_to(np.asarray(radius, float), (len(x),))
    axis = x[:, :2].mean(axis=0) if axis is None else np.asarray(axis, float)
    top = x[:, 2] + radius
    band = 2.0 * radius.max() if foot_band is None else foot_band
    low = top <= top.min() + band
    foot = np.hypot(x[low, 0] - axis[0], x[low, 1] - axis[1]).max()
    edges = np.linspace(inner * foot, outer * foot, rings + 1)
    r, tops = ring_tops(x, radius, axis, edges)
    if len(r) < 3:
        raise ValueError(f"the heap's flank has {len(r)} non-empty rings; 3 are needed")
    coef, cov = np.polyfit(r, tops, 1, cov=True)
    slope, err = coef[0], float(np.sqrt(cov[0, 0]))
    angle = float(np.degrees(np.arctan(-slope)))
    error = float(np.degrees(err / (1.0 + slope ** 2)))
    return Repose(angle, error, r, tops, float(foot))


def bed_angle(x, axis: int = 0, up: int = 2) -> float:
    """The dynamic angle of repose (degrees, in (−90, 90]) of the bed of centroids x (N,3) m
    in a drum turning about the coordinate axis ``axis`` with ``up`` the vertical (module
    docstring): the angle of the major principal axis of the cross-section's centroids from
    the horizontal, positive when the surface rises along the third coordinate axis."""
    x = np.asarray(x, float)
    side = 3 - axis - up
    yz = np.column_stack([x[:, side], x[:, up]])
    w, v = np.linalg.eigh(np.cov(yz.T))
    major = v[:, np.argmax(w)]
    if major[0] < 0.0:
        major = -major
    return float(np.degrees(np.arctan2(major[1], major[0])))


def main(argv=None) -> int:
    import h5py
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("results", help="results.h5 of a run")
    p.add_argument("--size", type=float, required=True,
                   help="the particles' largest bounding diameter (m)")
    p.add_argument("--time", type=float, default=None, help="sample time (s); default last")
    p.add_argument("--axis", type=float, nargs=2, default=None, metavar=("X", "Y"))
    p.add_argument("--rings", type=int, default=12)
    a = p.parse_args(argv)
    with h5py.File(a.results) as f:
        t, off = f["time"][:], f["offset"][:]
        k = len(t) - 1 if a.time is None else int(np.argmin(np.abs(t - a.time)))
        x = f["position"][off[k]:off[k + 1]]
    rep = angle_of_repose(x, 0.5 * a.size, a.axis, a.rings)
    print(f"t = {t[k]:.4g} s: angle of repose {rep.angle:.2f} ± {rep.error:.2f} degrees "
          f"({len(x)} particles, {len(rep.r)} rings)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
