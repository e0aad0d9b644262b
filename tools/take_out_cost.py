#!/usr/bin/env python3
"""Cost of one discharge: the wall time a Simulation spends taking the spheres that
reached a sink out of a large system, three ways (Performance.discharge_in_place,
takeout.py):

- reload: every sphere's rows and the warm-start table read to the host, renumbered
  there and loaded again (discharge_in_place = False);
- in place, serial: in the engine's fields, one pass in increasing index (the CPU below
  Performance.serial_light_below spheres);
- in place, parallel: numbered in chunks and moved through a scratch copy by parallel
  loops (a GPU; forced here with serial_light_below = 0).

The scene: ``--count`` spheres (r = 1 mm, frictional, e = 0.5) on a cubic lattice of
spacing 2.2 r at rest on the floor of a box under gravity, a sink over the bottom of one
corner; the lowest layer falls 0.1 r into it, then the layers above follow, one
discharge at a time. Each way runs the same ``--duration`` s; reported per way: the
discharges, the spheres taken out, and the wall ms of each discharge (the first one
includes compiling kernels, so the later ones are the cost). All three end
in the same state (the test suite checks the bits, tests/test_discharge.py).

    python tools/take_out_cost.py                    # 10^5 spheres, 2 threads, ~2 min
    python tools/take_out_cost.py --arch cuda --write     # section 'take-out-cost-cuda'
"""
from __future__ import annotations

import argparse
import datetime
import os
import sys
import time

import numpy as np
import taichi as ti

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, HERE)

import taichi_spheres as ts  # noqa: E402
from taichi_spheres import runtime  # noqa: E402
from taichi_spheres.config import Tuning  # noqa: E402
from machine import hardware, publish  # noqa: E402

#: the ways compared: label and Performance options
WAYS = (("reload", dict(discharge_in_place=False)),
        ("in place, serial", dict(discharge_in_place=True, serial_light_below=10 ** 9)),
        ("in place, parallel", dict(discharge_in_place=True, serial_light_below=0)))


def lattice_scene(count: int, radius: float = 0.001):
    """About ``count`` spheres on a cubic lattice at rest on the floor (module
    docstring), a sink over the floor of one corner."""
    side = max(2, round((count / 40) ** 0.5))
    layers = max(1, count // (side * side))
    step = 2.2 * radius
    g = np.arange(side) * step + step / 2
    X, Y, Z = np.meshgrid(g, g, np.arange(layers) * step + step / 2, indexing="ij")
    x = np.stack([X.ravel(), Y.ravel(), Z.ravel()], 1)
    box = ((0, 0, 0), (side * step, side * step, layers * step + 10 * radius))
    sink = ts.Sink((0, 0, 0), (20 * radius, 20 * radius, 1.05 * radius))
    return ts.Scene.from_arrays(x, np.zeros_like(x), np.full(len(x), radius), box=box,
                                gravity=(0, 0, -9.81), restitution=0.5, friction=0.5,
                                sinks=(sink,))


def discharge_times(scene, options: dict, duration: float, arch: str) -> dict:
    """Run ``scene`` for ``duration`` s with the Performance ``options``; the wall ms of
    each discharge (Simulation._discharge, timed around it), the spheres taken out
    and the end state's digest."""
    sim = ts.Simulation(scene, arch=arch, tuning=Tuning().with_(**options))
    inner, spent = sim._discharge, []

    def timed():
        start = time.perf_counter()
        inner()
        ti.sync()
        spent.append(1e3 * (time.perf_counter() - start))

    sim._discharge = timed
    sim.advance(duration)
    return dict(ms=spent, taken=sim.stats["discharged"],
                digest=ts.observe.state_digest(sim.state(), sim.precision))


def report(args, rows: dict, n: int) -> str:
    hw = hardware(args.arch) + (f", {args.threads} threads" if args.arch == "cpu" else "")
    lines = [f"Measured {datetime.date.today()} on {hw}, f64: "
             f"`python tools/take_out_cost.py {' '.join(a for a in sys.argv[1:] if a != '--write')}`",
             "", f"{n} spheres on a lattice at rest, a sink over the floor of one corner; "
             f"{args.duration} s, one discharge per layer that reaches it (the first "
             "includes compiling kernels).", "",
             "| way | discharges | spheres taken out | ms per discharge (first; later ones) "
             "| end state digest |", "|---|---|---|---|---|"]
    for label, r in rows.items():
        later = ", ".join(f"{t:.1f}" for t in r["ms"][1:]) or "-"
        first = f"{r['ms'][0]:.0f}" if r["ms"] else "-"
        lines.append(f"| {label} | {len(r['ms'])} | {r['taken']} | {first}; {later} "
                     f"| {r['digest']} |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--count", type=int, default=100_000)
    ap.add_argument("--duration", type=float, default=0.06)
    ap.add_argument("--threads", type=int, default=2, help="CPU threads (cpu only)")
    ap.add_argument("--arch", default="cpu", choices=runtime.ARCHS)
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args(argv)
    if args.count < 8 or not args.duration > 0:
        ap.error("--count takes at least 8 spheres and --duration a positive time")
    runtime.ensure(args.arch, "f64", threads=args.threads if args.arch == "cpu" else None)
    scene = lattice_scene(args.count)
    rows = {label: discharge_times(scene, options, args.duration, args.arch)
            for label, options in WAYS}
    section = "take-out-cost" + ("" if args.arch == "cpu" else f"-{args.arch}")
    publish(report(args, rows, scene.n), section, args.write)


if __name__ == "__main__":
    main()
