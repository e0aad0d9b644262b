#!/usr/bin/env python3
"""Compile time and step time of the compile modes (taichi_spheres.runtime.COMPILE_MODES).

Compile: each mode runs in a fresh process with an empty Taichi kernel cache (what a
first run, or CI, sees), modes alternating over ``--rounds`` rounds; per mode the
median over rounds of the seconds to build and first run

- *small*: two spheres (e = 0.5, gravity, walls: the features most tests compile),
  ``advance(0.5)``;
- *gas*: the bench's elastic gas (packing 0.3, periodic) of ``--n`` spheres, 3 steps;
- *fused*: 1,000 spheres of that gas with ``fused=True``, 3 steps;

and a hash of the gas's and the fused run's state after the timed steps below: equal
hashes mean both modes computed the same bits.

Steps: this shared VM's speed drifts by +-25 % from minute to minute, more than the
difference measured, so the modes step *side by side*: two processes at the same
time, one pinned to each core with one thread, for ``--window`` seconds, swapping
cores every round. Reported: the median over rounds of the per-round ratio of median
ms/step (fast / optimized), with its range, for the gas and for the fused 1,000 spheres. (Single
thread: the modes' code differs, not their threading.)

    python tools/compile_options.py                      # ~12 min on 2 cores
    python tools/compile_options.py --rounds 1 --n 10000 --window 5
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.join(HERE, "..")
sys.path.insert(0, HERE)
from machine import kernel_cache_env  # noqa: E402  (tools/machine.py)

MODES = ("optimized", "fast")


def _setup(mode, threads=None):
    sys.path.insert(0, ROOT)
    from taichi_spheres import runtime
    runtime.ensure("cpu", "f64", threads=threads, compile=mode)


def _state_hash(sim) -> str:
    st = sim.state()
    return hashlib.sha1(st.x.tobytes() + st.v.tobytes()).hexdigest()[:12]


def _steps(sim, count):
    import taichi as ti
    for _ in range(count):
        sim.step(sim.max_step())
    ti.sync()


def compile_child(mode: str, n: int) -> dict:
    """Compile seconds of the three builds in this fresh process, and state hashes."""
    _setup(mode)
    import numpy as np
    import taichi_spheres as ts
    from taichi_spheres.builders import gas
    out = {}
    x = np.array([[0.0, 0.0, 0.0], [1.5, 0.3, 0.0]])
    v = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    scene = ts.Scene.from_arrays(x, v, np.array([0.5, 0.5]), box=((-3.0,) * 3, (3.0,) * 3),
                                 gravity=(0.0, 0.0, -9.81), restitution=0.5)
    t0 = time.perf_counter()
    ts.Simulation(scene).advance(0.5)
    out["small"] = time.perf_counter() - t0
    for key, count, kw in (("gas", n, {}), ("fused", 1000, dict(fused=True))):
        t0 = time.perf_counter()
        sim = ts.Simulation(gas(count), **kw)
        _steps(sim, 3)
        out[key] = time.perf_counter() - t0
        _steps(sim, 20)
        out[key + "_hash"] = _state_hash(sim)
    return out


def step_child(mode: str, n: int, core: int, go: float, window: float) -> dict:
    """Median ms/step of the gas (n) and of the fused 1,000 spheres, one thread on one
    core, timed from wall time ``go`` for ``window`` s each (both processes in step)."""
    os.sched_setaffinity(0, {core})
    _setup(mode, threads=1)
    import taichi as ti
    import taichi_spheres as ts
    from taichi_spheres.builders import gas
    sims = {"gas": ts.Simulation(gas(n)), "fused": ts.Simulation(gas(1000), fused=True)}
    for sim in sims.values():
        _steps(sim, 3)
    if time.time() > go:
        raise SystemExit("compiling took longer than the start delay: raise --delay")
    out = {}
    for k, (key, sim) in enumerate(sims.items()):
        start = go + k * window
        while time.time() < start:
            time.sleep(0.005)
        times = []
        while time.time() < start + window:
            h = sim.max_step()
            t0 = time.perf_counter()
            sim.step(h)
            ti.sync()
            times.append(time.perf_counter() - t0)
        out[key] = statistics.median(times) * 1e3
        out[key + "_steps"] = len(times)
    return out


def _spawn(args, cache):
    env = kernel_cache_env(cache)
    return subprocess.Popen([sys.executable, __file__] + args, env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)


def _result(proc, what):
    out, err = proc.communicate()
    if proc.returncode != 0:
        raise SystemExit(f"{what} failed:\n{err[-3000:]}")
    return json.loads(out.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--n", type=int, default=100_000, help="spheres of the gas")
    ap.add_argument("--window", type=float, default=15.0, help="seconds of timed steps per "
                    "scene and round in the side-by-side runs")
    ap.add_argument("--delay", type=float, default=60.0, help="seconds both side-by-side "
                    "processes get to compile before timing starts")
    ap.add_argument("--child", nargs="+", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        kind, mode = args.child[:2]
        if kind == "compile":
            res = compile_child(mode, args.n)
        else:
            core, go = int(args.child[2]), float(args.child[3])
            res = step_child(mode, args.n, core, go, args.window)
        print(json.dumps(res))
        return
    if args.rounds < 1 or args.n < 8 or args.window <= 0 or args.delay <= 0:
        ap.error("--rounds >= 1, --n >= 8, --window > 0 and --delay > 0 please")
    allowed = sorted(os.sched_getaffinity(0))
    if len(allowed) < 2:
        ap.error("the side-by-side runs need 2 cores")
    common = ["--n", str(args.n), "--window", str(args.window)]
    compiled = {m: [] for m in MODES}
    ratios = {"gas": [], "fused": []}
    for r in range(args.rounds):
        for mode in (MODES if r % 2 == 0 else MODES[::-1]):
            with tempfile.TemporaryDirectory() as cache:
                res = _result(_spawn(["--child", "compile", mode] + common, cache),
                              f"compile run ({mode})")
            compiled[mode].append(res)
            print(f"round {r + 1} compile {mode}: " + ", ".join(
                f"{k} {v:.2f} s" if isinstance(v, float) else f"{k} {v}"
                for k, v in res.items()), flush=True)
        go = time.time() + args.delay
        cores = allowed[:2] if r % 2 == 0 else allowed[1::-1]
        side = {}
        with tempfile.TemporaryDirectory() as c0, tempfile.TemporaryDirectory() as c1:
            procs = {mode: _spawn(["--child", "steps", mode, str(core), str(go)] + common, cache)
                     for mode, core, cache in zip(MODES, cores, (c0, c1))}
            try:
                for mode, proc in procs.items():
                    side[mode] = _result(proc, f"side-by-side run ({mode})")
            finally:
                for proc in procs.values():
                    if proc.poll() is None:
                        proc.kill()
                        proc.wait()
        for key in ratios:
            ratios[key].append(side["fast"][key] / side["optimized"][key])
        print(f"round {r + 1} steps side by side (ms/step, one thread): " + "; ".join(
            f"{mode} gas {side[mode]['gas']:.2f} fused {side[mode]['fused']:.3f}"
            for mode in MODES), flush=True)

    med = {m: {k: statistics.median(row[k] for row in compiled[m])
               for k in ("small", "gas", "fused")} for m in MODES}
    same = all(a[k] == b[k] for a, b in zip(compiled["fast"], compiled["optimized"])
               for k in ("gas_hash", "fused_hash"))
    print(f"\nCompile modes, CPU, f64; {args.rounds} round(s); gas N = {args.n:,}, fused "
          "N = 1,000. Compile: seconds to build and first run, empty kernel cache, median "
          "of rounds. Steps: fast / optimized median ms/step, side by side on one core "
          "each, median of rounds (range over rounds).")
    print("| mode | compile small s | compile gas s | compile fused s | gas step time "
          "vs optimized | fused step time vs optimized | same bits |")
    print("|:---|---:|---:|---:|---:|---:|:---:|")

    def spread(vals):
        rng = f" ({min(vals):.3f}–{max(vals):.3f})" if len(vals) > 1 else ""
        return f"{statistics.median(vals):.3f}" + rng
    for mode in MODES:
        step = ("1" if mode == "optimized" else spread(ratios["gas"]),
                "1" if mode == "optimized" else spread(ratios["fused"]))
        print(f"| {mode} | {med[mode]['small']:.1f} | {med[mode]['gas']:.1f} | "
              f"{med[mode]['fused']:.1f} | {step[0]} | {step[1]} | "
              f"{'yes' if same else 'NO'} |")


if __name__ == "__main__":
    main()
