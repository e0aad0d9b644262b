#!/usr/bin/env python3
"""Paired A/B timing of a tuning field of the engine (taichi_spheres/config.py), in one
process.

Builds two Simulations of the same elastic gas (tools/bench.py's scene: packing 0.3,
periodic cube), the second with ``tuning=config.DEFAULT.with_(NAME=value, ...)``,
compiles and steps both, then
times blocks of --block consecutive steps alternately, A then B then B then A, ...,
so that the drift of a shared machine's speed (+-25 % from minute to minute here)
hits both alike (a block holds whole cycles of full scans and near-list detections,
which single steps would pair against each other). Reports the median of the ratios
B/A per pair of blocks with its quartiles (quartiles on both sides of 1 mean the
difference is within the noise), the ratio of the total times, and whether both runs
made the same collisions (performance fields change speed, not physics).

    python tools/ab_step.py --n 100000 dense_touched=1
    python tools/ab_step.py --n 100000 --shuffle dense_touched=1 prune_walks=False

--shuffle numbers the spheres in random order (the bench's lattice numbers them in
about the grid's cell order, which favours memory locality).
"""
import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("patches", nargs="+", metavar="NAME=value",
                    help="fields of taichi_spheres.config.Tuning to set for run B")
    ap.add_argument("--n", type=int, default=100_000)
    ap.add_argument("--steps", type=int, default=60, help="timed steps per run")
    ap.add_argument("--block", type=int, default=10,
                    help="consecutive steps timed together (a full scan every few steps)")
    ap.add_argument("--precision", default="f64")
    ap.add_argument("--shuffle", action="store_true")
    args = ap.parse_args()

    import taichi as ti
    import taichi_spheres as ts
    from taichi_spheres import runtime
    from taichi_spheres.builders import gas

    from taichi_spheres.config import DEFAULT
    changes = {}
    for item in args.patches:
        name, _, value = item.partition("=")
        if not value:
            ap.error(f"{name}: give a value, as {name}=VALUE")
        try:
            default = getattr(DEFAULT.physics, name, getattr(DEFAULT.performance, name, None))
            changes[name] = (value == "True") if isinstance(default, bool) else \
                type(default)(value) if default is not None else value
            tuning_b = DEFAULT.with_(**changes)
        except ValueError as err:
            ap.error(f"{item}: {err}")

    runtime.ensure("cpu", args.precision)
    scene = gas(args.n)
    if args.shuffle:
        p = np.random.default_rng(1).permutation(args.n)
        scene = ts.Scene.from_arrays(scene.x[p], scene.v[p], scene.radius[p],
                                     box=(scene.box_lo, scene.box_hi), periodic=scene.periodic)
    sims = [ts.Simulation(scene, precision=args.precision, tuning=t) for t in (DEFAULT, tuning_b)]
    for sim in sims:
        for _ in range(5):      # compiles (most of) its kernels
            sim.step(sim.max_step())
    # blocks of consecutive steps, so that each block holds whole cycles of full scans
    # and near-list detections (single steps of A and B would pair a scan with a list)
    times = [[], []]
    for rep in range(max(1, args.steps // args.block)):
        for k in (rep % 2, 1 - rep % 2):
            sim = sims[k]
            ti.sync()
            t0 = time.perf_counter()
            for _ in range(args.block):
                sim.step(sim.max_step())
            ti.sync()
            times[k].append((time.perf_counter() - t0) / args.block)
    a, b = (np.array(t) * 1e3 for t in times)
    q1, med, q3 = np.percentile(b / a, [25, 50, 75])
    same = all(sims[0].stats[k] == sims[1].stats[k] for k in ("pair_collisions", "sweeps"))
    print(f"N={args.n} {args.precision}{' shuffled' if args.shuffle else ''}, B: {' '.join(args.patches)}")
    print(f"A median {np.median(a):.2f} ms/step, B median {np.median(b):.2f} ms/step "
          f"(blocks of {args.block} steps); B/A per pair of blocks: median {med:.3f} "
          f"(quartiles {q1:.3f}-{q3:.3f}), total {b.sum() / a.sum():.3f}; "
          f"same collisions: {same}")


if __name__ == "__main__":
    main()
