#!/usr/bin/env python3
"""Cost of a large silo discharge (10^5 spheres by default) per thread count.

The silo of tools/silo.py (flat floor with a centred orifice, a cylinder wall, a sink
below; e = 0.5, mu = 0.5, density 2500 kg/m^3) is filled with ``--count`` spheres on
its jittered lattice (spacing 2.2 r, as tools/silo.py ``fill_positions``). With
``--settle`` > 0 the fill first settles with the orifice closed (untimed); the orifice
(``--orifice`` diameters) is then open and the discharge runs ``--duration`` s after
0.01 s, timed on a second pass from a checkpoint (the first pass, untimed, compiles
every kernel the window needs: Taichi compiles a kernel when it first runs, and some
run only after impacts start). Reported per thread count: wall seconds
per simulated second, steps, contact rows and velocity sweeps per step, spheres
discharged, the largest overlap.

    python tools/silo_large.py                          # 10^5 spheres, 1 and 2 threads
    python tools/silo_large.py --count 20000 --threads 2 --no-write
    python tools/silo_large.py --write                  # the 'silo-large' section of docs/bench.md
    python tools/silo_large.py --arch cuda --write      # on a GPU: section 'silo-large-cuda'
    python tools/silo_large.py --arch cuda --duration 0.02 --batches 8 1 --write
                                     # sweeps per wait compared: 'silo-large-cuda-waits'
"""
from __future__ import annotations

import argparse
import datetime
import math
import os
import sys
import time
import types

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, HERE)

import taichi_spheres as ts  # noqa: E402
from taichi_spheres import observe  # noqa: E402
from taichi_spheres.config import Tuning  # noqa: E402
import silo  # noqa: E402  (tools/silo.py)
from machine import hardware, untimed_pass, write_section  # noqa: E402


def fill_height(count, radius, silo_radius) -> float:
    """Lattice height [m] that holds about ``count`` spheres in the silo."""
    step = 2.2 * radius
    per_layer = math.pi * (silo_radius - radius) ** 2 / step ** 2
    return (count / per_layer + 1) * step


def discharging(a, threads, batch=None):
    """The silo of ``a`` (module docstring) on ``a.arch`` with ``threads`` CPU threads (None
    on a GPU, where the threads only launch kernels), 0.01 s into its discharge;
    ``batch``: the contact solver's sweeps per wait (Performance.sweeps_per_wait and
    gpu_sweeps_per_wait; None: the defaults)."""
    tuning = Tuning() if batch is None else Tuning().with_(
        sweeps_per_wait=batch, gpu_sweeps_per_wait=batch)
    settings = types.SimpleNamespace(silo_radius=a.silo_radius, radius=a.radius, mu=0.5,
                                     fill=fill_height(a.count, a.radius, a.silo_radius))
    c = a.silo_radius + 0.005
    x = silo.fill_positions(a.silo_radius, a.radius, settings.fill, 0.05, np.array([c, c]), 1)
    x = x[:a.count]
    hole = a.orifice * a.radius
    state = None
    if a.settle > 0:
        closed = ts.Simulation(silo.silo_scene(x, np.zeros_like(x), None, settings, None),
                               arch=a.arch, threads=threads, tuning=tuning)
        closed.advance(a.settle)
        st = closed.state()
        state = (st.x, st.v, st.omega)
    sim = ts.Simulation(silo.silo_scene(x, np.zeros_like(x), None, settings, hole),
                        arch=a.arch, threads=threads, tuning=tuning)
    if state is not None:
        sim.set_state(*state[:2], omega=state[2])
    sim.advance(0.01)
    return sim


def run(a, threads, batch=None) -> dict:
    """One timed discharge (module docstring) on ``a.arch`` with ``threads`` CPU threads
    and ``batch`` sweeps per wait (None: the default); the end state's digest too (the
    batch changes no bits)."""
    sim = discharging(a, threads, batch)
    untimed_pass(sim, lambda s: s.advance(a.duration))
    s0 = dict(sim.stats)
    t0, w0 = sim.time, time.perf_counter()
    sim.advance_to(t0 + a.duration)
    wall = time.perf_counter() - w0
    s = sim.stats
    steps = s["steps"] - s0["steps"]
    # the spheres it started with: the sink does not recycle, and restore (untimed_pass)
    # puts the counters back with the state
    return dict(threads=threads, n=sim.n + s["discharged"],
                wall_per_sim=wall / (sim.time - t0), steps=steps,
                rows=(s["contacts"] - s0["contacts"]) / max(steps, 1),
                sweeps=(s["contact_iterations"] - s0["contact_iterations"]) / max(steps, 1),
                discharged=s["discharged"], overlap=s["max_overlap"],
                arch=a.arch, batch=batch,
                digest=observe.state_digest(sim.state(), sim.precision))


def report(rows, argv, a) -> str:
    lines = [f"Measured {datetime.date.today()} on {hardware(a.arch)}, f64: "
             f"`python tools/silo_large.py {' '.join(argv)}`".rstrip(), "",
             f"{rows[0]['n']} spheres of d = {2e3 * a.radius:g} mm in a silo of radius "
             f"{1e3 * a.silo_radius:g} mm, orifice D = {a.orifice:g} d; "
             + (f"settled {a.settle:g} s with the orifice closed, then " if a.settle > 0
                else "from the lattice fill (the bed compacts while it discharges), ")
             + f"{a.duration:g} s of discharge timed.", "",
             "| threads | sweeps / wait | wall s / sim s | steps | rows / step | "
             "sweeps / step | discharged | max overlap / d | end state digest |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        wall = r["wall_per_sim"]
        batch = r["batch"] or "default"
        lines.append(f"| {r['threads'] or a.arch.upper()} | {batch} | "
                     f"{wall:.{0 if wall >= 100 else 2}f} | "
                     f"{r['steps']} | "
                     f"{r['rows']:.0f} | {r['sweeps']:.0f} | {r['discharged']} | "
                     f"{r['overlap']:.1e} | {r['digest']} |")
    return "\n".join(lines)


def parser() -> argparse.ArgumentParser:
    """The command line (module docstring); tools/kernel_profile.py builds its silo too."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--count", type=int, default=100_000)
    p.add_argument("--radius", type=float, default=0.001, help="sphere radius [m]")
    p.add_argument("--silo-radius", type=float, default=0.04, help="[m]")
    p.add_argument("--orifice", type=float, default=8.0, help="orifice diameter / d")
    p.add_argument("--settle", type=float, default=0.0, help="[s], orifice closed")
    p.add_argument("--duration", type=float, default=0.02, help="timed discharge [s]")
    p.add_argument("--threads", type=int, nargs="+", default=None,
                   help="CPU thread counts (default 1 2; not on a GPU)")
    p.add_argument("--arch", default="cpu", choices=ts.runtime.ARCHS,
                   help="cpu or a GPU arch (cuda)")
    p.add_argument("--batches", type=int, nargs="+", default=[None],
                   help="contact solver sweeps per wait to compare (default: the "
                        "default of Performance)")
    p.add_argument("--write", action="store_true")
    p.add_argument("--no-write", dest="write", action="store_false")
    return p


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    p = parser()
    a = p.parse_args(argv)
    if a.threads is not None and (a.arch != "cpu" or min(a.threads) < 1):
        p.error("--threads takes CPU thread counts >= 1, and only with --arch cpu")
    rows = []
    a.threads = (a.threads or [1, 2]) if a.arch == "cpu" else [None]
    for threads in a.threads:
        for batch in a.batches:
            rows.append(run(a, threads, batch))
            print(rows[-1], flush=True)
    text = report(rows, [s for s in argv if s != "--write"], a)
    print(text)
    if a.write:
        name = "silo-large" if a.arch == "cpu" else f"silo-large-{a.arch}"
        if a.batches != [None]:      # a comparison of sweeps per wait
            name += "-waits"
        write_section(os.path.join(HERE, "..", "docs", "bench.md"), name, text)


if __name__ == "__main__":
    main()
