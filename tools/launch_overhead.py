#!/usr/bin/env python3
"""Fixed costs of Taichi on this machine, which decide how the step is written:

- one kernel launch: a serial loop and a parallel loop over a small field;
- reading results back to Python: a scalar field read, ``Field.to_numpy`` of a small
  field, a kernel that copies into numpy arrays passed as arguments (what
  ``StepParams.read_back`` does), a kernel returning an i32 (what the detection and
  sweep kernels return);
- atomics from a parallel loop onto a few counters: elements of one small 1-d field
  (they contend between threads) against separate 0-d fields (Taichi reduces those
  per thread; what the step counters of ``params.StepParams`` are).

    python tools/launch_overhead.py [--arch cpu]
"""
import argparse
import time

import numpy as np
import taichi as ti


def per_call_us(fn, reps):
    fn()
    ti.sync()
    t0 = time.perf_counter()
    for _ in range(reps):
        fn()
    ti.sync()
    return (time.perf_counter() - t0) / reps * 1e6


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--arch", default="cpu")
    ap.add_argument("--reps", type=int, default=2000)
    ap.add_argument("--atomic-n", type=int, default=1_000_000,
                    help="loop length of the atomics comparison")
    args = ap.parse_args()
    ti.init(arch=getattr(ti, args.arch), log_level=ti.WARN, default_fp=ti.f32)
    a = ti.field(ti.f32, shape=1000)
    counts = ti.field(ti.i32, shape=8)
    vals = ti.field(ti.f32, shape=8)
    count0 = ti.field(ti.i32, shape=())
    val0 = ti.field(ti.f32, shape=())
    data = ti.field(ti.f32, shape=args.atomic_n)
    data.from_numpy(np.random.default_rng(0).random(args.atomic_n, dtype=np.float32))
    host_counts = np.zeros(8, np.int32)
    host_vals = np.zeros(8, np.float32)

    @ti.kernel
    def serial():
        ti.loop_config(serialize=True)
        for i in range(1000):
            a[i] += 1.0

    @ti.kernel
    def parallel():
        for i in range(1000):
            a[i] += 1.0

    @ti.kernel
    def copy_out(c: ti.types.ndarray(dtype=ti.i32, ndim=1),
                 v: ti.types.ndarray(dtype=ti.f32, ndim=1)):
        for k in ti.static(range(8)):
            c[k] = counts[k]
            v[k] = vals[k]

    @ti.kernel
    def returns_i32() -> ti.i32:
        return counts[0]

    @ti.kernel
    def atomics_1d():
        for i in range(args.atomic_n):
            if data[i] > 0.5:
                ti.atomic_add(counts[1], 1)
                ti.atomic_max(vals[2], data[i])

    @ti.kernel
    def atomics_0d():
        for i in range(args.atomic_n):
            if data[i] > 0.5:
                ti.atomic_add(count0[None], 1)
                ti.atomic_max(val0[None], data[i])

    reps = args.reps
    rows = [
        ("launch: serial loop (1000 elements)", per_call_us(serial, reps)),
        ("launch: parallel loop (1000 elements)", per_call_us(parallel, reps)),
        ("read: one scalar field element", per_call_us(lambda: counts[0], reps)),
        ("read: to_numpy of an 8-element field", per_call_us(counts.to_numpy, reps)),
        ("read: kernel copying 2 x 8 values into numpy arguments",
         per_call_us(lambda: copy_out(host_counts, host_vals), reps)),
        ("read: kernel returning an i32", per_call_us(returns_i32, reps)),
        (f"atomics onto elements of a 1-d field ({args.atomic_n} loop)",
         per_call_us(atomics_1d, 20)),
        (f"atomics onto 0-d fields ({args.atomic_n} loop)", per_call_us(atomics_0d, 20)),
    ]
    for name, us in rows:
        print(f"{name}: {us:.1f} us")


if __name__ == "__main__":
    main()
