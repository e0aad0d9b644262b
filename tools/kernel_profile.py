#!/usr/bin/env python3
"""Where a step's time goes: Taichi's kernel profiler over a window of a run, 1 thread.

The runs (``--gas N``, the gas of tools/bench.py, is the fourth):

- ``--scene TOML --at T``: the scene file, advanced to T s (untimed), then the window;
- ``--silo``: the silo of tools/peer_lammps_silo.py (1,722 spheres of d = 6 mm, mu =
  0.5, orifice 5 d), its fill settled 0.3 s with the orifice closed, then discharging:
  the window starts 0.2 s into the discharge;
- ``--silo-large N``: the silo of tools/silo_large.py with N spheres, on cpu or cuda; the
  window starts 0.01 s into the discharge from the lattice fill.

The window (``--window`` s) runs twice from a checkpoint, the first time untimed (so
that no kernel compiles in the second). Reported: steps, wall ms per step (profiler
on), contact rows and sweeps per step, and each kernel's share of the kernel time with
its mean ms per launch. Taichi names a kernel's tasks ``<kernel>_c<n>_<k>_kernel_<task>``:
``solve_serial`` is the contact solver of the serial engines (Taichi merges its
consecutive serial loops: task 0 searches for the rows, task 2 places them and holds
the warm start, the velocity and position sweeps and the rest; with ``--stages`` each
stage is a kernel of its own, ``solve_<stage>``: contacts/solver.py SOLVE_STAGES),
``sweep`` one parallel sweep, ``detect_*`` and ``build`` the grid and detection, ``drift`` the
flight.

    python tools/kernel_profile.py --scene scenes/pour.toml --at 1.0 --window 0.2
    python tools/kernel_profile.py --scene scenes/pour.toml --at 1.5 --window 0.2 --stages \
        --step-fraction 0.2 --tuning position_iterations=100
    python tools/kernel_profile.py --silo --write
    python tools/kernel_profile.py --silo --stages --write   # the serial solve's stages
    python tools/kernel_profile.py --silo --tuning step_scaled_sweeps=False contact_iterations=60
    python tools/kernel_profile.py --gas 10000 --arch cuda --window 0.02 --host
    python tools/kernel_profile.py --silo-large 100000 --arch cuda --window 0.01
"""
from __future__ import annotations

import argparse
import datetime
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, HERE)

import taichi as ti  # noqa: E402
from taichi.profiler.kernel_profiler import get_default_kernel_profiler  # noqa: E402

import taichi_spheres as ts  # noqa: E402
from taichi_spheres.config import DEFAULT  # noqa: E402
from taichi_spheres import runtime  # noqa: E402
from machine import (hardware, publish, step_fraction_arg, tuning_args,  # noqa: E402
                     untimed_pass)


def silo_simulation(tuning=()):
    """The silo of tools/peer_lammps_silo.py, settled and 0.2 s into its discharge
    (``tuning``: tools/silo.py's --tuning NAME=VALUE items)."""
    import peer_lammps_silo  # noqa: E402  (tools/peer_lammps_silo.py)
    import silo  # noqa: E402  (tools/silo.py)
    a = peer_lammps_silo.settings(["--tuning", *tuning] if tuning else [])
    sim = silo.discharging(a, silo.settled_fill(a, a.fill, seed=1), a.orifice * a.radius)
    sim.advance(0.2)
    return sim


def profile(sim, window: float) -> dict:
    """Kernel profile of ``window`` s of ``sim`` (second pass from a checkpoint)."""
    untimed_pass(sim, lambda s: s.advance(window))
    ti.profiler.clear_kernel_profiler_info()
    before = dict(sim.stats)
    t0 = time.perf_counter()
    sim.advance(window)
    wall = time.perf_counter() - t0
    s = sim.stats
    steps = s["steps"] - before["steps"]
    prof = get_default_kernel_profiler()
    prof._update_records()       # the table print_kernel_profiler_info builds, as data
    prof._count_statistics()
    kernels = {name: [r.total_time * 1e-3, r.counter]       # [s], launches
               for name, r in prof._statistical_results.items()}
    return dict(steps=steps, wall=wall, kernels=kernels,
                rows=(s["contacts"] - before["contacts"]) / max(steps, 1),
                vel=(s["contact_iterations"] - before["contact_iterations"]) / max(steps, 1),
                pos=(s["position_iterations"] - before["position_iterations"]) / max(steps, 1))


def capped_steps(sim, window: float):
    """(steps, of them those whose velocity sweeps and those whose position sweeps ran
    to the step's cap) over the next ``window`` s of ``sim``, stepped one by one from a
    checkpoint and put back (untimed: the same steps as advance; None without a
    contact solver)."""
    solver = sim.debug_view().solver
    if solver is None:
        return None
    counts = [0, 0, 0]

    def walk(s):
        end = s.time + window
        while s.time < end:
            before = dict(s.stats)
            s.step_toward(end)
            counts[0] += 1
            counts[1] += s.stats["contact_iterations"] - before["contact_iterations"] >= solver.cap_v[None]
            counts[2] += s.stats["position_iterations"] - before["position_iterations"] >= solver.cap_w[None]

    untimed_pass(sim, walk)
    return tuple(counts)


def capped(counts) -> str:
    """The report's words on capped_steps' counts."""
    if counts is None:
        return ""
    steps, velocity, position = counts
    return (f"; of the {steps} steps, {velocity} ran their velocity sweeps and {position} "
            "their position sweeps to the step's cap (an untimed pass, step by step)")


def report(args, label, p) -> str:
    total = sum(t for t, _ in p["kernels"].values())
    hw = hardware(args.arch) + (", 1 thread" if args.arch == "cpu"
                                else f", {args.precision}")
    lines = [f"Measured {datetime.date.today()} on {hw}: "
             f"`python tools/kernel_profile.py {' '.join(a for a in sys.argv[1:] if a != '--write')}`",
             "",
             f"{label}: {p['steps']} steps in {args.window} s, {1e3 * p['wall'] / p['steps']:.2f} "
             f"wall ms per step with the profiler on ({1e3 * total / p['steps']:.2f} ms in "
             f"kernels), {p['rows']:.0f} contact rows, {p['vel']:.1f} velocity and "
             f"{p['pos']:.1f} position sweeps per step{capped(p['capped'])}.", "",
             "| kernel task | share of kernel time | ms per launch | launches per step |",
             "|---|---|---|---|"]
    for name, (t, n) in sorted(p["kernels"].items(), key=lambda kv: -kv[1][0])[:args.top]:
        lines.append(f"| {name} | {100 * t / total:.1f} % | {1e3 * t / n:.3f} | {n / p['steps']:.2f} |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default=None)
    ap.add_argument("--at", type=float, default=0.0)
    ap.add_argument("--silo", action="store_true")
    ap.add_argument("--silo-large", type=int, default=0, metavar="N",
                    help="the silo of tools/silo_large.py with N spheres (cpu or cuda, f64)")
    ap.add_argument("--window", type=float, default=0.1)
    ap.add_argument("--top", type=int, default=8)
    ap.add_argument("--gas", type=int, default=0,
                    help="the gas of tools/bench.py with this many spheres (packing 0.3)")
    ap.add_argument("--arch", default="cpu", choices=runtime.ARCHS,
                    help="cpu (1 thread) or a GPU arch (cuda)")
    ap.add_argument("--precision", default="f64", choices=["f64", "f32"])
    ap.add_argument("--host", action="store_true",
                    help="also profile the Python side of the window (cProfile, top 15)")
    ap.add_argument("--tuning", nargs="+", default=[], metavar="NAME=VALUE",
                    help="with --silo: Tuning.with_ keywords of its run (tools/silo.py's); "
                         "with --scene: over the scene file's [tuning]")
    ap.add_argument("--step-fraction", type=float, default=None,
                    help="with --scene: the Simulation's step_fraction (else the scene "
                         "file's, else the default)")
    ap.add_argument("--stages", action="store_true",
                    help="launch the serial contact solve one kernel per stage "
                         "(Performance.staged_solve, the same bits): the table then "
                         "shows each stage (gather, sweeps, ...) as a kernel of its own")
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args(argv)
    if args.tuning and not (args.silo or args.scene):
        ap.error("--tuning goes with --silo or --scene")
    if args.step_fraction is not None and not args.scene:
        ap.error("--step-fraction goes with --scene")
    if (args.tuning or args.step_fraction is not None) and args.write:
        ap.error("--write keeps the defaults' profile: run --tuning and --step-fraction "
                 "without it")
    args.scene_tuning = tuning_args(args.tuning, ap) if args.scene else {}
    args.scene_steps = step_fraction_arg(args.step_fraction, ap) if args.scene else {}
    if [args.scene is not None, args.silo, args.gas != 0, args.silo_large != 0].count(True) != 1:
        ap.error("give one of --scene TOML, --gas N, --silo or --silo-large N")
    if args.gas < 0 or args.silo_large < 0:
        ap.error("--gas and --silo-large take a positive sphere count")
    if args.silo_large and (args.precision != "f64" or args.arch not in ("cpu", "cuda")):
        ap.error("--silo-large runs in f64 on cpu or cuda (the silo of tools/silo_large.py)")
    if args.silo and (args.arch != "cpu" or args.precision != "f64"):
        ap.error("--silo runs on the CPU in f64 (the silo of tools/silo.py)")
    if args.stages and (args.silo_large or args.gas):
        ap.error("--stages goes with --silo or --scene (a serial solve on the CPU)")
    for mode in runtime.COMPILE_MODES.values():
        mode["kernel_profiler"] = True
    threads = 1 if args.arch == "cpu" else None
    runtime.ensure(args.arch, args.precision, threads=threads)
    sim, label, section = simulation(args, threads)
    if args.stages:
        section += "-stages"
    counts = capped_steps(sim, args.window)        # the window profile() times
    result = dict(profile(sim, args.window), capped=counts)
    publish(report(args, label, result), section, args.write)
    if args.host:
        host_profile(sim, args.window)


def simulation(args, threads) -> tuple:
    """(Simulation at the window's start, its label in the report, the report's section)
    of the command line's run."""
    if args.silo:
        tuning = args.tuning + (["staged_solve=True"] if args.stages else [])
        return silo_simulation(tuning), "Silo discharge (tools/peer_lammps_silo.py's)", "profile-silo"
    if args.silo_large:
        import silo_large  # noqa: E402  (tools/silo_large.py)
        a = silo_large.parser().parse_args(["--count", str(args.silo_large),
                                            "--arch", args.arch])
        return (silo_large.discharging(a, threads),
                f"Silo of {args.silo_large} spheres (tools/silo_large.py's)",
                "profile-silo-large" + ("" if args.arch == "cpu" else f"-{args.arch}"))
    if args.gas:
        from taichi_spheres.builders import gas
        sim = ts.Simulation(gas(args.gas, packing=0.3, periodic=True, seed=0), arch=args.arch,
                            precision=args.precision, threads=threads)
        return sim, f"Gas of {args.gas} spheres (tools/bench.py's)", f"profile-gas-{args.arch}"
    scene = ts.load_scene(args.scene)
    changes = dict(scene.meta.get("tuning", {}), **args.scene_tuning)
    if args.stages:
        changes["staged_solve"] = True
    tuning = DEFAULT.with_(**changes) if changes else None   # (None: as Simulation reads it)
    sim = ts.Simulation(scene, arch=args.arch, precision=args.precision, threads=threads,
                        tuning=tuning, **args.scene_steps)
    sim.advance_to(args.at)
    name = os.path.splitext(os.path.basename(args.scene))[0]
    section = f"profile-{name}" + ("" if args.arch == "cpu" else f"-{args.arch}")
    return sim, f"`{args.scene}` from t = {args.at} s", section


def host_profile(sim, window: float) -> None:
    """Print where the Python side of ``window`` s of ``sim`` spends its time."""
    import cProfile
    import pstats
    prof = cProfile.Profile()
    prof.runcall(sim.advance, window)
    pstats.Stats(prof).sort_stats("cumulative").print_stats(15)


if __name__ == "__main__":
    main()
