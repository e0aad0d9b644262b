#!/usr/bin/env python3
"""Throughput benchmark: elastic gas at packing fraction 0.3 (periodic cube).

Reports sphere-steps per second, collisions per second, the cost of a full step
against a bare grid pass (drift + grid build + neighbour scan, the same kernels the
step uses, timed on the same states), and the effect of compiled-out features.
Writes docs/bench.md (with date, hardware and the command) unless --no-write.

    python tools/bench.py                       # CPU, N = 1e3, 1e4, 1e5, f64 and f32
    python tools/bench.py --arch cuda --sizes 1000000 10000000
"""
from __future__ import annotations

import argparse
import datetime
import os
import platform
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import taichi as ti  # noqa: E402

import taichi_spheres as ts  # noqa: E402
from taichi_spheres.builders import gas  # noqa: E402
from machine import cpu_name, gpu_name  # noqa: E402  (tools/machine.py)


def timed_steps(sim, min_seconds, min_steps):
    """Alternate, on the same states, a bare grid pass (drift + grid build + neighbour
    scan, then the state is put back) and a full step; run until both minima are met.
    Returns (steps, full seconds, bare seconds, collisions)."""
    motion, grid, contacts = sim._motion, sim._grid, sim._contacts
    c0 = sim.stats["pair_collisions"]
    steps, full, bare = 0, 0.0, 0.0
    while True:
        h = sim.max_step()
        st = sim.state()                       # untimed snapshot
        vmax2 = sim._vmax2
        ti.sync()
        t0 = time.perf_counter()
        sim._params.h[None] = h
        motion.drift()
        grid.build()
        contacts.detect_all()
        _ = sim._params.count[0]               # the step reads this too
        ti.sync()
        bare += time.perf_counter() - t0
        sim.set_state(st.x, st.v)              # untimed: back to the same state
        sim._vmax2 = vmax2
        t0 = time.perf_counter()
        sim.step(h)
        ti.sync()
        full += time.perf_counter() - t0
        steps += 1
        if steps >= min_steps and full >= min_seconds:
            break
    return steps, full, bare, sim.stats["pair_collisions"] - c0


def measure(scene, arch, precision, min_seconds, blocks=3):
    """Best of ``blocks`` timed blocks (the least disturbed by other load on a shared
    machine); each block runs at least 10 steps and min_seconds / blocks seconds."""
    t0 = time.perf_counter()
    sim = ts.Simulation(scene, arch=arch, precision=precision)
    for _ in range(3):                      # compile and warm up
        sim.step(sim.max_step())
    compile_s = time.perf_counter() - t0
    best = None
    for _ in range(blocks):
        steps, secs, bare_total, coll = timed_steps(sim, min_seconds / blocks, 10)
        row = dict(steps=steps, seconds=secs, bare=bare_total / steps, coll=coll)
        if best is None or secs / steps < best["seconds"] / best["steps"]:
            best = row
    n = scene.n
    steps, secs, bare, coll = best["steps"], best["seconds"], best["bare"], best["coll"]
    return dict(n=n, precision=precision, steps=steps, seconds=secs,
                sphere_steps=n * steps / secs, collisions=coll / secs,
                step_ms=secs / steps * 1e3, bare_ms=bare * 1e3,
                ratio=(secs / steps) / bare, compile_s=compile_s,
                sweeps=sim.stats["sweeps"] / max(sim.stats["steps"], 1))


def feature_pairs(n):
    """The same scene with its features compiled out (default) and forced in: the
    trajectories are identical, so the difference is the cost of the code alone."""
    base = dict(packing=0.3, seed=0)
    yield "periodic gas: g = 0, equal radii and masses, e = 1", gas(n, periodic=True, **base)
    yield "walled gas: g = 0, equal radii and masses, e = 1", gas(n, periodic=False, **base)


def step_seconds(sim, steps):
    """Mean wall seconds per step over ``steps`` steps."""
    ti.sync()
    t0 = time.perf_counter()
    for _ in range(steps):
        sim.step(sim.max_step())
    ti.sync()
    return (time.perf_counter() - t0) / steps


def compare_features(scene, arch, precision, repeats=5, steps=20):
    """Alternate blocks of steps of the compiled-out and compiled-in builds of one scene
    (same states, so the same work) and keep the best block of each."""
    out = {}
    sims = {flag: ts.Simulation(scene, arch=arch, precision=precision, compile_all=flag)
            for flag in (False, True)}
    for sim in sims.values():
        sim.step(sim.max_step())
    times = {False: float("inf"), True: float("inf")}
    for _ in range(repeats):
        st = sims[False].state()
        for flag, sim in sims.items():
            sim.set_state(st.x, st.v)
            times[flag] = min(times[flag], step_seconds(sim, steps))
    same = np.array_equal(sims[False].state().x, sims[True].state().x)
    for flag in (False, True):
        out[flag] = scene.n / times[flag]
    return out[False], out[True], same


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--arch", default="cpu")
    ap.add_argument("--sizes", type=int, nargs="+", default=[1000, 10000, 100000])
    ap.add_argument("--precisions", nargs="+", default=None)
    ap.add_argument("--feature-n", type=int, default=10000,
                    help="sphere count for the feature comparison (0: skip)")
    ap.add_argument("--seconds", type=float, default=4.5,
                    help="minimum timed seconds per row (split into 3 blocks)")
    ap.add_argument("--out", default=os.path.join("docs", "bench.md"))
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args()
    precisions = args.precisions or (["f32"] if args.arch in ("vulkan", "metal") else ["f64", "f32"])

    rows = []
    for precision in precisions:
        for n in args.sizes:
            r = measure(gas(n, packing=0.3, periodic=True, seed=0), args.arch, precision,
                        args.seconds)
            rows.append(r)
            print(f"N={n:>9} {precision}: {r['sphere_steps']:.3e} sphere-steps/s, "
                  f"{r['collisions']:.3e} collisions/s, step {r['step_ms']:.3f} ms, "
                  f"bare pass {r['bare_ms']:.3f} ms, ratio {r['ratio']:.2f}", flush=True)
    feats = []
    if args.feature_n:
        for label, scene in feature_pairs(args.feature_n):
            off, on, same = compare_features(scene, args.arch, precisions[0])
            feats.append((label, off, on, same))
            print(f"{label}: {off:.3e} compiled out, {on:.3e} compiled in, "
                  f"speed-up {off / on:.2f}, identical states {same}", flush=True)

    rt = ts.Simulation(gas(8, packing=0.01), arch=args.arch, precision=precisions[0]).runtime
    hw = gpu_name() if rt.actual == "cuda" else None
    hardware = f"{hw} (GPU)" if hw else f"{cpu_name()}, {os.cpu_count()} cores"
    cmd = "python tools/bench.py " + " ".join(sys.argv[1:])
    lines = [
        "# Benchmark: elastic hard-sphere gas",
        "",
        f"Generated {datetime.date.today().isoformat()} by `{cmd.strip()}` on {hardware}, "
        f"arch {rt.arch} (Taichi {'.'.join(map(str, ti.__version__))}, {rt.actual}), Python "
        f"{platform.python_version()}.",
        "",
        "Scene: N spheres of radius 0.5 m on a jittered lattice in a periodic cube at packing "
        "fraction 0.3, Gaussian velocities (rms 1 m/s per component), no gravity, e = 1; "
        "default step_fraction 0.1. A *sphere-step* is one sphere advanced by one adaptive "
        "step. *Bare pass* = drift + grid build + neighbour scan (the same kernels, timed on "
        "the same states as the steps); *ratio* = full step / bare pass. Each row is the "
        "best of 3 timed blocks: this is a shared VM whose speed varies by up to ±25 % "
        "from minute to minute.",
        "",
        "| N | precision | sphere-steps/s | collisions/s | ms/step | bare pass ms | ratio | "
        "sweeps/step | compile+warm-up s |",
        "|---:|:---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(f"| {r['n']:,} | {r['precision']} | {r['sphere_steps']:.3g} | "
                     f"{r['collisions']:.3g} | {r['step_ms']:.3f} | {r['bare_ms']:.3f} | "
                     f"{r['ratio']:.2f} | {r['sweeps']:.2f} | {r['compile_s']:.1f} |")
    if feats:
        lines += ["", f"## Compiled-out features (N = {args.feature_n:,}, {precisions[0]})", "",
                  "The same scene run twice: with gravity, per-sphere radius and mass fields "
                  "and restitution compiled out (what the scene needs: `ti.static` flags) "
                  "and with all of them compiled in (`Simulation(..., compile_all=True)`, "
                  "g = 0, equal values, e = 1). Both runs compute identical states; the "
                  "best of 5 blocks of 20 steps is kept for each.", "",
                  "| scene | compiled out, sphere-steps/s | compiled in | speed-up | "
                  "identical states |", "|:---|---:|---:|---:|:---:|"]
        for label, off, on, same in feats:
            lines.append(f"| {label} | {off:.3g} | {on:.3g} | {off / on:.2f} | "
                         f"{'yes' if same else 'no'} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if not args.no_write:
        os.makedirs(os.path.dirname(args.out) or ".", exist_ok=True)
        with open(args.out, "w") as fh:
            fh.write(text)
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
