#!/usr/bin/env python3
"""What a run of a parameter sweep costs beyond its own stepping, on a Dask LocalCluster.

A sweep of ``--runs`` runs of one gas (``--n`` spheres, inelastic, walls and gravity
along z; restitution varied so that every run has the same compiled features) on a
LocalCluster of ``--workers`` processes, one Taichi thread each. Per run: *setup* is
building the Scene and the Simulation, *advance* the wall time of ``advance(--duration)``
(a worker's first run compiles the kernels there: Taichi compiles at first launch).
Reported: a worker's first run against its later ones, and the sweep's wall time
against the sum of its runs' wall times divided by the workers (scheduling, starting
the cluster and moving scenes to the workers).

    python tools/sweep_overhead.py                 # ~1 min on 2 cores
    python tools/sweep_overhead.py --write         # also into docs/bench.md
"""
from __future__ import annotations

import argparse
import datetime
import os
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(HERE, ".."))
from machine import cpu_name, publish  # noqa: E402  (tools/machine.py)


def worker_pid(sim):
    """The measure of every run: which worker process ran it, and when it ended."""
    return {"pid": os.getpid(), "ended": time.time()}


def run(args):
    """(rows, sweep wall seconds)."""
    import taichi_spheres as ts
    from taichi_spheres.builders import gas
    scene = gas(args.n, packing=0.2, radius=0.01, periodic=(True, True, False),
                gravity=(0.0, 0.0, -9.81), restitution=0.9, wall_restitution=0.9)
    values = [round(0.5 + 0.45 * k / max(args.runs - 1, 1), 4) for k in range(args.runs)]
    t0 = time.perf_counter()
    rows = ts.sweep(scene, {"restitution": values}, duration=args.duration,
                    measure=worker_pid, workers=args.workers, compile=args.compile)
    return rows, time.perf_counter() - t0


def report(rows, wall, args) -> str:
    """The markdown section: first and later runs of each worker, and the sweep's total."""
    failed = [r for r in rows if r["error"]]
    if failed:
        raise SystemExit(f"{len(failed)} runs failed: {failed[0]['error']}")
    first, later, seen = [], [], set()
    for row in sorted(rows, key=lambda r: r["ended"]):
        (later if row["pid"] in seen else first).append(row)
        seen.add(row["pid"])
    med = lambda rs, key: statistics.median(r[key] for r in rs) if rs else float("nan")  # noqa: E731
    busy = sum(r["setup_s"] + r["wall_s"] for r in rows) / args.workers
    date = datetime.date.today().isoformat()
    lines = [
        "## Sweeps: per-run overhead on a local Dask cluster", "",
        f"Generated {date} by `python tools/sweep_overhead.py --write` on {cpu_name()}, "
        f"{os.cpu_count()} cores, arch cpu, f64, {args.compile} compile mode. "
        f"{args.runs} runs of a gas of {args.n:,} spheres (walls and gravity along z, "
        f"restitution 0.5-0.95: the same compiled features) for {args.duration:g} s each, "
        f"on a LocalCluster of {args.workers} worker processes with one Taichi thread each; "
        f"Taichi's offline kernel cache as the machine has it (with an empty cache a "
        f"worker's first run compiles for longer: docs/bench.md, compile once).",
        "", "| runs | setup s (median) | advance s (median) |", "|---|---:|---:|",
        f"| first run of a worker ({len(first)}) | {med(first, 'setup_s'):.3f} | "
        f"{med(first, 'wall_s'):.3f} |",
        f"| later runs ({len(later)}) | {med(later, 'setup_s'):.3f} | "
        f"{med(later, 'wall_s'):.3f} |", "",
        f"Sweep wall time {wall:.1f} s (cluster start included) against {busy:.1f} s of "
        f"setup and advancing per worker. A worker's first run compiles the kernels "
        f"(Taichi compiles at first launch, so it shows in *advance*); later runs of the "
        f"same features reuse them (taichi_spheres/engine.py)."]
    return "\n".join(lines)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--n", type=int, default=2000)
    p.add_argument("--runs", type=int, default=8)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--duration", type=float, default=0.05)
    p.add_argument("--compile", default="fast", choices=["fast", "optimized"])
    p.add_argument("--write", action="store_true", help="also write docs/bench.md's section")
    args = p.parse_args()
    rows, wall = run(args)
    publish(report(rows, wall, args), "sweep-overhead", args.write)


if __name__ == "__main__":
    main()
