#!/usr/bin/env python3
"""What a later Simulation in the same process costs to start: compile once.

In a fresh process per compile mode (and per kernel-cache state): build a gas of
``--n`` spheres (inelastic, walls on z, gravity: most features compiled in) and time
its first ``advance(--window)`` (compiles the step), then a second one (warm); then
build a *later* Simulation with the same features but another sphere count and box
(``--n2`` spheres) and time its first ``advance(--window)``. Reported: the later
Simulation's first window minus a warm window ("extra"), i.e. what starting it
compiled. An engine shared by Simulations (taichi_spheres/engine.py) makes that
extra close to zero.

Kernel cache: "empty" runs with a new empty Taichi offline cache (what a first run or
CI sees), "warm" runs again on the cache the empty run filled.

    python tools/compile_once.py                 # ~1-2 min on 2 cores
    python tools/compile_once.py --modes fast --n 2000 --n2 1500
    python tools/compile_once.py --write         # also into docs/bench.md
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.join(HERE, "..")
sys.path.insert(0, HERE)
from machine import cpu_name, kernel_cache_env, publish  # noqa: E402  (tools/machine.py)


def _scene(n, seed):
    sys.path.insert(0, ROOT)
    from taichi_spheres.builders import gas
    return gas(n, packing=0.2, radius=0.01, periodic=(True, True, False),
               gravity=(0, 0, -9.81), restitution=0.8, wall_restitution=0.9, seed=seed)


def _timed_advance(sim, window) -> float:
    import taichi as ti
    t0 = time.perf_counter()
    sim.advance(window)
    ti.sync()
    return time.perf_counter() - t0


def child(mode: str, n: int, n2: int, window: float) -> dict:
    """One process: first, warm and later-Simulation windows [s]."""
    sys.path.insert(0, ROOT)
    import taichi_spheres as ts
    from taichi_spheres import runtime
    runtime.ensure("cpu", "f64", compile=mode)
    t0 = time.perf_counter()
    first = ts.Simulation(_scene(n, 1))
    build_first = time.perf_counter() - t0
    cold = _timed_advance(first, window)
    warm = min(_timed_advance(first, window) for _ in range(3))
    t0 = time.perf_counter()
    later = ts.Simulation(_scene(n2, 2))
    build_later = time.perf_counter() - t0
    later_first = _timed_advance(later, window)
    later_warm = min(_timed_advance(later, window) for _ in range(3))
    return dict(mode=mode, n=n, n2=n2, window=window, build_first=build_first,
                first_advance=cold, warm_advance=warm, build_later=build_later,
                later_first_advance=later_first, later_warm_advance=later_warm,
                extra=build_later + later_first - later_warm)


def run_child(mode, n, n2, window, cache_dir) -> dict:
    env = kernel_cache_env(cache_dir)
    out = subprocess.run([sys.executable, __file__, "--child", mode, "--n", str(n),
                          "--n2", str(n2), "--window", str(window)],
                         env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def report(args, rows) -> str:
    """docs/bench.md's section: provenance, table, what it means."""
    cmd = " ".join(["python tools/compile_once.py"] + sys.argv[1:])
    lines = "\n".join(rows)
    return f"""## Compile once: a later Simulation in the same process

Generated {datetime.date.today().isoformat()} by `{cmd}` on {cpu_name()}, {os.cpu_count()} cores, arch cpu, f64, Python {platform.python_version()}.
One process per row: a gas of {args.n:,} spheres (inelastic, periodic in x and y, walls
and gravity along z) is built and advanced by {args.window} s three times (its first
window compiles the step), then a later Simulation of the same features but
{args.n2:,} spheres in a smaller box is built and advanced by {args.window} s.
*Extra*: the later Simulation's build and first window minus one of its warm windows,
i.e. what starting it costs beyond stepping. Kernel cache *empty*: a new Taichi offline
cache (a first run, CI); *warm*: the cache the empty row filled. Simulations share an
engine (`taichi_spheres/engine.py`) when their compiled features match and the
earlier one's fields have room, so the later one compiles nothing.

| compile mode | kernel cache | first Simulation: build + first advance [s] | warm advance [s] | later Simulation: build + first advance [s] | extra [s] |
|---|---|---|---|---|---|
{lines}
"""


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--modes", nargs="+", default=["fast", "optimized"])
    p.add_argument("--n", type=int, default=2000)
    p.add_argument("--n2", type=int, default=1500)
    p.add_argument("--window", type=float, default=0.05)
    p.add_argument("--write", action="store_true", help="write the table into docs/bench.md")
    p.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.child:
        print(json.dumps(child(args.child, args.n, args.n2, args.window)))
        return 0
    rows = []
    for mode in args.modes:
        with tempfile.TemporaryDirectory() as cache:
            for state in ("empty", "warm"):
                r = run_child(mode, args.n, args.n2, args.window, cache)
                rows.append(f"| {mode} | {state} | {r['build_first'] + r['first_advance']:.2f} | "
                            f"{r['warm_advance']:.4f} | "
                            f"{r['build_later'] + r['later_first_advance']:.3f} | "
                            f"{r['extra']:.3f} |")
                print(rows[-1], flush=True)
    text = report(args, rows)
    publish(text, "compile-once", args.write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
