#!/usr/bin/env python3
"""Contact solver figures (contacts/solver.py): the pour scene in two phases, resting
columns, warm starting, and a large lattice bed held on 1 and 2 threads.

- pour: scenes/pour.toml (2,000 spheres, e = 0.5) on 1 thread: wall seconds per
  simulated second over the fall [0, 1] s and the bed [1, 2] s (compile time
  excluded: measured on a throw-away run first), the largest pair or wall overlap at
  t = 2 s (brute force, / diameter), kinetic energy at 2 s / initial energy,
  sweep-limit hits and unresolved overlaps in the bed phase, velocity and position
  sweeps per step, the residual of the bed phase's last step and the largest of any
  step from t = 0 (Simulation.stats keeps the largest over the run);
- column (plain sweeps at 100 / 100 without substeps, the former defaults, unless a
  row says otherwise): 20 equal spheres, and 20 with the upper half 10 and 10^3 times heavier, settling
  on the floor for 3 s: largest speed, overlap, sweeps per step at the end (the 10^3
  column also with Rules.shock_propagation off: unequal masses have it by default, and
  with Rules.relaxation 1.8);
- warm start: the settled column's velocity sweeps per step with and without it;
- heavy ball: a ball 8 x heavier dropped onto a settled FCC block, the largest growth
  of the total energy in one step, at the defaults, at relaxation 1.8 with the former
  defaults otherwise (100 / 100 sweeps, no substeps), with
  RELAXED_BEDS (relaxation 1.8, 70 / 50 sweeps) and with the faster bed settings
  FAST_BEDS (relaxation 1.8, 40 / 40 sweeps, shock propagation on);
- error against run time: the pour's bed phase again from its state at t1 with
  velocity/position sweep caps 10, 30, 100 and 300, and 30 and 100 with shock
  propagation on (equal masses: off by default), with over-relaxation 1.5 and 1.8
  (Rules.relaxation, 1.8 by default; all rows here without substeps and plain unless
  they say so; 1.8 from 40 to 100 sweeps, 70 / 50, 40 and 50
  also with shock propagation on), and at step fraction 0.25 (default 0.1), each
  with the largest overlap after a step and the largest growth of the total energy
  in one step over the phase;
- bed: a flat FCC lattice block of --bed-n spheres (10 sphere layers) resting in a
  box that fits it, held for --bed-time s after 0.5 s of settling, on 1 and 2 threads (each in a child
  process: Taichi fixes the thread count at start), with shock propagation off (the
  default for equal masses) and on (what its serial pass costs): wall s per simulated
  s, largest speed and overlap; also with FAST_BEDS.

    python tools/contact_solver.py --write            # ~20-25 min on 2 cores
    python tools/contact_solver.py --quick            # smaller, no write
    python tools/contact_solver.py --beds-only --arch cuda --write   # the bed on a GPU
"""
from __future__ import annotations

import argparse
import collections
import datetime
import json
import os
import subprocess
import sys
import time

import numpy as np

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import taichi_spheres as ts  # noqa: E402
from taichi_spheres.builders import ball_on_block, fcc_block  # noqa: E402
from taichi_spheres.config import Tuning  # noqa: E402
from taichi_spheres.simulation import DEFAULT_STEP_FRACTION  # noqa: E402
from machine import FORMER_DEFAULTS, cpu_name, hardware, publish, untimed_pass  # noqa: E402

G = 9.81


def max_overlap(st, scene, cell=None) -> float:
    """Largest pair or wall overlap / diameter (pairs through a sorted sweep on x)."""
    x, r = st.x, st.radius
    order = np.argsort(x[:, 0])
    xs, rs = x[order], r[order]
    reach = 2 * r.max()
    worst = 0.0
    for k in range(len(xs)):
        hi = np.searchsorted(xs[:, 0], xs[k, 0] + reach, side="right")
        if hi > k + 1:
            d = np.linalg.norm(xs[k + 1:hi] - xs[k], axis=1)
            s = rs[k + 1:hi] + rs[k]
            worst = max(worst, float(np.max((s - d) / s)))
    lo = (x - r[:, None] - scene.box_lo).min()
    hi = (scene.box_hi - x - r[:, None]).min()
    return max(worst, float(-min(lo, hi) / (2 * r.min())))


def window(sim, t_end):
    """Advance to t_end; returns (wall s, counters over the window)."""
    keys = ("steps", "sweep_limit_hits", "unresolved", "contact_iterations",
            "position_iterations", "contact_steps", "pair_collisions", "wall_collisions")
    before = {k: sim.stats[k] for k in keys}
    t0 = time.perf_counter()
    sim.advance_to(t_end)
    wall = time.perf_counter() - t0
    return wall, {k: sim.stats[k] - before[k] for k in keys}


def pour(scene_path, t1, t2):
    """The pour scene's two phases on this process's threads; also returns the
    checkpoint at t1 (for the iteration-cap table)."""
    scene = ts.load_scene(scene_path)
    warm = ts.Simulation(scene)
    warm.advance(0.01)                                   # compile
    sim = ts.Simulation(scene)
    fall, c_fall = window(sim, t1)
    at_t1 = sim.checkpoint()
    bed, c_bed = window(sim, t2)
    st = sim.state()
    ke = ts.observe.kinetic_energy(st)
    return dict(fall=fall / t1, bed=bed / (t2 - t1), overlap=max_overlap(st, scene),
                ke=ke, ke_rel=ke / sim.initial_energy, c_fall=c_fall, c_bed=c_bed,
                residual=sim.last_step["contact_residual"],
                largest_residual=sim.stats["contact_residual"], t1=t1, t2=t2,
                at_t1=at_t1, scene=scene)


#: one row of the error-against-run-time table: sweep caps, Rules.shock_propagation,
#: Rules.relaxation and the step fraction the bed phase runs with (without substeps,
#: as the table in docs/bench.md)
Variant = collections.namedtuple("Variant", "vel pos shock omega step_fraction",
                                 defaults=("auto", 1.0, DEFAULT_STEP_FRACTION))


def stepped_energy_growth(sim, t_end):
    """Advance to t_end with advance_to's steps, one at a time (Simulation.step_toward);
    returns the largest growth of the total energy (kinetic + potential) in one step
    [J] (0 if it never grew) and the largest overlap after a step / contact distance."""
    worst, last, overlap = 0.0, sim.energy_budget()["current"], 0.0
    while sim.time < t_end:
        sim.step_toward(t_end)
        now = sim.energy_budget()["current"]
        worst, last = max(worst, now - last), now
        overlap = max(overlap, sim.last_step["max_overlap"])
    return worst, overlap


def bed_with_caps(p, variants):
    """The pour's bed phase again from its t1 state for each Variant: wall s per
    simulated s, overlap and kinetic energy at t2, and the largest one-step energy
    growth (measured in the untimed pass that precedes the timed one; the same steps).
    A Variant with another step fraction continues the t1 state under that bound."""
    out = {}
    for var in variants:
        tuning = Tuning().with_(contact_iterations=var.vel, position_iterations=var.pos,
                                shock_propagation=var.shock, relaxation=var.omega,
                                substeps=False, step_scaled_sweeps=False)
        sim = ts.Simulation(p["scene"], tuning=tuning, step_fraction=var.step_fraction)
        sim.restore(dict(p["at_t1"], step_fraction=var.step_fraction))
        growth = {}
        untimed_pass(sim, lambda s: growth.update(zip(("J", "overlap"),
                                                      stepped_energy_growth(s, p["t2"]))))
        wall, _ = window(sim, p["t2"])
        st = sim.state()
        out[var] = dict(wall=wall / (p["t2"] - p["t1"]), overlap=max_overlap(st, p["scene"]),
                        ke=ts.observe.kinetic_energy(st), growth=growth["J"] / sim.initial_energy,
                        phase_overlap=growth["overlap"])
    return out


def column(ratio: float, seconds: float, warm_start=True, shock="auto", omega=1.0):
    """20 spheres r = 0.01 m on the floor, gaps 1e-4 m; the upper half ``ratio`` x
    heavier (``shock``: Rules.shock_propagation, ``omega``: Rules.relaxation)."""
    n, r = 20, 0.01
    x = np.zeros((n, 3))
    x[:, :2] = 0.05
    x[:, 2] = r + (2 * r + 1e-4) * np.arange(n)
    mass = np.full(n, 4.19e-3)
    mass[n // 2:] *= ratio
    scene = ts.Scene.from_arrays(x, np.zeros((n, 3)), np.full(n, r), mass=mass,
                                 box=((0, 0, 0), (0.1, 0.1, 0.6)), gravity=(0, 0, -G),
                                 restitution=0.5, wall_restitution=0.5)
    sim = ts.Simulation(scene, tuning=Tuning().with_(warm_start=warm_start,
                                                     shock_propagation=shock, relaxation=omega,
                                                     substeps=False, position_iterations=100,
                                                     step_scaled_sweeps=False))
    sim.advance(seconds - 0.5)
    _, c = window(sim, seconds)
    st = sim.state()
    return dict(vmax=float(np.abs(st.v).max()), overlap=max_overlap(st, scene),
                sweeps=c["contact_iterations"] / max(c["contact_steps"], 1),
                positions=c["position_iterations"] / max(c["contact_steps"], 1))


#: faster settings for settled beds: over-relaxed sweeps, lower caps, shock propagation
FAST_BEDS = dict(relaxation=1.8, contact_iterations=40, position_iterations=40,
                 shock_propagation="on")

#: FAST_BEDS by name in the report
FAST = "relaxation 1.8, 40 / 40 sweeps, shock propagation on"

#: over-relaxed sweeps, 70 / 50: the pour's bed under 1 wall s per simulated s, up to
#: 1.7e-4 d after a step (docs/bench.md)
RELAXED_BEDS = dict(relaxation=1.8, contact_iterations=70, position_iterations=50)
RELAXED = "relaxation 1.8, 70 / 50 sweeps"

#: the contact solver's defaults before over-relaxation and substeps (CHANGELOG)
FORMER = "former defaults: plain, 100 / 100, no substeps"

#: --bed-settings: short names of the FCC bed rows' settings
BED_SETTINGS = {"defaults": "defaults", "fast": FAST, "shock": "shock propagation on",
                "relaxed": RELAXED, "former": FORMER}

#: a heavy-ball row's settings with the warm start unbounded (Rules.bounded_warm_start)
PLAIN_WARM = ", plain warm start"

#: the settings of the heavy-ball rows and of the FCC bed rows, by name
SETTINGS = {"defaults": {}, "relaxation 1.8": dict(FORMER_DEFAULTS, relaxation=1.8),
            RELAXED: RELAXED_BEDS,
            "shock propagation on": dict(shock_propagation="on"), FAST: FAST_BEDS,
            FORMER: FORMER_DEFAULTS,
            "defaults" + PLAIN_WARM: dict(bounded_warm_start="off"),
            FAST + PLAIN_WARM: dict(FAST_BEDS, bounded_warm_start="off")}


def heavy_ball(settings: str, steps: int = 200) -> dict:
    """A 256-sphere FCC block (r = 0.01 m, e = 0.5) settled 1 s, then a ball 8 x heavier
    dropped on it at 1 m/s, its centre 0.05 m above the top sphere's (a 0.03 m gap;
    unequal masses: shock propagation on), under SETTINGS[settings], in a new
    Simulation (set_state: its first step starts without warm start): the largest
    growth of the total energy in one of the next ``steps`` steps [J], the step after
    the drop where it happened, and the ball's kinetic energy when it reaches the
    block [J]."""
    tuning = Tuning().with_(**SETTINGS[settings])
    block = fcc_bed(256, layers=4)
    sim = ts.Simulation(block, tuning=tuning)
    sim.advance(1.0)
    scene, x, v = ball_on_block(block, sim.state(), ratio=8.0, height=0.05, speed=1.0)
    mass = scene.mass
    sim = ts.Simulation(scene, tuning=tuning)
    sim.set_state(x, v)
    energy = [sim.energy_budget()["current"]]
    for _ in range(steps):
        sim.advance(sim.max_step())
        energy.append(sim.energy_budget()["current"])
    growth = np.diff(energy)
    gap = 0.05 - 2 * 0.01
    return dict(growth=max(float(growth.max()), 0.0), step=int(np.argmax(growth)) + 1,
                impact_ke=0.5 * mass[-1] * (1.0 + 2 * G * gap))


def fcc_bed(n_target: int, layers: int = 5):
    """A flat FCC block of about n_target spheres (r = 0.01 m), ``layers`` lattice cells
    (2 x layers sphere layers) tall, in a box that fits it on x and y, nearest
    neighbours 1 + 1e-6 diameters apart."""
    side_cells = max(1, round((n_target / (4 * layers)) ** 0.5))
    return fcc_block((side_cells, side_cells, layers), radius=0.01, restitution=0.5, gravity=G)


def bed_child(n_target: int, hold: float, settings: str, settle: float = 0.5,
              arch: str = "cpu") -> dict:
    """Settle ``settle`` s, then hold ``hold`` s (on ``arch``, f64, this process's threads;
    SETTINGS[settings])."""
    scene = fcc_bed(n_target)
    sim = ts.Simulation(scene, arch=arch, precision="f64",
                        tuning=Tuning().with_(**SETTINGS[settings]))
    sim.advance(settle)
    wall, c = window(sim, settle + hold)
    st = sim.state()
    return dict(n=scene.n, wall_per_s=wall / hold, vmax=float(np.abs(st.v).max()),
                overlap=max_overlap(st, scene),
                sweeps=c["contact_iterations"] / max(c["contact_steps"], 1),
                steps=c["steps"], residual=sim.stats["contact_residual"])


def bed(n_target, hold, threads, settings="defaults", arch="cpu", timeout=None):
    """bed_child in a child process on ``arch`` with ``threads`` CPU threads (None: the
    arch's default; on a GPU the threads only launch its kernels); with ``timeout`` [s],
    {"timeout": timeout} if the child has not finished by then."""
    cmd = [sys.executable, __file__, "--child-bed", str(n_target), str(hold), settings,
           "--arch", arch] + (["--threads", str(threads)] if threads else [])
    try:
        out = subprocess.run(cmd, capture_output=True, text=True, check=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"timeout": timeout}
    return json.loads(out.stdout.strip().splitlines()[-1])


def beds_table(args, beds) -> list:
    """The FCC bed rows (markdown lines) of the report."""
    lines = [f"FCC bed: a flat lattice block (10 sphere layers, r = 0.01 m) in a box that "
             f"fits it on x and y, settled 0.5 s, then held {args.bed_time:g} s; "
             "Performance defaults (serial sweeps below 30,000 spheres, else one "
             "parallel launch per sweep).", "",
             "| FCC bed held | threads | settings | wall s per simulated s | "
             "steps | velocity sweeps per step | largest speed [m/s] | overlap / diameter |",
             "|---|---|---|---|---|---|---|---|"]
    for (t, name), b in beds.items():
        where = t if t else args.arch.upper()
        label = "defaults (shock propagation off: equal masses)" if name == "defaults" else name
        if "timeout" in b:
            lines.append(f"| about {args.bed_n} spheres | {where} | {label} | not done in "
                         f"{b['timeout']:g} s (settling included) | | | | |")
            continue
        lines.append(f"| {b['n']} spheres | {where} | {label} | "
                     f"{b['wall_per_s']:.2f} | {b['steps']} | "
                     f"{b['sweeps']:.1f} | {b['vmax']:.2e} | {b['overlap']:.2e} |")
    return lines


def beds_report(args, beds) -> str:
    """The section of --beds-only: the FCC bed on args.arch, with its hardware."""
    hw = hardware(args.arch) + (", threads as given" if args.arch == "cpu" else "")
    cmd = " ".join(["python tools/contact_solver.py --beds-only --arch", args.arch,
                    "--bed-n", str(args.bed_n), "--bed-settings", *args.bed_settings,
                    "--write"])
    return "\n".join([f"{datetime.date.today()}, {hw}, f64: `{cmd}`.", ""]
                     + beds_table(args, beds)) + "\n"


def report(args, p, cols, warm, beds, capped, balls) -> str:
    """The markdown section."""
    cb = p["c_bed"]
    steps = max(cb["contact_steps"], 1)
    lines = [
        "## Contact solver (persistent contacts)", "",
        f"{datetime.date.today()}, {cpu_name()}, 1 thread for the pour and the columns; "
        f"`python tools/contact_solver.py{' --quick' if args.quick else ''} --write`.", "",
        f"Pour (`{args.scene}`): fall [0, {p['t1']:g}] s **{p['fall']:.1f}** wall s per "
        f"simulated s, bed [{p['t1']:g}, {p['t2']:g}] s **{p['bed']:.2f}**; at "
        f"{p['t2']:g} s overlap {p['overlap']:.2e} of a diameter, kinetic energy "
        f"{p['ke']:.3g} J ({p['ke_rel']:.2e} of the initial energy); bed phase: "
        f"{cb['sweep_limit_hits']} sweep-limit hits, {cb['unresolved']} unresolved, "
        f"{cb['pair_collisions']} pair and {cb['wall_collisions']} wall impacts, "
        f"{cb['contact_iterations'] / steps:.1f} velocity and "
        f"{cb['position_iterations'] / steps:.1f} position sweeps per step, the last "
        f"step's residual {p['residual']:.2e} m/s (the largest of any step from t = 0: "
        f"{p['largest_residual']:.2e}).", "",
        "| column of 20 on the floor, 3 s | largest speed [m/s] | overlap / diameter | "
        "velocity sweeps per step | position sweeps per step |", "|---|---|---|---|---|"]
    for name, c in cols.items():
        lines.append(f"| {name} | {c['vmax']:.2e} | {c['overlap']:.2e} | {c['sweeps']:.1f} | "
                     f"{c['positions']:.1f} |")
    lines += ["", f"Warm start, settled column of 20: {warm[True]:.1f} velocity sweeps per "
              f"step with it, {warm[False]:.1f} without.", "",
              "A ball 8 x heavier dropped at 1 m/s onto a settled FCC block of 256 spheres "
              f"(it reaches the block with {next(iter(balls.values()))['impact_ke']:.2e} J "
              "of kinetic energy; a new Simulation, so its first step starts without warm "
              "start): the largest growth of the total energy in one of the next 200 steps "
              "is " + "; ".join(f"{b['growth']:.2e} J ({b['growth'] / b['impact_ke']:.2%} of "
                                f"the ball's, step {b['step']}) with {name}"
                                for name, b in balls.items()) + ".", "",
              f"Error against run time, the pour's bed phase again from its t = {p['t1']:g} s "
              "state with other sweep caps (Rules.contact_iterations, position_iterations), "
              "shock propagation, over-relaxation (Rules.relaxation) or a longer step bound "
              "(step_fraction):",
              "", "| velocity / position sweeps at most | wall s per simulated s | overlap / "
              f"diameter at {p['t2']:g} s | largest overlap after a step in [{p['t1']:g}, "
              f"{p['t2']:g}] s / diameter | kinetic energy at {p['t2']:g} s [J] | largest "
              "energy growth in one step / initial energy |",
              "|---|---|---|---|---|---|"]
    for var, c in capped.items():
        extra = (", shock propagation on" if var.shock == "on" else "") + \
            (f", relaxation {var.omega:g}" if var.omega != 1.0 else "") + \
            (f", step fraction {var.step_fraction:g}"
             if var.step_fraction != DEFAULT_STEP_FRACTION else "")
        lines.append(f"| {var.vel} / {var.pos}{extra} | {c['wall']:.2f} | {c['overlap']:.2e} | "
                     f"{c['phase_overlap']:.2e} | {c['ke']:.2e} | {c['growth']:.1e} |")
    lines.append("")
    if beds:
        lines += beds_table(args, beds)
    return "\n".join(lines) + "\n"


def check_args(ap, args) -> None:
    """Usage errors (ap.error) for options out of range or that do not go together."""
    if args.threads is not None and args.threads < 1:
        ap.error(f"--threads must be at least 1, got {args.threads}")
    if args.arch != "cpu" and args.threads is not None:
        ap.error(f"--threads sets CPU threads; not with --arch {args.arch}")
    if args.child_bed:
        return
    if args.arch != "cpu" and not args.beds_only:
        ap.error("--arch other than cpu needs --beds-only")
    if args.child_timeout is not None and not args.child_timeout > 0:
        ap.error(f"--child-timeout must be > 0 s, got {args.child_timeout}")
    if not args.beds_only and (args.child_timeout is not None
                               or args.bed_settings != ap.get_default("bed_settings")):
        ap.error("--bed-settings and --child-timeout go with --beds-only")
    if args.beds_only and args.quick:
        ap.error("--quick does not go with --beds-only (give --bed-n)")


def parser() -> argparse.ArgumentParser:
    """The command line (module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", default="scenes/pour.toml")
    ap.add_argument("--phases", type=float, nargs=2, default=(1.0, 2.0))
    ap.add_argument("--bed-n", type=int, default=100_000)
    ap.add_argument("--bed-time", type=float, default=0.3)
    ap.add_argument("--quick", action="store_true", help="0.3/0.6 s pour, 4,000-sphere bed")
    ap.add_argument("--write", action="store_true", help="write into docs/bench.md")
    ap.add_argument("--threads", type=int, default=None, help="CPU threads (default 1)")
    ap.add_argument("--arch", default="cpu", choices=ts.runtime.ARCHS,
                    help="cpu, or a GPU arch (cuda) for --beds-only")
    ap.add_argument("--beds-only", action="store_true",
                    help="only the FCC bed (on the CPU: 1 and 2 threads; on a GPU: once), "
                         "written to the section fcc-bed-ARCH-SETTINGS")
    ap.add_argument("--bed-settings", nargs="+", choices=list(BED_SETTINGS),
                    default=["defaults", "fast", "shock"],
                    help="--beds-only: which settings (fast: FAST_BEDS, relaxed: RELAXED_BEDS)")
    ap.add_argument("--child-timeout", type=float, default=None,
                    help="--beds-only: seconds each bed may take (settling included)")
    ap.add_argument("--child-bed", nargs=3, default=None, help=argparse.SUPPRESS)
    return ap


def beds_only(args) -> None:
    """--beds-only: the FCC bed with each of args.bed_settings, each in a child process
    (on the CPU on 1 and 2 threads), printed as they finish, then the report."""
    beds = {}
    for name in (BED_SETTINGS[key] for key in args.bed_settings):
        for t in (1, 2) if args.arch == "cpu" else (None,):
            beds[t, name] = bed(args.bed_n, args.bed_time, t, name, args.arch,
                                args.child_timeout)
            print(t, name, beds[t, name], flush=True)
    publish(beds_report(args, beds), "-".join(["fcc-bed", args.arch, *args.bed_settings]),
            args.write)


def everything(args) -> None:
    """The whole report (module docstring) on the CPU."""
    if args.quick:
        args.phases, args.bed_n = (0.3, 0.6), 4000
    os.chdir(ROOT)
    p = pour(args.scene, *args.phases)
    cols = {"equal masses": column(1.0, 3.0), "upper half 10 x heavier": column(10.0, 3.0),
            "upper half 10^3 x heavier": column(1e3, 3.0),
            "upper half 10^3 x heavier, shock propagation off": column(1e3, 3.0, shock="off"),
            "upper half 10^3 x heavier, relaxation 1.8": column(1e3, 3.0, omega=1.8)}
    balls = {name: heavy_ball(name) for name in
             ("defaults", "relaxation 1.8", RELAXED, FAST, "defaults" + PLAIN_WARM,
              FAST + PLAIN_WARM)}
    warm = {w: column(1.0, 3.0, warm_start=w)["sweeps"] for w in (True, False)}
    V = Variant
    capped = bed_with_caps(p, [V(10, 10), V(30, 30), V(100, 100), V(300, 300),
                               V(30, 30, "on"), V(100, 100, "on"),
                               V(30, 30, omega=1.5), V(100, 100, omega=1.5),
                               V(40, 40, omega=1.8), V(50, 50, omega=1.8),
                               V(70, 70, omega=1.8), V(100, 100, omega=1.8),
                               V(70, 50, omega=1.8),
                               V(40, 40, "on", 1.8), V(50, 50, "on", 1.8),
                               V(80, 80, omega=1.8, step_fraction=0.25)])
    beds = {(t, name): bed(args.bed_n, args.bed_time, t, name)
            for name in ("defaults", "shock propagation on", FAST) for t in (1, 2)}
    publish(report(args, p, cols, warm, beds, capped, balls), "contact-solver",
            args.write and not args.quick)


def main(argv=None):
    ap = parser()
    args = ap.parse_args(argv)
    check_args(ap, args)
    if args.beds_only and not args.child_bed:    # (its beds run in child processes)
        beds_only(args)
        return 0
    ts.runtime.ensure(args.arch, "f64", args.threads or (1 if args.arch == "cpu" else None))
    if args.child_bed:
        print(json.dumps(bed_child(int(args.child_bed[0]), float(args.child_bed[1]),
                                   args.child_bed[2], arch=args.arch)))
        return 0
    everything(args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
