#!/usr/bin/env python3
"""Cost of one Taichi kernel launch on this machine: a serial loop and a parallel loop
over a small field, each launched many times (the README quotes these).

    python tools/launch_overhead.py [--arch cpu]
"""
import argparse
import time

import taichi as ti


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--arch", default="cpu")
    ap.add_argument("--reps", type=int, default=2000)
    args = ap.parse_args()
    ti.init(arch=getattr(ti, args.arch), log_level=ti.WARN)
    a = ti.field(ti.f32, shape=1000)

    @ti.kernel
    def serial():
        ti.loop_config(serialize=True)
        for i in range(1000):
            a[i] += 1.0

    @ti.kernel
    def parallel():
        for i in range(1000):
            a[i] += 1.0

    for name, kernel in (("serial loop", serial), ("parallel loop", parallel)):
        kernel()
        ti.sync()
        t0 = time.perf_counter()
        for _ in range(args.reps):
            kernel()
        ti.sync()
        print(f"{name}: {(time.perf_counter() - t0) / args.reps * 1e6:.1f} us per launch "
              f"(1000 elements, {args.reps} launches)")


if __name__ == "__main__":
    main()
