#!/usr/bin/env python3
"""What the frontend memos (taichi_spheres/frontend.py) save in a scene's first run.

Each run is a fresh process that loads a scene, builds its Simulation and advances one
step: Taichi turns every kernel's Python into IR (the frontend), then compiles it or,
when its offline cache holds the kernel, loads it. Runs use an offline cache directory
of their own: "cold" starts from an empty one (a first run on a machine, and every
engine variant the test suite compiles), "warm" repeats the run on the cache the cold
run filled. With the memos ("on") and without them (TAICHI_SPHERES_FRONTEND_MEMO=off),
alternated, --repeat times; the median wall seconds of each, 1 thread.

    python tools/compile_frontend.py                 # ~8 min on an idle 2-core machine
    python tools/compile_frontend.py --write         # the 'compile-frontend' section of docs/bench.md
"""
from __future__ import annotations

import argparse
import datetime
import os
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.join(HERE, "..")
sys.path.insert(0, HERE)

from machine import cpu_name, kernel_cache_env, publish  # noqa: E402  (tools/machine.py)

SCENES = ("scenes/pour.toml", "scenes/silo.toml")
CHILD = """
import sys, time
sys.path.insert(0, {root!r})
import taichi_spheres as ts
from taichi_spheres.config import Tuning
t0 = time.perf_counter()
sim = ts.Simulation(ts.load_scene({scene!r}), threads=1)
sim.advance(sim.max_step())
t1 = time.perf_counter()
other = ts.Simulation(ts.load_scene({scene!r}), threads=1,
                      tuning=Tuning().with_(projection_iterations=7))
other.advance(other.max_step())
print(t1 - t0, time.perf_counter() - t1)
"""


def first_run(scene: str, mode: str, memo: bool, cache: str) -> tuple:
    """Wall seconds of a fresh process's first step of ``scene`` (compile mode
    ``mode``, the memos on or off) with Taichi's offline cache in directory ``cache``,
    and of the first step of a second engine variant in that process (another sweep
    cap: the same kernels, compiled again)."""
    env = kernel_cache_env(cache, TAICHI_SPHERES_FRONTEND_MEMO="on" if memo else "off",
                           TAICHI_SPHERES_COMPILE=mode)
    code = CHILD.format(root=ROOT, scene=os.path.join(ROOT, scene))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, check=True)
    first, second = out.stdout.strip().splitlines()[-1].split()
    return float(first), float(second)


def measure(scene: str, mode: str, repeat: int) -> dict:
    """Median seconds of cold and warm first runs and of their second variants, with
    the memos on and off."""
    times = {(memo, state): [] for memo in (True, False)
             for state in ("cold", "warm", "cold, 2nd variant", "warm, 2nd variant")}
    for r in range(repeat):
        for memo in ((True, False) if r % 2 == 0 else (False, True)):
            with tempfile.TemporaryDirectory() as cache:
                for state in ("cold", "warm"):
                    first, second = first_run(scene, mode, memo, cache)
                    times[memo, state].append(first)
                    times[memo, state + ", 2nd variant"].append(second)
    return {key: sorted(t)[len(t) // 2] for key, t in times.items()}


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scenes", nargs="+", default=list(SCENES))
    p.add_argument("--compile", nargs="+", default=["optimized", "fast"],
                   choices=["optimized", "fast"])
    p.add_argument("--repeat", type=int, default=1)
    p.add_argument("--write", action="store_true")
    a = p.parse_args(argv)
    t0 = time.perf_counter()
    lines = ["## Compile frontend: Taichi's source lookups remembered", "",
             f"Measured {datetime.date.today()} on {cpu_name()}, 1 thread: "
             f"`python tools/compile_frontend.py {' '.join(x for x in argv if x != '--write')}`"
             .rstrip(), "",
             f"A fresh process's first step (compile and run), median of {a.repeat}, "
             "memos on and off alternated; cold: empty offline cache, warm: the cache the "
             "cold run filled; 2nd variant: then, in the same process, a Simulation of the same "
             "scene with another compiled-in option (projection_iterations = 7, which a "
             "scene with a contact solver does not use: the same kernels compiled again, as "
             "the test suite and sweeps over compiled-in options do).", "",
             "| scene | compile mode | cache | without memos [s] | with memos [s] | saved |",
             "|---|---|---|---|---|---|"]
    for scene in a.scenes:
        for mode in a.compile:
            m = measure(scene, mode, a.repeat)
            for state in ("cold", "warm", "cold, 2nd variant", "warm, 2nd variant"):
                off, on = m[False, state], m[True, state]
                lines.append(f"| {scene} | {mode} | {state} | {off:.1f} | {on:.1f} | "
                             f"{1 - on / off:.0%} |")
                print(lines[-1], flush=True)
    print(f"({time.perf_counter() - t0:.0f} s)")
    publish("\n".join(lines), "compile-frontend", a.write)


if __name__ == "__main__":
    main()
