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
so that the ratio B / A reads as for throughput). A bed is chaotic: two revisions that
differ in round-off take different steps, and one fill's bed speed moves by 10-20 %
with them. ``--pour-seeds K`` runs K fills instead (the pour's ``seed`` = 1..K), each
timed over its whole bed [1, 2] s, and reports their summed speed, their steps, and
the wall time per step, which separates a costlier step from a trajectory that takes
more steps.

    python tools/ab_revisions.py fd81525 HEAD            # N = 1e5, f64, 3 rounds
    python tools/ab_revisions.py HEAD~1 HEAD --n 10000 --rounds 5
    python tools/ab_revisions.py HEAD~1 HEAD --pour-bed --rounds 5
    python tools/ab_revisions.py HEAD~1 HEAD --pour-bed --pour-seeds 8 --rounds 1
    python tools/ab_revisions.py HEAD~1 HEAD --silo --rounds 2
    python tools/ab_revisions.py HEAD~1 HEAD --silo --interleaved --repeats 10
    python tools/ab_revisions.py HEAD~1 HEAD --silo --interleaved --tuning \
        step_scaled_sweeps=False contact_iterations=60 position_iterations=10
    python tools/ab_revisions.py HEAD~1 HEAD --pour-bed --interleaved --window 0.05
    python tools/ab_revisions.py HEAD~1 HEAD --pour-bed --interleaved --window 0.05 \
        --step-fraction 0.2 --tuning position_iterations=100

With ``--silo`` the measure is the frictional silo of tools/kernel_profile.py --silo
(tools/peer_lammps_silo.py's 1,722 spheres, mu = 0.5, settled, 0.2 s into the
discharge): each revision's run times the same ``--window`` s (default 0.1) of the
discharge ``--repeats`` times from one checkpoint (after an untimed pass), 1 thread,
and reports the fastest wall ms per step. Two revisions that keep the same bits run the
same steps, so the ratio of ms per step is the ratio of their costs.

With ``--interleaved`` (and ``--silo`` or ``--pour-bed``) both revisions run in one
process on one Taichi runtime: each revision's package is imported from its worktree
under a name of its own, with this checkout's tools/silo.py bound to it (the silo's
settings, its --tuning names and scenes/pour.toml are this checkout's too). Both start
from the same state (the silo's fill settled by revision A, 0.2 s into its discharge;
the pour at 1 s), and their windows of ``--window`` s alternate ``--repeats`` times,
A B, then B A, each from its revision's checkpoint: a shared machine whose speed
drifts from minute to minute slows both alike, where separate processes a minute
apart can differ by 30 %. Reported: per revision the fastest and the median window,
and the median of the per-pair ratios B / A (``--rounds``, ``--n`` and
``--precision`` do not apply). ``--tuning`` gives both runs Tuning.with_ keywords
(the silo's through tools/silo.py), ``--step-fraction`` the pour's step bound.
"""
from __future__ import annotations

import argparse
import contextlib
import math
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, ".."))
sys.path.insert(0, ROOT)
sys.path.insert(0, HERE)

from machine import step_fraction_arg, tuning_args  # noqa: E402  (tools/machine.py)


def checkout(rev: str, where: str) -> str:
    """A detached worktree of ``rev`` under ``where``; returns its path."""
    path = os.path.join(where, re.sub(r"[^A-Za-z0-9]", "_", rev))
    subprocess.run(["git", "-C", ROOT, "worktree", "add", "--detach", "-f", path, rev],
                   check=True, capture_output=True)
    return path


@contextlib.contextmanager
def worktrees(*revs):
    """{rev: path} of a detached worktree per revision, removed (with their temporary
    folder) when the block ends, whatever ends it."""
    where = tempfile.mkdtemp(prefix="ab_revisions_")
    trees = {}
    try:
        for rev in revs:
            trees[rev] = checkout(rev, where)
        yield trees
    finally:
        for tree in trees.values():
            subprocess.run(["git", "-C", ROOT, "worktree", "remove", "--force", tree],
                           capture_output=True)
        shutil.rmtree(where, ignore_errors=True)


def throughput(tree: str, n: int, precision: str) -> float:
    """sphere-steps/s of one row of the bench of the revision checked out in ``tree``."""
    out = subprocess.run([sys.executable, "tools/bench.py", "--sizes", str(n), "--precisions",
                          precision, "--feature-n", "0", "--no-write"],
                         capture_output=True, text=True, check=True, cwd=tree)
    match = re.search(r"N=\s*%d %s: ([0-9.e+]+) sphere-steps/s" % (n, precision), out.stdout)
    if not match:
        raise RuntimeError(f"no throughput line in bench.py's output:\n{out.stdout[-2000:]}")
    return float(match.group(1))


#: --pour-bed: run in a revision's worktree (its package is the one imported);
#: argv: t_start t_end seed... (no seed: scenes/pour.toml as it is)
POUR_BED = """
import re, sys, tempfile, time, taichi_spheres as ts
t_start, t_end = float(sys.argv[1]), float(sys.argv[2])
text = open("scenes/pour.toml").read()
wall = steps = 0.0
for seed in sys.argv[3:] or [None]:
    filled, found = (text, 1) if seed is None else \
        re.subn(r"(?m)^seed = [0-9]+$", "seed = " + seed, text)
    if found != 1:
        sys.exit("scenes/pour.toml has no single 'seed = N' line to vary")
    with tempfile.NamedTemporaryFile("w", suffix=".toml") as f:
        f.write(filled)
        f.flush()
        sim = ts.Simulation(ts.load_scene(f.name), threads=1)
    sim.advance_to(t_start)
    s0, t0 = sim.stats["steps"], time.perf_counter()
    sim.advance_to(t_end)
    wall += time.perf_counter() - t0
    steps += sim.stats["steps"] - s0
runs = max(len(sys.argv) - 3, 1)
print("bed", runs * (t_end - t_start) / wall, int(steps), wall / steps)
"""


#: --silo: run in a revision's worktree; argv: window [s], repeats
SILO = """
import sys, time
sys.path.insert(0, "tools")
import kernel_profile
from machine import untimed_pass
window, repeats = float(sys.argv[1]), int(sys.argv[2])
sim = kernel_profile.silo_simulation()
untimed_pass(sim, lambda s: s.advance(window))
start = sim.checkpoint()
times = []
for _ in range(repeats):
    sim.restore(start)
    s0, t0 = sim.stats["steps"], time.perf_counter()
    sim.advance(window)
    times.append((time.perf_counter() - t0) / (sim.stats["steps"] - s0))
print("silo", min(times), sim.stats["steps"] - s0)
print("windows", *times)
"""


#: --interleaved: run in this checkout; argv: the two worktrees, "silo" or "pour",
#: window [s], repeats, the pour's step_fraction ("none": the default), then the silo's
#: --tuning items (tools/silo.py's) or the pour's Tuning.with_ keywords as one Python
#: literal (machine.tuning_args's dict)
INTERLEAVED = """
import ast, importlib.util, sys, time
sys.path.insert(0, "tools")
tree_a, tree_b, what = sys.argv[1:4]
window, repeats = float(sys.argv[4]), int(sys.argv[5])
fraction, tuning = sys.argv[6], sys.argv[7:]

def load(path, name, folder=None):
    # the module file ``path`` as ``name`` (``folder``: a package's, for its submodules)
    spec = importlib.util.spec_from_file_location(
        name, path, submodule_search_locations=None if folder is None else [folder])
    module = importlib.util.module_from_spec(spec)
    if folder is not None:
        sys.modules[name] = module
    spec.loader.exec_module(module)
    return module

def package(tree, name):
    # the package of a worktree as ``name``; the tools' silo.py bound to it
    folder = tree + "/taichi_spheres"
    ts = load(folder + "/__init__.py", name, folder)
    saved = {k: v for k, v in sys.modules.items() if k == "taichi_spheres" or
             k.startswith("taichi_spheres.")}
    for k in list(saved):
        del sys.modules[k]
    sys.modules["taichi_spheres"] = ts
    sys.modules["taichi_spheres.config"] = ts.config
    silo = load("tools/silo.py", "silo_" + name)
    for k in ("taichi_spheres", "taichi_spheres.config"):
        del sys.modules[k]
    sys.modules.update(saved)
    return ts, silo

ts_a, silo_a = package(tree_a, "revision_a")
ts_b, silo_b = package(tree_b, "revision_b")
import peer_lammps_silo
from machine import untimed_pass
rt = ts_a.runtime.ensure("cpu", "f64", threads=1)
ts_b.runtime._current, ts_b.runtime._generation = rt, ts_a.runtime._generation
if what == "silo":
    a = peer_lammps_silo.settings(["--tuning", *tuning] if tuning else [])
    settled = silo_a.settled_fill(a, a.fill, seed=1)
    sims = [silo.discharging(a, settled, a.orifice * a.radius) for silo in (silo_a, silo_b)]
    start = 0.2
else:
    changes = ast.literal_eval(tuning[0])
    extra = {} if fraction == "none" else {"step_fraction": float(fraction)}
    sims = [ts.Simulation(ts.load_scene("scenes/pour.toml"), threads=1,
                          tuning=ts.config.Tuning().with_(**changes), **extra)
            for ts in (ts_a, ts_b)]
    start = 1.0
starts = []
for sim in sims:
    sim.advance(start)
    untimed_pass(sim, lambda s: s.advance(window))
    starts.append(sim.checkpoint())
assert ts_a.runtime._current is rt and ts_b.runtime._current is rt, "Taichi re-initialised"
times, steps = [[], []], [0, 0]
for r in range(repeats):
    for k in ((0, 1) if r % 2 == 0 else (1, 0)):     # A B, B A, ...: neither always first
        sims[k].restore(starts[k])
        s0, t0 = sims[k].stats["steps"], time.perf_counter()
        sims[k].advance(window)
        steps[k] = sims[k].stats["steps"] - s0
        times[k].append((time.perf_counter() - t0) / steps[k])
print("steps", *steps)
for k in range(2):
    print("windows", *times[k])
"""


def interleaved(trees: tuple, what: str, window: float, repeats: int, tuning=(),
                step_fraction=None) -> tuple:
    """([A's wall s per step per window], [B's], (A's steps, B's)) of ``window`` s of
    the silo's discharge (``what`` "silo") or the pour's bed ("pour"), both revisions'
    windows alternating in one process (``tuning``: the silo's --tuning items,
    tools/silo.py's, or the pour's Tuning.with_ keywords, a dict; ``step_fraction``:
    the pour's, None for the default)."""
    fraction = "none" if step_fraction is None else repr(step_fraction)
    tail = [repr(dict(tuning))] if what == "pour" else list(tuning)
    out = subprocess.run([sys.executable, "-c", INTERLEAVED, *trees, what, str(window),
                          str(repeats), fraction, *tail], capture_output=True, text=True,
                         cwd=ROOT)
    if out.returncode != 0:
        raise RuntimeError(f"the interleaved run failed:\n{out.stderr[-3000:]}")
    steps = re.search(r"^steps ([0-9]+) ([0-9]+)$", out.stdout, re.M)
    windows = re.findall(r"^windows (.*)$", out.stdout, re.M)
    if not steps or len(windows) != 2:
        raise RuntimeError(f"no steps and windows in the run's output:\n{out.stdout[-2000:]}")
    a, b = ([float(w) for w in line.split()] for line in windows)
    return a, b, (int(steps.group(1)), int(steps.group(2)))


def interleaved_main(args) -> int:
    """--interleaved: both revisions in one process, windows alternating."""
    a_rev, b_rev = args.rev_a, args.rev_b
    with worktrees(a_rev, b_rev) as trees:
        a, b, steps = interleaved((trees[a_rev], trees[b_rev]),
                                  "silo" if args.silo else "pour", args.window,
                                  args.repeats, args.tuning, args.step_fraction)
    for rev, times in ((a_rev, a), (b_rev, b)):
        print(f"{rev}: fastest {1e3 * min(times):.2f}, median "
              f"{1e3 * statistics.median(times):.2f} ms per step ("
              + " ".join(f"{1e3 * t:.2f}" for t in times) + ")")
    if steps[0] != steps[1]:
        print(f"warning: the revisions ran different steps ({steps}): they do not keep "
              "the same bits, so the ratio mixes cost per step with trajectory")
    ratios = [y / x for x, y in zip(a, b)]
    print(f"{b_rev} / {a_rev}: wall per step, pairs of windows: median "
          f"{statistics.median(ratios):.3f} (range {min(ratios):.3f}-{max(ratios):.3f}); "
          f"fastest {min(b) / min(a):.3f} ({steps[0]} steps per window; < 1: {b_rev} "
          "is faster)")
    return 0


def silo_cost(tree: str, window: float, repeats: int) -> tuple:
    """(fastest wall s per step, steps) of ``window`` s of the silo's discharge with the
    package of the revision checked out in ``tree``."""
    out = subprocess.run([sys.executable, "-c", SILO, str(window), str(repeats)],
                         capture_output=True, text=True, check=True, cwd=tree)
    match = re.search(r"^silo ([0-9.e+-]+) ([0-9]+)$", out.stdout, re.M)
    if not match:
        raise RuntimeError(f"no silo line in the run's output:\n{out.stdout[-2000:]}")
    windows = re.search(r"^windows (.*)$", out.stdout, re.M).group(1).split()
    print("  windows [ms per step]: " + " ".join(f"{1e3 * float(w):.2f}" for w in windows))
    return float(match.group(1)), int(match.group(2))


def bed_speed(tree: str, seeds: int = 0) -> tuple:
    """(simulated s per wall s, steps, wall s per step) of the pour's bed with the
    package of the revision checked out in ``tree``: [1, 1.5] s of scenes/pour.toml,
    or with ``seeds`` > 0 the beds [1, 2] s of that many fills (seed 1..seeds), summed."""
    span = ["1.0", "2.0"] if seeds else ["1.0", "1.5"]
    out = subprocess.run([sys.executable, "-c", POUR_BED, *span,
                          *[str(k) for k in range(1, seeds + 1)]],
                         capture_output=True, text=True, check=True, cwd=tree)
    match = re.search(r"^bed ([0-9.e+-]+) ([0-9]+) ([0-9.e+-]+)$", out.stdout, re.M)
    if not match:
        raise RuntimeError(f"no bed line in the run's output:\n{out.stdout[-2000:]}")
    return float(match.group(1)), int(match.group(2)), float(match.group(3))


def report(args, runs, beds, unit) -> None:
    """Print the medians per revision and of the per-round ratios B / A (with --pour-bed
    also the ratios of steps and of wall time per step)."""
    a, b = args.rev_a, args.rev_b
    for rev in (a, b):
        what = "" if args.pour_bed else f"N = {args.n:,}, {args.precision}, "
        print(f"{rev}: median {statistics.median(runs[rev]):.3e} {unit} "
              f"({what}{args.rounds} runs)")
    ratios = [y / x for x, y in zip(runs[a], runs[b])]
    print(f"{b} / {a}: median {statistics.median(ratios):.3f} "
          f"(range {min(ratios):.3f}-{max(ratios):.3f})")
    if args.pour_bed:
        steps = [y[1] / x[1] for x, y in zip(beds[a], beds[b])]
        per_step = [y[2] / x[2] for x, y in zip(beds[a], beds[b])]
        print(f"{b} / {a}: steps median {statistics.median(steps):.3f}, wall per step "
              f"median {statistics.median(per_step):.3f} "
              f"(range {min(per_step):.3f}-{max(per_step):.3f})")


def silo_main(args) -> int:
    """--silo: alternate the two revisions' silo runs; print ms per step and the
    per-round ratios B / A."""
    runs, steps = {args.rev_a: [], args.rev_b: []}, {}
    with worktrees(args.rev_a, args.rev_b) as trees:
        for k in range(args.rounds):
            for rev in (args.rev_a, args.rev_b):
                per_step, steps[rev] = silo_cost(trees[rev], args.window, args.repeats)
                runs[rev].append(per_step)
                print(f"round {k + 1} {rev}: {per_step * 1e3:.2f} ms per step "
                      f"(fastest of {args.repeats}, {steps[rev]} steps)", flush=True)
    a, b = args.rev_a, args.rev_b
    if len({s for s in steps.values()}) > 1:
        print(f"warning: the revisions ran different steps ({steps}): they do not keep "
              "the same bits, so the ratio mixes cost per step with trajectory")
    ratios = [y / x for x, y in zip(runs[a], runs[b])]
    print(f"{b} / {a}: wall per step median {statistics.median(ratios):.3f} "
          f"(range {min(ratios):.3f}-{max(ratios):.3f}; < 1: {b} is faster)")
    return 0


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("rev_a")
    p.add_argument("rev_b")
    p.add_argument("--n", type=int, default=100_000)
    p.add_argument("--precision", default="f64", choices=["f64", "f32"])
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--pour-bed", action="store_true",
                   help="measure the pour's bed (simulated s per wall s) instead")
    p.add_argument("--pour-seeds", type=int, default=0, metavar="K",
                   help="with --pour-bed: K fills (seed 1..K), each over [1, 2] s")
    p.add_argument("--silo", action="store_true",
                   help="measure the frictional silo's discharge (wall ms per step)")
    p.add_argument("--window", type=float, default=None,
                   help="with --silo or --interleaved: seconds timed (default 0.1)")
    p.add_argument("--repeats", type=int, default=None,
                   help="with --silo or --interleaved: timed windows (default 5)")
    p.add_argument("--interleaved", action="store_true",
                   help="with --silo or --pour-bed: both revisions in one process, "
                        "windows alternating")
    p.add_argument("--tuning", nargs="+", default=[], metavar="NAME=VALUE",
                   help="with --interleaved: Tuning.with_ keywords of both runs "
                        "(the silo's tools/silo.py items, or the pour's)")
    p.add_argument("--step-fraction", type=float, default=None,
                   help="with --pour-bed --interleaved: the pour's step_fraction")
    args = p.parse_args(argv)
    if args.pour_seeds < 0 or (args.pour_seeds and not args.pour_bed):
        p.error("--pour-seeds takes a count >= 0 and needs --pour-bed")
    if args.silo and args.pour_bed:
        p.error("give --silo or --pour-bed, not both")
    if args.interleaved and not (args.silo or args.pour_bed) or args.pour_seeds and \
            args.interleaved:
        p.error("--interleaved needs --silo or --pour-bed (without --pour-seeds)")
    if not (args.silo or args.interleaved) and (args.window is not None or
                                                args.repeats is not None):
        p.error("--window and --repeats need --silo or --interleaved")
    if args.tuning and not args.interleaved:
        p.error("--tuning needs --interleaved")
    if args.step_fraction is not None and not (args.interleaved and args.pour_bed):
        p.error("--step-fraction needs --pour-bed --interleaved")
    step_fraction_arg(args.step_fraction, p)
    if args.pour_bed:       # keywords, or an error naming a bad item, before the runs
        args.tuning = tuning_args(args.tuning, p)
    if args.silo or args.interleaved:
        args.window = 0.1 if args.window is None else args.window
        args.repeats = 5 if args.repeats is None else args.repeats
        if not (math.isfinite(args.window) and args.window > 0) or args.repeats < 1:
            p.error("--window takes seconds > 0 and --repeats a count >= 1")
        return interleaved_main(args) if args.interleaved else silo_main(args)
    unit = "simulated s per wall s (pour bed, 1 thread)" if args.pour_bed else \
        "sphere-steps/s"
    with worktrees(args.rev_a, args.rev_b) as trees:
        runs = {args.rev_a: [], args.rev_b: []}
        beds = {args.rev_a: [], args.rev_b: []}
        for k in range(args.rounds):
            for rev in (args.rev_a, args.rev_b):
                if args.pour_bed:
                    beds[rev].append(bed_speed(trees[rev], args.pour_seeds))
                    speed, steps, per_step = beds[rev][-1]
                    runs[rev].append(speed)
                    print(f"round {k + 1} {rev}: {speed:.3e} {unit}, {steps} steps, "
                          f"{per_step * 1e3:.2f} ms per step", flush=True)
                else:
                    runs[rev].append(throughput(trees[rev], args.n, args.precision))
                    print(f"round {k + 1} {rev}: {runs[rev][-1]:.3e} {unit}", flush=True)
        report(args, runs, beds, unit)
    return 0


if __name__ == "__main__":
    sys.exit(main())
