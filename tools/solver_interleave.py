#!/usr/bin/env python3
"""What interleaving cells in the contact solver's sweeps buys on the CPU
(Performance.solver_interleave, frictional_interleave with friction; contacts/pgs.py
``sweep_cells``), and that it changes no bit.

A projected Gauss-Seidel row update reads the velocities the previous update of its
cell wrote (rows of a cell share spheres), so one cell's updates form a chain of
dependent loads and floating-point operations. Cells of one colour share no sphere:
sweeping k of them interleaved (row j of each, then row j + 1 of each) gives the
processor k independent chains to overlap, with the bits of one cell after the other.

Runs on one thread, from the state at --at s (reached once, untimed): the pour's bed
(scenes/pour.toml, frictionless) and the same pour with friction mu = 0.5 on pairs
and walls, for --window s, for each k in --interleave. These 2,000 spheres run the
serial one-launch solver. Reported per scene and k: wall seconds per simulated second
of the window (fastest of --repeat runs from the same state, after an untimed pass
that compiles), contact rows and velocity sweeps per step, and whether the state at
the end has the same bits as with k = 1.

Then the parallel solver path (one launch per sweep, each colour a parallel loop): an
FCC block of about --bed-n spheres (10 sphere layers, tools/contact_solver.py's bed)
settled 0.5 s, held --bed-window s on 1 thread with solver_interleave k = 1 and 8 and
on 2 threads with parallel_interleave k = 1 and 8 (the parallel path forced:
Performance.serial_heavy_below = serial_solver_below = 0), the runs
alternated --bed-repeat times (two threads on a shared machine vary by tens of per
cent from run to run): median and fastest wall seconds per simulated second.

    python tools/solver_interleave.py               # ~6 min
    python tools/solver_interleave.py --write       # the 'solver-interleave' section of docs/bench.md
"""
from __future__ import annotations

import argparse
import datetime
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, HERE)

import taichi_spheres as ts  # noqa: E402
from taichi_spheres.config import Tuning  # noqa: E402
from machine import cpu_name, publish, untimed_pass  # noqa: E402  (tools/machine.py)
from contact_solver import fcc_bed  # noqa: E402  (tools/contact_solver.py)


def scenes(path: str) -> dict:
    """The frictionless pour and the same pour with mu = 0.5 (pairs and walls)."""
    pour = ts.load_scene(path)
    return {"pour, frictionless": pour,
            "pour, mu = 0.5": pour.replace(friction=0.5, wall_friction=None)}


def timed(scene, start: dict, interleave: int, window: float, repeat: int) -> dict:
    """Fastest wall s per simulated s of ``window`` s from checkpoint ``start``, rows and
    sweeps per step, and the end state's digest, with k cells interleaved
    (solver_interleave and frictional_interleave)."""
    sim = ts.Simulation(scene, threads=1, tuning=Tuning().with_(
        solver_interleave=interleave, frictional_interleave=interleave))
    sim.restore(start)
    t_end = sim.time + window
    untimed_pass(sim, lambda s: s.advance_to(t_end))
    best = float("inf")
    for _ in range(repeat):
        sim.restore(start)
        before = dict(sim.stats)
        t0 = time.perf_counter()
        sim.advance_to(t_end)
        best = min(best, time.perf_counter() - t0)
    s = sim.stats
    steps = max(s["contact_steps"] - before["contact_steps"], 1)
    return dict(wall=best / window, rows=(s["contacts"] - before["contacts"]) / steps,
                sweeps=(s["contact_iterations"] - before["contact_iterations"]) / steps,
                digest=ts.observe.state_digest(sim.state(), sim.precision))


def parallel_bed(n_target: int, window: float, repeat: int) -> list:
    """Report lines: the settled FCC bed held ``window`` s on 1 and 2 threads with
    interleave 1 and 8, alternated ``repeat`` times (median and fastest)."""
    scene = fcc_bed(n_target)
    sim = ts.Simulation(scene, threads=2)
    sim.advance(0.5)
    start = sim.checkpoint()
    lines = ["", f"Parallel solver path: FCC bed of {scene.n} spheres settled 0.5 s, then "
                 f"{window:g} s held; {repeat} alternated runs per setting.", "",
             "| threads | cells interleaved (solver_interleave on 1 thread, parallel_interleave on 2) "
             "| median wall s / sim s | fastest | same bits as 1 |",
             "|---|---|---|---|---|"]
    for threads in (1, 2):
        sims, times, digests = {}, {}, {}
        for k in (1, 8):
            knobs = (("solver_interleave", "frictional_interleave") if threads == 1
                     else ("parallel_interleave",))
            sims[k] = ts.Simulation(scene, threads=threads, tuning=Tuning().with_(
                serial_heavy_below=0, serial_solver_below=0, **{n: k for n in knobs}))
            sims[k].restore(start)
            untimed_pass(sims[k], lambda s: s.advance(window))
            times[k] = []
        for _ in range(repeat):
            for k, run in sims.items():
                run.restore(start)
                t0 = time.perf_counter()
                run.advance(window)
                times[k].append((time.perf_counter() - t0) / window)
                digests[k] = ts.observe.state_digest(run.state(), run.precision)
        for k in (1, 8):
            ordered = sorted(times[k])
            lines.append(f"| {threads} | {k} | {ordered[len(ordered) // 2]:.1f} | "
                         f"{ordered[0]:.1f} | {'yes' if digests[k] == digests[1] else 'NO'} |")
            print(lines[-1], flush=True)
    return lines


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scene", default=os.path.join(HERE, "..", "scenes", "pour.toml"))
    p.add_argument("--at", type=float, default=1.0, help="start of the timed window [s]")
    p.add_argument("--window", type=float, default=0.1, help="simulated seconds timed")
    p.add_argument("--interleave", type=int, nargs="+", default=[1, 2, 4, 8, 16])
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--bed-n", type=int, default=40_000, help="spheres of the parallel-path bed")
    p.add_argument("--bed-window", type=float, default=0.06)
    p.add_argument("--bed-repeat", type=int, default=5)
    p.add_argument("--write", action="store_true")
    a = p.parse_args(argv)
    if a.interleave[0] != 1:
        a.interleave = [1] + a.interleave
    lines = [f"Measured {datetime.date.today()} on {cpu_name()}, 1 thread: "
             f"`python tools/solver_interleave.py {' '.join(x for x in argv if x != '--write')}`"
             .rstrip(), "",
             f"From the state at t = {a.at:g} s, {a.window:g} s simulated; fastest of "
             f"{a.repeat} runs.", "",
             "| scene | cells interleaved | wall s / sim s | vs 1 | rows / step | "
             "velocity sweeps / step | same bits as 1 |", "|---|---|---|---|---|---|---|"]
    for name, scene in scenes(a.scene).items():
        sim = ts.Simulation(scene, threads=1)
        sim.advance_to(a.at)
        start = sim.checkpoint()
        base = None
        for k in a.interleave:
            r = timed(scene, start, k, a.window, a.repeat)
            base = base or r
            lines.append(f"| {name} | {k} | {r['wall']:.3f} | {base['wall'] / r['wall']:.2f}x | "
                         f"{r['rows']:.0f} | {r['sweeps']:.1f} | "
                         f"{'yes' if r['digest'] == base['digest'] else 'NO'} |")
            print(lines[-1], flush=True)
    lines += parallel_bed(a.bed_n, a.bed_window, a.bed_repeat)
    publish("\n".join(lines), "solver-interleave", a.write)


if __name__ == "__main__":
    main()
