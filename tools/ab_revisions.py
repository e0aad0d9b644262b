#!/usr/bin/env python3
"""Throughput of two git revisions of the engine, measured alternately on one machine.

Checks each revision out into a temporary git worktree and runs that revision's
``tools/bench.py`` there (``--sizes N --precisions P --feature-n 0 --no-write``),
revision A then B then A ..., ``--rounds`` times, and reports sphere-steps/s per run, the median per revision and the median of
the per-round ratios B / A. Alternating spreads the drift of a shared machine over
both revisions; a ratio within the spread of the rounds is noise.

With ``--pour-bed`` the measure is instead the pour's settled bed: each revision's
package (imported from its worktree) runs scenes/pour.toml to 1 s untimed, then 0.5 s
timed, on 1 thread; reported in simulated seconds per wall second (higher is faster,
so that the ratio B / A reads as for throughput).

    python tools/ab_revisions.py fd81525 HEAD            # N = 1e5, f64, 3 rounds
    python tools/ab_revisions.py HEAD~1 HEAD --n 10000 --rounds 5
    python tools/ab_revisions.py HEAD~1 HEAD --pour-bed --rounds 5
"""
from __future__ import annotations

import argparse
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, ".."))


def checkout(rev: str, where: str) -> str:
    """A detached worktree of ``rev`` under ``where``; returns its path."""
    path = os.path.join(where, re.sub(r"[^A-Za-z0-9]", "_", rev))
    subprocess.run(["git", "-C", ROOT, "worktree", "add", "--detach", "-f", path, rev],
                   check=True, capture_output=True)
    return path


def throughput(tree: str, n: int, precision: str) -> float:
    """sphere-steps/s of one row of the bench of the revision checked out in ``tree``."""
    out = subprocess.run([sys.executable, "tools/bench.py", "--sizes", str(n), "--precisions",
                          precision, "--feature-n", "0", "--no-write"],
                         capture_output=True, text=True, check=True, cwd=tree)
    match = re.search(r"N=\s*%d %s: ([0-9.e+]+) sphere-steps/s" % (n, precision), out.stdout)
    if not match:
        raise RuntimeError(f"no throughput line in bench.py's output:\n{out.stdout[-2000:]}")
    return float(match.group(1))


#: --pour-bed: run in a revision's worktree (its package is the one imported)
POUR_BED = """
import time, taichi_spheres as ts
sim = ts.Simulation(ts.load_scene("scenes/pour.toml"), threads=1)
sim.advance_to(1.0)
t0 = time.perf_counter()
sim.advance_to(1.5)
print("bed", 0.5 / (time.perf_counter() - t0), sim.stats["steps"])
"""


def bed_speed(tree: str) -> float:
    """Simulated s per wall s of the pour's bed, [1, 1.5] s, with the package of the
    revision checked out in ``tree``."""
    out = subprocess.run([sys.executable, "-c", POUR_BED], capture_output=True, text=True,
                         check=True, cwd=tree)
    match = re.search(r"^bed ([0-9.e+-]+) ", out.stdout, re.M)
    if not match:
        raise RuntimeError(f"no bed line in the run's output:\n{out.stdout[-2000:]}")
    return float(match.group(1))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("rev_a")
    p.add_argument("rev_b")
    p.add_argument("--n", type=int, default=100_000)
    p.add_argument("--precision", default="f64", choices=["f64", "f32"])
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--pour-bed", action="store_true",
                   help="measure the pour's bed (simulated s per wall s) instead")
    args = p.parse_args(argv)
    unit = "simulated s per wall s (pour bed, 1 thread)" if args.pour_bed else \
        "sphere-steps/s"
    where = tempfile.mkdtemp(prefix="ab_revisions_")
    trees = {}
    try:
        for rev in (args.rev_a, args.rev_b):
            trees[rev] = checkout(rev, where)
        runs = {args.rev_a: [], args.rev_b: []}
        for k in range(args.rounds):
            for rev in (args.rev_a, args.rev_b):
                runs[rev].append(bed_speed(trees[rev]) if args.pour_bed else
                                 throughput(trees[rev], args.n, args.precision))
                print(f"round {k + 1} {rev}: {runs[rev][-1]:.3e} {unit}", flush=True)
        ratios = [b / a for a, b in zip(runs[args.rev_a], runs[args.rev_b])]
        for rev in (args.rev_a, args.rev_b):
            what = "" if args.pour_bed else f"N = {args.n:,}, {args.precision}, "
            print(f"{rev}: median {statistics.median(runs[rev]):.3e} {unit} "
                  f"({what}{args.rounds} runs)")
        print(f"{args.rev_b} / {args.rev_a}: median {statistics.median(ratios):.3f} "
              f"(range {min(ratios):.3f}-{max(ratios):.3f})")
    finally:
        for tree in trees.values():
            subprocess.run(["git", "-C", ROOT, "worktree", "remove", "--force", tree],
                           capture_output=True)
        shutil.rmtree(where, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
