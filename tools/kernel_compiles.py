#!/usr/bin/env python3
"""What a scene's first step costs to compile, revision against revision.

Each run is a fresh process with an empty Taichi offline cache (a first run on a
machine, CI, and every engine kind the test suite builds) that loads a scene, builds
its Simulation and advances it by one step bound (``max_step``): its wall seconds, and
the seconds each kernel's compile took (the AST pass and its first launch, from
tools/engine_census_plugin.py). Each revision is checked out into a temporary git
worktree (tools/ab_revisions.py) and its package imported from there; runs alternate
between the revisions, --repeats times, and the medians are reported. 1 thread.

    python tools/kernel_compiles.py 43288f9 HEAD --scenes scenes/pour.toml scenes/silo.toml
    python tools/kernel_compiles.py 43288f9 HEAD --write    # docs/bench.md 'kernel-compiles'
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import statistics
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

from ab_revisions import worktrees  # noqa: E402
from machine import cpu_name, kernel_cache_env, publish  # noqa: E402

SCENES = ("scenes/pour.toml", "scenes/silo.toml", "scenes/gas.toml")
#: the child: a revision's package (its worktree first on sys.path), this checkout's
#: compile logger; prints one JSON line
CHILD = """
import json, sys, time
sys.path.insert(0, {tree!r})
sys.path.insert(1, {tools!r})
import taichi_spheres as ts
assert ts.__file__.startswith({tree!r}), ts.__file__
from engine_census_plugin import log_kernel_compiles
seconds = log_kernel_compiles()
t0 = time.perf_counter()
sim = ts.Simulation(ts.load_scene({scene!r}), threads=1)
sim.advance(sim.max_step())
wall = time.perf_counter() - t0
print(json.dumps(dict(wall=wall, kernels={{k: v[0] + v[1] for k, v in seconds.items()}})))
"""


def first_step(tree: str, scene: str, mode: str) -> dict:
    """{wall: s, kernels: {name: s}} of a fresh process's first step of ``scene`` with
    the package of worktree ``tree``, compile mode ``mode``, an empty kernel cache."""
    with tempfile.TemporaryDirectory() as cache:
        env = kernel_cache_env(cache, TAICHI_SPHERES_COMPILE=mode)
        code = CHILD.format(tree=tree, tools=HERE, scene=os.path.join(tree, scene))
        out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                             text=True, cwd=tree)
    if out.returncode != 0:
        raise RuntimeError(f"{scene} in {tree} failed:\n{out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def labelled(rev: str) -> str:
    """``rev`` with its short commit hash where it names one by another name (HEAD)."""
    out = subprocess.run(["git", "-C", HERE, "rev-parse", "--short", rev],
                         capture_output=True, text=True)
    short = out.stdout.strip()
    return rev if not short or rev.startswith(short) else f"{rev} ({short})"


def medians(runs: list) -> dict:
    """The median wall seconds and per-kernel seconds of ``runs``."""
    names = {name for run in runs for name in run["kernels"]}
    return dict(wall=statistics.median(run["wall"] for run in runs),
                kernels={name: statistics.median(run["kernels"].get(name, 0.0) for run in runs)
                         for name in names})


def table(revs, scene, mode, results, top) -> list:
    """Markdown rows of one scene and mode: the first step, all kernels, then the
    ``top`` kernels that took longest in either revision."""
    a, b = (results[rev] for rev in revs)
    rows = [f"| {scene} | {mode} | first step (build + advance) | {a['wall']:.2f} | "
            f"{b['wall']:.2f} | {b['wall'] / a['wall']:.2f} |",
            f"| | | all kernels' compiles | {sum(a['kernels'].values()):.2f} | "
            f"{sum(b['kernels'].values()):.2f} | "
            f"{sum(b['kernels'].values()) / sum(a['kernels'].values()):.2f} |"]
    names = sorted(set(a["kernels"]) | set(b["kernels"]),
                   key=lambda n: -max(a["kernels"].get(n, 0), b["kernels"].get(n, 0)))
    for name in names[:top]:
        sa, sb = a["kernels"].get(name, 0.0), b["kernels"].get(name, 0.0)
        ratio = f"{sb / sa:.2f}" if sa > 0 else "new"
        rows.append(f"| | | {name} | {sa:.2f} | {sb:.2f} | {ratio} |")
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("rev_a")
    ap.add_argument("rev_b")
    ap.add_argument("--scenes", nargs="+", default=list(SCENES))
    ap.add_argument("--modes", nargs="+", default=["fast"], choices=["fast", "optimized"])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--top", type=int, default=6, help="kernels listed per scene")
    ap.add_argument("--write", action="store_true",
                    help="write the result into docs/bench.md ('kernel-compiles')")
    args = ap.parse_args(argv)
    revs = (args.rev_a, args.rev_b)
    shown = {rev: labelled(rev) for rev in revs}
    lines = []
    with worktrees(*revs) as trees:
        for scene in args.scenes:
            for mode in args.modes:
                runs = {rev: [] for rev in revs}
                for _ in range(args.repeats):
                    for rev in revs:
                        runs[rev].append(first_step(trees[rev], scene, mode))
                lines += table(revs, scene, mode, {rev: medians(runs[rev]) for rev in revs},
                               args.top)
    cmd = " ".join(["python tools/kernel_compiles.py", *revs, "--scenes", *args.scenes,
                    "--modes", *args.modes, "--repeats", str(args.repeats)]
                   + (["--write"] if args.write else []))
    text = f"""## Kernel compiles of a scene's first step, revision against revision

{datetime.date.today().isoformat()}, {cpu_name()}, 1 thread: `{cmd}`.

A fresh process per run with an empty Taichi kernel cache: build the scene's Simulation
and advance it by one step bound; median of {args.repeats} runs per revision, alternated.
Kernel seconds: the AST pass and the first launch (LLVM's compile and one run) of each
kernel, summed over its instances (tools/engine_census_plugin.py).

| scene | compile mode | what | {shown[revs[0]]} [s] | {shown[revs[1]]} [s] | ratio |
|---|---|---|---|---|---|
""" + "\n".join(lines) + "\n"
    publish(text, "kernel-compiles", args.write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
