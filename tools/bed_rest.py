#!/usr/bin/env python3
"""Does the pour's bed come to rest? Its kinetic energy against time up to --until s,
and how far its spheres still move in the last second, in taichi_spheres and LAMMPS.

scenes/pour.toml (2,000 spheres, e = 0.5, poured into a box) runs from t = 0 on one
thread, f64, with the run stopped every --every s to sample it (each stop shortens the
step before it, so the trajectory is that of a run with those stops). Runs:

- taichi_spheres, frictionless (the scene), at the defaults;
- the same with 1,000 velocity and 1,000 position sweeps at most per step (a solve far
  closer to the converged one: docs/bench.md, "solver-convergence");
- the same at the defaults with friction mu = 0.5 between spheres and on the walls;
- LAMMPS GRANULAR, frictionless Hertz as in tools/peer_lammps.py (E = 5e9 Pa,
  nu = 0.3, dt = 5e-6 s), the same initial state, and over --lammps-fills fills;
  each run is saved to --lammps-json and reused on the same CPU model with the same
  initial state, model and sampling (~5-7 min a run on one core);
- over --fills fills (the pour's ``seed`` 1..K), taichi_spheres at the defaults
  (the scene's own seed is 3: its fill is the first run again, and LAMMPS's the
  saved scene run);
- from the first run's state at until - 1 s, its last second again, with the same
  stops, under solves of increasing accuracy (velocity sweeps at most: CAPS; 1,000
  position sweeps where the cap is not the default's, else the default 60): how the
  motion of the bed depends on how close the solve is to the converged one (the
  default cap's row is the first run's last second itself: checked); then, from the
  end of the most accurate of them, GROWTH_STEPS single steps with each cap: does a
  bed that slow stay so?

Reported per run: the kinetic energy over the initial energy at 2 s and each whole
second after (taichi_spheres: spin included; LAMMPS: translational, its frictionless
contacts exert no torque), the first sample from which every later sample is at most
1e-6 of it, and, over the last second [until - 1, until], the median, 99th percentile
and largest displacement of a sphere / its diameter and the rms speed at the end
[m/s]; for taichi_spheres also the wall seconds per simulated second from 1 s on (the
untimed step that compiles a Simulation's kernels is taken back; kernels first needed
later, such as the contact solver's at the first contact, compile before 1 s).

    python tools/bed_rest.py --lammps-only        # LAMMPS's 8 runs, ~45 min on one core
    python tools/bed_rest.py --write              # ~5 min once they are saved
    python tools/bed_rest.py --until 15 --fills 0 --no-lammps --write \\
        --section bed-rest-long                   # ~4 min: does it end?
"""
from __future__ import annotations

import argparse
import contextlib
import datetime
import json
import math
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.join(HERE, "..")
sys.path.insert(0, ROOT)
sys.path.insert(0, HERE)

import taichi_spheres as ts  # noqa: E402
from taichi_spheres.config import Tuning  # noqa: E402
from machine import cpu_name, publish, untimed_pass  # noqa: E402  (tools/machine.py)
from bed_steps import pour_fill  # noqa: E402
import peer_lammps  # noqa: E402

SCENE = os.path.join("scenes", "pour.toml")
#: the threshold of issue targets: kinetic energy / initial energy
K_TARGET = 1e-6
#: LAMMPS model and step, as tools/peer_lammps.py's defaults
YOUNG, POISSON, DT = 5e9, 0.3, 5e-6
#: velocity sweep caps of the accuracy rows (the first: the defaults; the last leaves
#: the bed nearly at rest, where the growth rows start)
CAPS = (100, 300, 1000, 3000)
#: steps of the growth rows, and every how many the table shows
GROWTH_STEPS, GROWTH_SHOWN = 40, 5
DEFAULT_CAP = Tuning().physics.contact_iterations
#: taichi_spheres runs: label -> (Tuning changes, friction mu or None)
RUNS = {
    "taichi_spheres, frictionless, defaults": ({}, None),
    "taichi_spheres, frictionless, 1000 / 1000 sweeps":
        (dict(contact_iterations=1000, position_iterations=1000), None),
    "taichi_spheres, friction 0.5, defaults": ({}, 0.5),
}


def whole_multiple(value: float, step: float) -> bool:
    """True when value / step is a whole number (to 1e-9)."""
    ratio = value / step
    return abs(ratio - round(ratio)) < 1e-9


def check_sampling(args, ap) -> None:
    """Usage errors: --until not a number of at least 3 s, --every not > 0 or not
    dividing 1 s and --until, --fills or --lammps-fills below 0, LAMMPS options that
    contradict --no-lammps, --lammps-only without a file to save to."""
    if not (math.isfinite(args.until) and args.until >= 3.0):
        ap.error(f"--until must be at least 3 s, got {args.until:g}")
    if not (args.every > 0 and whole_multiple(1.0, args.every)
            and whole_multiple(args.until, args.every)):
        ap.error(f"--every must divide 1 s and --until ({args.until:g} s), "
                 f"got {args.every:g}")
    if args.fills < 0 or (args.lammps_fills or 0) < 0:
        ap.error(f"--fills and --lammps-fills must be >= 0, got {args.fills}, "
                 f"{args.lammps_fills}")
    if args.no_lammps and (args.lammps_only or args.lammps_fills is not None):
        ap.error("--no-lammps runs no LAMMPS: --lammps-only and --lammps-fills contradict it")
    if args.lammps_only and not args.lammps_json:
        ap.error("--lammps-only saves LAMMPS's runs to --lammps-json: give a file")


def command_text(args) -> str:
    """The command line that reproduces the report (options that differ from the
    defaults)."""
    parts = ["python tools/bed_rest.py"]
    for name, default in (("until", 5.0), ("every", 0.25), ("fills", 8)):
        if getattr(args, name) != default:
            parts.append(f"--{name} {getattr(args, name):g}")
    if args.lammps_fills is not None:
        parts.append(f"--lammps-fills {args.lammps_fills}")
    if args.no_lammps:
        parts.append("--no-lammps")
    if args.write:
        parts.append("--write")
    if args.section != "bed-rest":
        parts.append(f"--section {args.section}")
    return " ".join(parts)


def sample_times(until: float, every: float) -> np.ndarray:
    """The sampling instants every..until [s]."""
    return np.round(np.arange(1, int(round(until / every)) + 1) * every, 9)


def last_second(t: float, times) -> bool:
    """True at the sample that starts the last second, until - 1 [s]."""
    return abs(t - (times[-1] - 1.0)) < 1e-9


def rms_speed(v) -> float:
    """Root mean square of the speeds of velocities v (N, 3) [m/s]."""
    return float(np.sqrt((np.asarray(v) ** 2).sum(axis=1).mean()))


def motion(x_start, x_end, v_end, diameter) -> dict:
    """Displacements / diameter over a window (median, p99, largest) and the rms speed
    at its end [m/s]; x (N, 3) [m] in the same sphere order, diameter (N,) [m]."""
    d = np.linalg.norm(x_end - x_start, axis=1) / diameter
    return dict(median=float(np.median(d)), p99=float(np.percentile(d, 99)),
                largest=float(d.max()), rms_speed=rms_speed(v_end))


def compiled_simulation(scene, tuning: dict, start=None):
    """A 1-thread Simulation under ``tuning`` at ``start`` (a checkpoint; None: t = 0),
    the kernels of its first step compiled (or loaded) by one untimed step taken
    back."""
    sim = ts.Simulation(scene, threads=1, tuning=Tuning().with_(**tuning))
    if start is not None:
        sim.restore(start)
    untimed_pass(sim, lambda s: s.advance(s.max_step()))
    return sim


def run_taichi(scene, times, tuning: dict) -> dict:
    """Kinetic energy / initial energy at ``times``, motion() over the last second,
    wall s per simulated s from 1 s on (the first step's compile excluded), and the
    checkpoint at the start of the last second (``last``)."""
    sim = compiled_simulation(scene, tuning)
    e0, kinetic, wall, x_last = sim.initial_energy, [], 0.0, None
    for t in times:
        t0 = time.perf_counter()
        sim.advance_to(float(t))
        wall += (time.perf_counter() - t0) if t > 1.0 + 1e-9 else 0.0
        st = sim.state()
        kinetic.append((ts.observe.kinetic_energy(st) + ts.observe.rotational_energy(st)) / e0)
        if last_second(t, times):
            x_last, last = st.x.copy(), sim.checkpoint()
    st = sim.state()
    return dict(kinetic=kinetic, wall=wall / (times[-1] - 1.0),
                motion=motion(x_last, st.x, st.v, 2 * st.radius), last=last)


def cap_tuning(cap: int) -> dict:
    """Tuning changes for at most ``cap`` velocity sweeps (and 1,000 position sweeps;
    none at the default cap)."""
    return {} if cap == DEFAULT_CAP else dict(contact_iterations=cap,
                                              position_iterations=1000)


def accuracy_row(scene, start, cap: int, times) -> dict:
    """From checkpoint ``start`` (at times[-1] - 1 s) to times[-1], stopping at the
    same ``times``, with at most ``cap`` velocity sweeps (cap_tuning): motion(),
    velocity sweeps per step, wall s per simulated s, and the checkpoint at the end
    (``end``)."""
    sim = compiled_simulation(scene, cap_tuning(cap), start)
    x0, sweeps, steps = sim.state().x.copy(), sim.stats["contact_iterations"], sim.stats["steps"]
    t0 = time.perf_counter()
    for t in times[times > sim.time + 1e-9]:
        sim.advance_to(float(t))
    wall = time.perf_counter() - t0                 # over one simulated second
    st = sim.state()
    return dict(motion=motion(x0, st.x, st.v, 2 * st.radius), wall=wall,
                sweeps=(sim.stats["contact_iterations"] - sweeps) / max(
                    sim.stats["steps"] - steps, 1), end=sim.checkpoint())


def growth_row(scene, start, cap: int, steps: int) -> list:
    """The rms speed [m/s] after each of ``steps`` single steps (each the longest the
    Simulation takes) from checkpoint ``start`` with at most ``cap`` velocity sweeps."""
    sim = compiled_simulation(scene, cap_tuning(cap), start)
    out = []
    for _ in range(steps):
        sim.step_toward(sim.time + sim.max_step())
        out.append(rms_speed(sim.state().v))
    return out


def lammps_by_id(lmp):
    """peer_lammps.lammps_atoms (positions, velocities [m, m/s], masses [kg], radii
    [m]) in atom-id order, which LAMMPS's own order is not (it sorts its atoms)."""
    nl = lmp.extract_global("nlocal")
    order = np.argsort(np.array(lmp.numpy.extract_atom("id")[:nl]))
    return tuple(a[order] for a in peer_lammps.lammps_atoms(lmp))


def lammps_samples(scene, times):
    """LAMMPS GRANULAR (frictionless Hertz as tools/peer_lammps.py: YOUNG, POISSON, DT,
    one thread) from ``scene``'s spheres: yields lammps_by_id's (x, v, m, r) at t = 0,
    then at each of ``times`` [s] (increasing); SystemExit where LAMMPS is missing."""
    lammps, why = peer_lammps.import_lammps()
    if lammps is None:
        raise SystemExit(f"LAMMPS: {why}")
    lmp = peer_lammps.lammps_scene_setup(lammps, scene, 1, YOUNG, POISSON, DT)
    try:
        lmp.command("run 0")
        yield lammps_by_id(lmp)
        done = 0
        for t in times:
            steps = int(round(t / DT)) - done
            lmp.command(f"run {steps} pre no post no")
            done += steps
            yield lammps_by_id(lmp)
    finally:
        lmp.close()


def run_lammps(scene, times) -> dict:
    """As run_taichi for LAMMPS (no wall time): kinetic energy / initial energy at
    ``times`` and motion() over the last second."""
    with contextlib.closing(lammps_samples(scene, times)) as samples:
        x, v, m, _ = next(samples)
        e0 = peer_lammps.energies(x, v, m, scene.gravity)[1]
        kinetic, x_last = [], None
        for t, (x, v, m, r) in zip(times, samples):
            kinetic.append(peer_lammps.energies(x, v, m, scene.gravity)[0] / e0)
            if last_second(t, times):
                x_last = x.copy()
            print(f"LAMMPS t = {t:g} s: K / E0 = {kinetic[-1]:.2e}", flush=True)
    return dict(kinetic=kinetic, wall=None, motion=motion(x_last, x, v, 2 * r))


def lammps_key(scene, times) -> dict:
    """What a saved LAMMPS run must share with the one asked for: the scene's initial
    state (digest), the sampling, the contact models and step, the CPU model."""
    return dict(format=1, digest=peer_lammps.scene_digest(scene),
                times=[float(t) for t in times], young=YOUNG, poisson=POISSON, dt=DT,
                model=peer_lammps.granular_model(YOUNG, POISSON, scene.restitution),
                wall_model=peer_lammps.granular_model(YOUNG, POISSON, scene.wall_restitution),
                cpu=cpu_name())


def lammps_result(scene, times, path) -> tuple:
    """LAMMPS's run of ``scene``: from ``path`` where one was saved with the same
    lammps_key, else run now (and added to ``path`` if given); returns (result, where
    it came from)."""
    key = lammps_key(scene, times)
    for run in load_runs(path):
        if run["key"] == key:
            return run["result"], f"saved {run['date']} in {os.path.relpath(path, ROOT)}"
    result = run_lammps(scene, times)
    if path:
        save_run(path, dict(key=key, result=result, date=datetime.date.today().isoformat()))
    return result, "run now"


def load_runs(path) -> list:
    """The LAMMPS runs saved at ``path`` (none if there is no such file)."""
    if not path or not os.path.exists(path):
        return []
    with open(path) as fh:
        data = json.load(fh)
    return data.get("runs", [])


def save_run(path, run: dict) -> None:
    """Add ``run`` to the runs saved at ``path`` (read again just before: another
    process may have added some meanwhile), replacing one with the same key; written
    to a temporary file first, so that an interrupted write leaves the old file."""
    runs = [r for r in load_runs(path) if r["key"] != run["key"]] + [run]
    tmp = path + ".tmp"
    with open(tmp, "w") as fh:
        json.dump(dict(runs=runs), fh, indent=1)
    os.replace(tmp, path)


def lammps_fills(times, fills: int, path) -> tuple:
    """lammps_result for the pour's seed 1..fills: (results, where they came from)."""
    results, sources = [], set()
    for seed in range(1, fills + 1):
        result, source = lammps_result(pour_fill(seed), times, path)
        results.append(result)
        sources.add(source.split(" in ")[0])
    return results, "; ".join(sorted(sources))


def settled_from(kinetic, times) -> str:
    """The first sampled time from which every sample is <= K_TARGET, as text."""
    above = [t for t, k in zip(times, kinetic) if k > K_TARGET]
    if not above:
        return f"{times[0]:g}"
    if above[-1] == times[-1]:
        return f"not by {times[-1]:g}"
    return f"{times[list(times).index(above[-1]) + 1]:g}"


def fills_result(times, fills: int) -> list:
    """run_taichi at the defaults for the pour's seed 1..fills."""
    out = []
    for seed in range(1, fills + 1):
        out.append(run_taichi(pour_fill(seed), times, {}))
        print(f"fill {seed}: K / E0 at the end {out[-1]['kinetic'][-1]:.2e}", flush=True)
    return out


def whole_seconds(times) -> list:
    """Indices of the samples at 2 s and each whole second after."""
    return [k for k, t in enumerate(times) if t >= 2.0 - 1e-9 and abs(t - round(t)) < 1e-9]


def run_row(label, r, times) -> str:
    """One run's table row."""
    kin = " | ".join(f"{r['kinetic'][k]:.1e}" for k in whole_seconds(times))
    m = r["motion"]
    wall = "-" if r["wall"] is None else f"{r['wall']:.2f}"
    return (f"| {label} | {kin} | {settled_from(r['kinetic'], times)} | {m['median']:.1e} | "
            f"{m['p99']:.1e} | {m['largest']:.1e} | {m['rms_speed']:.1e} | {wall} |")


def fills_row(label, rows, times) -> str:
    """The fills' row of ``label``: medians (and largest) over the fills."""
    cells = []
    for k in whole_seconds(times):
        ks = [r["kinetic"][k] for r in rows]
        cells.append(f"{np.median(ks):.1e} ({max(ks):.1e})")
    at_most = [sum(r["kinetic"][k] <= K_TARGET for r in rows) for k in whole_seconds(times)]
    med = {key: np.median([r["motion"][key] for r in rows])
           for key in ("median", "p99", "largest", "rms_speed")}
    walls = [r["wall"] for r in rows if r["wall"] is not None]
    wall = f"{np.median(walls):.2f}" if walls else "-"
    return (f"| {label}, {len(rows)} fills: median (largest) | "
            + " | ".join(cells) + " | fills at most 1e-6 at each: "
            + ", ".join(str(a) for a in at_most)
            + f" | {med['median']:.1e} | {med['p99']:.1e} | {med['largest']:.1e} | "
            f"{med['rms_speed']:.1e} | {wall} |")


def report(args, times, results, fills: dict, source) -> str:
    """The markdown section (fills: label -> the fills' results)."""
    until = times[-1]
    heads = " | ".join(f"K / E0 at {times[k]:g} s" for k in whole_seconds(times))
    lines = [f"{datetime.date.today()}, {cpu_name()}, 1 thread, f64: "
             f"`{command_text(args)}`.", "",
             f"`{SCENE}`, the run stopped every {args.every:g} s up to {until:g} s; K: kinetic "
             "energy (spin included), E0: the initial energy. Motion over the last second "
             f"[{until - 1:g}, {until:g}] s: displacement of a sphere / its diameter, rms "
             f"speed at {until:g} s (LAMMPS's K: translational; its frictionless contacts "
             f"exert no torque). LAMMPS (Hertz, frictionless, E = {YOUNG:g} Pa, "
             f"nu = {POISSON}, dt = {DT:g} s): {source}.", "",
             f"| run | {heads} | K / E0 at most 1e-6 from [s] | median displacement / d | "
             "99th percentile | largest | rms speed [m/s] | wall s per simulated s after 1 s |",
             "|---|" + "---|" * len(whole_seconds(times)) + "---|---|---|---|---|---|"]
    lines += [run_row(label, r, times) for label, r in results.items()]
    lines += [fills_row(label, rows, times) for label, rows in fills.items() if rows]
    return "\n".join(lines) + "\n"


def accuracy_table(rows: dict, until: float, repeats: bool) -> str:
    """The accuracy rows' markdown (``repeats``: whether the default cap's row gave the
    first run's last second, as it should)."""
    lines = ["", f"The first run's last second [{until - 1:g}, {until:g}] s again from its state "
             f"at {until - 1:g} s, with the same stops, under solves closer to the converged "
             "one (position sweeps 1,000 at most where the velocity cap is not the default; "
             "the default's row repeats the first run's last second: "
             f"{'checked, the same' if repeats else 'NOT the same'}):", "",
             "| velocity sweeps at most | velocity sweeps per step | median displacement / d | "
             "99th percentile | largest | rms speed at the end [m/s] | wall s per simulated s |",
             "|---|---|---|---|---|---|---|"]
    for cap, r in rows.items():
        m = r["motion"]
        label = f"{cap} (default)" if cap == DEFAULT_CAP else f"{cap}"
        lines.append(f"| {label} | {r['sweeps']:.0f} | {m['median']:.1e} | {m['p99']:.1e} | "
                     f"{m['largest']:.1e} | {m['rms_speed']:.1e} | {r['wall']:.2f} |")
    return "\n".join(lines) + "\n"


def growth_rate(speeds) -> str:
    """Growth per step of the rms speeds over the last half of the steps (geometric
    mean of the ratios), as text; '-' where it starts from zero."""
    half = speeds[-(len(speeds) // 2) - 1:]
    if half[0] == 0:
        return "-"
    return f"{(half[-1] / half[0]) ** (1.0 / (len(half) - 1)):.2f}"


def growth_table(rows: dict, start_cap: int, start_speed: float, every: int = 1) -> str:
    """The growth rows' markdown: rms speed after every ``every``-th step and
    growth_rate; the rows start from the end of the ``start_cap`` row, at rms speed
    ``start_speed`` [m/s]."""
    steps = len(next(iter(rows.values())))
    shown = list(range(every - 1, steps, every))
    lines = ["", f"From the end of the {start_cap}-sweep row (rms speed {start_speed:.1e} "
             f"m/s), {steps} single steps with each cap: the rms speed [m/s] after "
             + ("each step" if every == 1 else f"every {every}th step")
             + f", and how much it grows per step over the last {steps // 2}:", "",
             "| velocity sweeps at most | " + " | ".join(f"step {k + 1}" for k in shown)
             + " | growth per step |", "|---|" + "---|" * (len(shown) + 1)]
    for cap, speeds in rows.items():
        lines.append(f"| {cap} | " + " | ".join(f"{speeds[k]:.1e}" for k in shown)
                     + f" | {growth_rate(speeds)} |")
    return "\n".join(lines) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--until", type=float, default=5.0, help="end of the runs [s]")
    ap.add_argument("--every", type=float, default=0.25, help="sampling interval [s]")
    ap.add_argument("--fills", type=int, default=8, help="fills at the defaults (0: none)")
    ap.add_argument("--lammps-json", default=os.path.join("docs", "bed_rest_lammps.json"),
                    help="LAMMPS's saved runs, reused and added to ('': none)")
    ap.add_argument("--no-lammps", action="store_true", help="no LAMMPS rows")
    ap.add_argument("--lammps-fills", type=int, default=None,
                    help="fills LAMMPS runs too (default: --fills)")
    ap.add_argument("--lammps-only", action="store_true",
                    help="only run (or load) LAMMPS's runs and save them to --lammps-json")
    ap.add_argument("--write", action="store_true", help="write into docs/bench.md")
    ap.add_argument("--section", default="bed-rest", help="docs/bench.md section")
    args = ap.parse_args(argv)
    check_sampling(args, ap)
    times = sample_times(args.until, args.every)
    scene = ts.load_scene(os.path.join(ROOT, SCENE))
    path = os.path.join(ROOT, args.lammps_json) if args.lammps_json else None
    lammps_fill_count = args.fills if args.lammps_fills is None else args.lammps_fills
    if args.lammps_only:
        print(lammps_result(scene, times, path)[1])
        print(lammps_fills(times, lammps_fill_count, path)[1])
        return 0
    results = {}
    for label, (tuning, mu) in RUNS.items():
        run_scene = scene if mu is None else scene.replace(friction=mu, wall_friction=None)
        results[label] = run_taichi(run_scene, times, tuning)
        print(label, results[label]["kinetic"], results[label]["motion"], flush=True)
    first = results[next(iter(RUNS))]
    accuracy = {cap: accuracy_row(scene, first["last"], cap, times) for cap in CAPS}
    repeats = accuracy[DEFAULT_CAP]["motion"] == first["motion"]
    growth = {cap: growth_row(scene, accuracy[CAPS[-1]]["end"], cap, GROWTH_STEPS)
              for cap in CAPS}
    fills = {"taichi_spheres, frictionless, defaults": fills_result(times, args.fills)}
    source = "not run"
    if not args.no_lammps:
        results["LAMMPS, frictionless"], source = lammps_result(scene, times, path)
        fills["LAMMPS, frictionless"], fill_source = lammps_fills(times, lammps_fill_count,
                                                                  path)
        source = f"{source}; its fills: {fill_source}" if lammps_fill_count else source
    publish(report(args, times, results, fills, source)
            + accuracy_table(accuracy, times[-1], repeats)
            + growth_table(growth, CAPS[-1], accuracy[CAPS[-1]]["motion"]["rms_speed"],
                           GROWTH_SHOWN),
            args.section, args.write)
    return 0


if __name__ == "__main__":
    peer_lammps.ensure_lib_path()
    sys.exit(main())
