#!/usr/bin/env python3
"""What exact floating point costs: steps with Taichi's fast math off (the engine's
setting, runtime.FAST_MATH = False) against on, on the bench's gas.

Each round runs one process per setting (order alternating between rounds), each
building the elastic periodic gas of tools/bench.py (``--n`` spheres, packing 0.3),
taking warm-up steps and then timing ``--blocks`` blocks of ``--steps`` steps from
the same state; a process reports its fastest block in ms/step. Reported per round:
the ratio off / on (above 1: exact arithmetic is slower), then the median and range
over rounds. With ``--write`` the table goes into docs/bench.md (its own section).

    python tools/fast_math_cost.py                   # N = 1e5, 5 rounds, ~4 min
    python tools/fast_math_cost.py --n 10000 --rounds 3
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import statistics
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.join(HERE, "..")
sys.path.insert(0, HERE)
from machine import cpu_name, publish  # noqa: E402  (tools/machine.py)


def child(fast_math: bool, n: int, steps: int, blocks: int) -> dict:
    """One process: the fastest block's ms/step with fast math ``fast_math``."""
    sys.path.insert(0, ROOT)
    import taichi as ti
    import taichi_spheres as ts
    from taichi_spheres import runtime
    from taichi_spheres.builders import gas
    runtime.FAST_MATH = fast_math
    runtime.ensure("cpu", "f64")
    sim = ts.Simulation(gas(n, packing=0.3, periodic=True))
    for _ in range(5):
        sim.step(sim.max_step())
    start = sim.checkpoint()
    best = float("inf")
    for _ in range(blocks):
        sim.restore(start)
        ti.sync()
        t0 = time.perf_counter()
        for _ in range(steps):
            sim.step(sim.max_step())
        ti.sync()
        best = min(best, (time.perf_counter() - t0) / steps)
    return dict(fast_math=fast_math, ms_per_step=1e3 * best)


def run_child(fast_math, args) -> float:
    out = subprocess.run([sys.executable, __file__, "--child", str(int(fast_math)),
                          "--n", str(args.n), "--steps", str(args.steps),
                          "--blocks", str(args.blocks)],
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])["ms_per_step"]


def report(args, rounds) -> str:
    ratios = [off / on for off, on in rounds]
    rows = "\n".join(f"| {k + 1} | {off:.2f} | {on:.2f} | {off / on:.3f} |"
                     for k, (off, on) in enumerate(rounds))
    cmd = " ".join(["python tools/fast_math_cost.py"] + [a for a in sys.argv[1:]])
    return f"""## Exact floating point: fast math off (N = {args.n:,}, f64)

Generated {datetime.date.today().isoformat()} by `{cmd}` on {cpu_name()}, {os.cpu_count()} cores, arch cpu, Python {platform.python_version()}.
The engine initialises Taichi with `fast_math=False` (`taichi_spheres/runtime.py`
FAST_MATH), so that no multiply-add is fused and nothing is reassociated behind the
code's back: the bits then depend only on scene, precision and thread count, not on the
CPU model or compile mode (`tests/test_same_bits.py`). Cost on the bench's elastic gas,
one process per setting per round (order alternating), fastest of {args.blocks} blocks of
{args.steps} steps from the same state:

| round | fast math off, ms/step | on, ms/step | off / on |
|---:|---:|---:|---:|
{rows}

Median off / on over {len(rounds)} rounds: **{statistics.median(ratios):.3f}** (range
{min(ratios):.3f}–{max(ratios):.3f}); differences of ±25 % between runs are this
shared VM's noise.
"""


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--n", type=int, default=100_000)
    p.add_argument("--rounds", type=int, default=5)
    p.add_argument("--steps", type=int, default=20)
    p.add_argument("--blocks", type=int, default=3)
    p.add_argument("--write", action="store_true", help="write the table into docs/bench.md")
    p.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.child is not None:
        print(json.dumps(child(bool(int(args.child)), args.n, args.steps, args.blocks)))
        return 0
    rounds = []
    for k in range(args.rounds):
        times = {}
        for flag in ((False, True) if k % 2 == 0 else (True, False)):
            times[flag] = run_child(flag, args)
        rounds.append((times[False], times[True]))
        print(f"round {k + 1}: off {times[False]:.2f} ms/step, on {times[True]:.2f} ms/step, "
              f"off/on {times[False] / times[True]:.3f}", flush=True)
    text = report(args, rounds)
    publish(text, "fast-math", args.write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
