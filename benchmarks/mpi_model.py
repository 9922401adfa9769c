"""A model of the domain decomposition's cost on P ranks, calibrated by the 2-rank run of
benchmarks/bench_mpi.py, predicting the strong-scaling efficiency at 16 and 64 ranks.

What is measured (bench_mpi.py, on this machine) and what is modelled (here):

measured
  t1     time loop per deck step on 1 rank x 1 thread for the settled pack of N0 particles (s)
  s      internal steps per deck step
  g2     ghosts per rank on 2 ranks (one cut plane across the pack's extent L)
  G      bytes every rank receives per deck step in the gathers (deck end, rebuilds): the sum
         of all ranks' parts, from the 2-rank run (it grows with N, not with P)
  Tg     seconds per deck step in the gathers and their merges on 2 ranks (merge work ~ N)
  c_rep  seconds per particle and deck step of the work every rank repeats for all N
         particles (integration, odometers, the cell grid of the bounding spheres): the cost
         per particle-step of a falling pack without contacts, on 1 rank

modelled (assumptions stated)
  ghost layer   w = g2 L / N0 (ghosts lie within w of the cut); an interior cube of an RCB cut
                into P parts of side l = (V/P)^(1/3) has the ghost fraction
                gamma = (1 + 2w/l)^3 - 1; half its ghosts' pairs cross the cut and are solved
                twice
  compute       t1 (N/N0) / P * (1 + gamma/2)
  per internal  alpha (6 + 3 log2 P) + beta 48 B x ghosts  (6 face neighbours' loads, 3
  step          reductions)
  per deck      Tg N/N0 + alpha log2 P + beta G N/N0  (gathers: volume and merges grow with N)
  step
  repeated      c_rep N
  network       alpha = 2 us latency, beta = 1 / (10 GB/s): an InfiniBand-class cluster
                network (assumed, not measured here)

Efficiency E(P) = (t1 N/N0 / P) / (compute + s x per-internal-step + per-deck-step + repeated).
"""
from __future__ import annotations

import math

ALPHA = 2e-6          # s, message latency (assumed)
BETA = 1.0 / 10e9     # s/B, inverse bandwidth (assumed)


def calibrate(strong: list[dict], weak: list[dict], n0: int, extent: float) -> dict:
    """The model's measured inputs from bench_mpi's strong and weak results."""
    one = next(r for r in strong if r["ranks"] == 1 and r["threads"] == 1)
    two = next(r for r in strong if r["ranks"] == 2)
    dom = two["domain"]
    steps = max(two["steps"], 1)
    ghosts = sum(d["ghosts"] for d in dom) / len(dom)
    internal = sum(d["internal_steps"] for d in dom) / len(dom)
    gathered = sum(d["gather_bytes_per_internal_step"] for d in dom) * internal / steps
    t_gather = max(d["seconds"]["gathers"] for d in dom) / steps
    fall = weak[0]
    return dict(n0=n0, t1=one["per_step"], s=one["substeps"] / max(one["steps"], 1),
                g2=ghosts, w=ghosts * extent / n0, extent=extent, G=gathered, Tg=t_gather,
                c_rep=fall["per_step"] / fall["n"])


def efficiency(m: dict, n: int, p: int) -> dict:
    """Predicted time per deck step and efficiency of N = n particles on p ranks."""
    scale = n / m["n0"]
    volume = scale * m["extent"] ** 3 / 2          # the pack: L x L x L/2 (bench_settled_pack)
    side = (volume / p) ** (1 / 3)
    gamma = (1 + 2 * m["w"] / side) ** 3 - 1
    ideal = m["t1"] * scale / p
    compute = ideal * (1 + gamma / 2)
    ghosts = gamma * n / p
    per_internal = ALPHA * (6 + 3 * math.log2(p)) + BETA * 48 * ghosts
    per_deck = m["Tg"] * scale + ALPHA * math.log2(p) + BETA * m["G"] * scale
    repeated = m["c_rep"] * n
    total = compute + m["s"] * per_internal + per_deck + repeated
    return dict(n=n, p=p, gamma=gamma, ideal=ideal, compute=compute,
                comm=m["s"] * per_internal + per_deck, repeated=repeated, total=total,
                efficiency=ideal / total,
                bytes_per_internal_step=48 * ghosts + m["G"] * scale / m["s"])
