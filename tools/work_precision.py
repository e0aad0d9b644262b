#!/usr/bin/env python3
"""Work-precision: engine run time vs error against exact answers, per accuracy setting.

For each case and each ``step_fraction`` (f64, plus f32 at a couple of settings)
it runs the engine, prints its run time (``sim.sim_seconds``) and its error, and
writes docs/work_precision.md (date, machine, command, the tables, and for each
case the first setting at which the error goes below 1e-6 and 1e-9). A log-log
plot docs/work_precision.png is written only if matplotlib is importable.

Cases (the exact answers come from ``taichi_spheres.reference.EventDrivenReference``
or, for the bouncing ball, from the closed form):

  traj       elastic gas, 64 spheres, walls, no gravity, to t = 2 s (about 4 pair
             collisions per sphere; the reference vs itself with a 1e-12 position
             perturbation differs by a few 1e-11 there (printed as the "chaos
             check"), so chaos does not yet swamp round-off): max_i |x_engine -
             x_ref| / box side.
  gravity    the same gas released 5 m above the floor of a tall box, g = 9.81,
             e = e_wall = 0.9, to t = 1.2 s (a few first floor contacts, no resting):
             max_i |x_engine - x_ref| / box width.
  counts     elastic gas of ``traj`` run to t = 5 s (2.5x longer; by t = 8 s the
             trajectories of every setting have diverged chaotically to ~1e-3 and the
             collision count differs by a few in a way that does not track the setting):
             |N_engine - N_ref| / N_ref for pair collisions, and |E - E0| / E0.
  bounce     one ball dropped from h0 = 1 m (centre height above its floor contact),
             e_wall = 0.8: the engine is advanced to each analytic apex time and
             max_k |z_engine - z_apex,k| / h0 with z_apex,k - r = e^{2k} h0.
  pressure   periodic elastic gas, 125 spheres, packing 0.25, no gravity, to t = 1 s
             (about 7 pair collisions per sphere): pressure from the collisional
             virial, P = (N k T + W / (3 t)) / V [Pa], N k T = (2/3) KE [J] (constant
             for e = 1), W = sum over pair collisions of r_ij . dp_i at contact
             [kg m^2/s = J s] (``ref.virial``, ``sim.stats["virial"]``):
             |P_engine - P_ref| / P_ref.  The Carnahan-Starling value is printed for
             information only.  Until the engine has ``stats["virial"]`` the case
             reports "engine virial not available" (timings only).

Reference vs engine speed (``--speed-budget``): the exact reference's wall time on
each case above next to the engine's, and on denser, larger periodic gases
(packing 0.35, N = 125 ... 2000, short horizon) with the reference stopped at a wall
budget: reference and engine seconds per simulated second.

Timing excludes Taichi compilation: each Simulation is first warmed up on itself
(advanced until it has done pair and wall collisions, or a few hundred steps), then
restored to its t = 0 checkpoint and its ``sim_seconds`` reset to zero.

    python tools/work_precision.py            # ~ a few minutes on 2 CPU cores
    python tools/work_precision.py --quick    # ~ 1 minute
    python tools/work_precision.py --workers 2                 # engine runs on Dask
    python tools/work_precision.py --scheduler tcp://host:8786

With ``--workers N`` (a local Dask cluster) or ``--scheduler ADDRESS`` the engine runs
of each case (one per setting) go through ``ts.sweep``, in parallel, one Taichi thread
each; each run is warmed up and timed in its worker as above. The references and the
speed comparison run in this process.

The plot docs/work_precision.png (needs the ``plot`` extra: ``pip install -e .[plot]``)
is error against engine seconds, log-log, one colour per case, f64 solid, f32 dashed.
"""
from __future__ import annotations

import argparse
import contextlib
import datetime
import functools
import math
import os
import sys
import time

import numpy as np

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
sys.path.insert(0, ROOT)

import taichi_spheres as ts  # noqa: E402
from taichi_spheres import observe  # noqa: E402
from taichi_spheres.builders import gas  # noqa: E402
from taichi_spheres.reference import EventDrivenReference  # noqa: E402
from machine import cpu_name  # noqa: E402  (tools/machine.py)

FRACTIONS = (0.3, 0.1, 0.03, 0.01, 0.003, 0.001)
QUICK_FRACTIONS = (0.3, 0.03, 0.003)
F32_FRACTIONS = (0.1, 0.01)
THRESHOLDS = (1e-6, 1e-9)


# ---- scenes ----
def scene_traj():
    return gas(64, packing=0.1, periodic=False, gravity=(0.0, 0.0, 0.0), seed=0)


def scene_gravity():
    base = gas(64, packing=0.1, periodic=False, gravity=(0.0, 0.0, 0.0), seed=0)
    side = float(base.box_hi[0] - base.box_lo[0])
    lift = 5.0
    x = np.array(base.x)
    x[:, 2] += lift
    hi = np.array(base.box_hi, dtype=float)
    hi[2] += lift
    return ts.Scene.from_arrays(x, base.v, base.radius, mass=base.mass,
                                box=(tuple(base.box_lo), tuple(hi)), periodic=(False,) * 3,
                                gravity=(0.0, 0.0, -9.81), restitution=0.9,
                                wall_restitution=0.9, name="gas64-falling"), side


BOUNCE_R = 0.2
BOUNCE_H0 = 1.0
BOUNCE_E = 0.8
BOUNCE_G = 9.81
BOUNCE_K = 3


def scene_bounce():
    x = [[0.5, 0.5, BOUNCE_R + BOUNCE_H0]]
    return ts.Scene.from_arrays(x, [[0.0, 0.0, 0.0]], BOUNCE_R, box=((0, 0, 0), (1, 1, 2)),
                                periodic=(False,) * 3, gravity=(0, 0, -BOUNCE_G),
                                restitution=1.0, wall_restitution=BOUNCE_E, name="ball")


def bounce_apexes():
    """(time, centre height) of the apex after each of the first BOUNCE_K bounces."""
    g, e = BOUNCE_G, BOUNCE_E
    v0 = math.sqrt(2.0 * g * BOUNCE_H0)
    t = v0 / g                       # first floor contact
    out = []
    for k in range(1, BOUNCE_K + 1):
        vk = e ** k * v0
        out.append((t + vk / g, BOUNCE_R + e ** (2 * k) * BOUNCE_H0))
        t += 2.0 * vk / g            # next floor contact
    return out


# ---- engine runs ----
def make_sim(scene, precision, fraction):
    """A Simulation of ``scene`` with its kernels compiled, at t = 0 (warm_up)."""
    return warm_up(ts.Simulation(scene, arch="cpu", precision=precision,
                                 step_fraction=fraction))


def warm_up(sim):
    """Compile every kernel ``sim`` will need, then restore it to t = 0 with
    ``sim_seconds`` reset, so that its timing excludes compilation. Returns sim."""
    scene = sim.scene
    ckpt = sim.checkpoint()
    walls = not all(scene.periodic)
    # warm-up: compile every kernel the run will need (sweep kernels compile on the
    # first collision), then go back to t = 0
    for _ in range(400):
        sim.advance(sim.max_step() * 10)
        st = sim.stats
        if (st["pair_collisions"] > 0 or scene.n < 2) and (st["wall_collisions"] > 0
                                                           or not walls):
            break
    sim.restore(ckpt)
    sim.sim_seconds = 0.0
    return sim


class LocalRuns:
    """The engine runs of a case here, one after another."""

    def rows(self, scene, settings, measure) -> list[dict]:
        """One row per (precision, step_fraction) of ``settings``: ``measure(sim)``
        (a dict: seconds, error, extra) with the setting added."""
        rows = []
        for prec, f in settings:
            sim = ts.Simulation(scene, arch="cpu", precision=prec, step_fraction=f)
            rows.append(dict(precision=prec, fraction=f, **measure(sim)))
        return rows


def _in_row(measure, sim):
    """measure(sim) under one key of a sweep's row (its own keys would mix with the
    row's, "error" among them)."""
    return {"result": measure(sim)}


class DaskRuns:
    """The engine runs of a case through ``ts.sweep`` on a Dask cluster (``client``:
    a distributed.Client): one run per setting, one Taichi thread each, optimized
    compile as here; each run is warmed up in its worker before it is timed."""

    def __init__(self, client):
        self.client = client

    def rows(self, scene, settings, measure) -> list[dict]:
        """As LocalRuns.rows; RuntimeError naming the setting of a run that failed."""
        rows = []
        for prec in dict.fromkeys(p for p, _ in settings):        # in order, f64 first
            fractions = [f for p, f in settings if p == prec]
            for row in ts.sweep(scene, {"precision": [prec], "step_fraction": fractions},
                                0.0, measure=functools.partial(_in_row, measure),
                                client=self.client, threads=1, compile="optimized"):
                if row["error"] is not None:
                    raise RuntimeError(f"{scene.name}, {prec}, step_fraction "
                                       f"{row['step_fraction']:g}: {row['error']}")
                rows.append(dict(precision=prec, fraction=row["step_fraction"],
                                 **row["result"]))
        return rows


def engine_rows(case, runs, scene, settings, measure):
    """Append the engine rows of ``settings`` (run by ``runs``) to case.rows, printing
    each; returns case."""
    for row in runs.rows(scene, settings, measure):
        case.rows.append(row)
        report(case, row)
    return case


def timed_reference(scene, t):
    t0 = time.perf_counter()
    ref = EventDrivenReference(scene)
    ref.advance_to(t)
    return ref, time.perf_counter() - t0


def perturbed(scene, eps, scale):
    """The scene with sphere 0 moved by eps * scale [m] along x."""
    x = np.array(scene.x, dtype=float)
    x[0, 0] += eps * scale
    return ts.Scene.from_arrays(x, scene.v, scene.radius, mass=scene.mass,
                                box=(tuple(scene.box_lo), tuple(scene.box_hi)),
                                periodic=tuple(scene.periodic), gravity=tuple(scene.gravity),
                                restitution=scene.restitution,
                                wall_restitution=scene.wall_restitution)


def chaos_check(scene, t, scale, eps=1e-12):
    """max |x_ref - x_ref'| / scale at t, where ' has sphere 0 moved by eps * scale:
    how much the dynamics itself amplifies a round-off-sized perturbation."""
    other = perturbed(scene, eps, scale)
    a = EventDrivenReference(scene)
    a.advance_to(t)
    b = EventDrivenReference(other)
    b.advance_to(t)
    return float(np.abs(a.state().x - b.state().x).max() / scale)


class Case:
    def __init__(self, name, title, metric):
        self.name, self.title, self.metric = name, title, metric
        self.rows = []        # dict(precision, fraction, seconds, error, extra)
        self.ref_seconds = None
        self.note = ""


def trajectory_error(sim, T, xr, side, counter):
    """Warm ``sim`` up and run it to time T [s]: the error is max |x - x_ref| / side;
    ``counter`` names the stat shown beside the pair count."""
    label = {"steps": "steps", "wall_rests": "rests"}[counter]
    warm_up(sim).advance_to(T)
    err = float(np.abs(sim.state().x - xr).max() / side)
    return dict(seconds=sim.sim_seconds, error=err,
                extra=f"pairs {sim.stats['pair_collisions']}, {label} {sim.stats[counter]}")


def run_traj(settings, runs=LocalRuns()):
    case = Case("traj", "Trajectory, elastic gas N=64, walls, t = 2 s",
                "max |x - x_ref| / box side")
    scene = scene_traj()
    side = float(scene.box_hi[0] - scene.box_lo[0])
    T = 2.0
    ref, case.ref_seconds = timed_reference(scene, T)
    xr = ref.state().x
    case.note = f"reference: {ref.stats['pair_collisions']} pair, " \
                f"{ref.stats['wall_collisions']} wall collisions; chaos check: a 1e-12 " \
                f"perturbation of the start grows to {chaos_check(scene, T, side):.1e} by t = {T:g}"
    return engine_rows(case, runs, scene, settings, functools.partial(
        trajectory_error, T=T, xr=xr, side=side, counter="steps"))


def run_gravity(settings, runs=LocalRuns()):
    case = Case("gravity", "Trajectory under gravity, gas N=64 falling, e = e_w = 0.9, "
                "t = 1.2 s", "max |x - x_ref| / box width")
    scene, side = scene_gravity()
    T = 1.2
    ref, case.ref_seconds = timed_reference(scene, T)
    xr = ref.state().x
    st = ref.stats
    case.note = f"reference: {st['pair_collisions']} pair, {st['wall_collisions']} wall " \
                f"collisions, {st['wall_rests']} wall rests; chaos check: a 1e-12 " \
                f"perturbation of the start grows to {chaos_check(scene, T, side):.1e} by t = {T:g}"
    return engine_rows(case, runs, scene, settings, functools.partial(
        trajectory_error, T=T, xr=xr, side=side, counter="wall_rests"))


def count_errors(sim, T, n_ref, e0, xr, side):
    """Warm ``sim`` up and run it to time T [s]: the larger of the pair-count error
    against n_ref and the energy error against e0 [J]; x err against xr [m] beside."""
    warm_up(sim).advance_to(T)
    gravity = sim.scene.gravity
    n_err = abs(sim.stats["pair_collisions"] - n_ref) / n_ref
    e_err = abs(observe.total_energy(sim.state(), gravity) - e0) / e0
    return dict(seconds=sim.sim_seconds, error=max(n_err, e_err),
                extra=f"count {n_err:.2e}, energy {e_err:.2e}, x err "
                      f"{np.abs(sim.state().x - xr).max() / side:.1e}")


def run_counts(settings, T, runs=LocalRuns()):
    case = Case("counts", f"Collision count and energy, elastic gas N=64, walls, t = {T:g} s",
                "max(|N - N_ref| / N_ref, |E - E0| / E0)")
    scene = scene_traj()
    ref, case.ref_seconds = timed_reference(scene, T)
    n_ref = ref.stats["pair_collisions"]
    e0 = observe.total_energy(scene_state(scene), scene.gravity)
    side = float(scene.box_hi[0] - scene.box_lo[0])
    xr = ref.state().x
    case.note = f"reference: {n_ref} pair collisions; chaos check: a 1e-12 perturbation " \
                f"of the start grows to {chaos_check(scene, T, side):.1e} by t = {T:g}. " \
                "The error column is the larger of the count and energy errors; 'x err' " \
                "(max |x - x_ref| / box side) shows how far the trajectory has diverged"
    return engine_rows(case, runs, scene, settings, functools.partial(
        count_errors, T=T, n_ref=n_ref, e0=e0, xr=xr, side=side))


def apex_error(sim, apexes):
    """Warm ``sim`` up and advance it to each apex time: max_k |z - z_apex,k| / h0."""
    warm_up(sim)
    err = 0.0
    for t, z in apexes:
        sim.advance_to(t)
        err = max(err, abs(float(sim.state().x[0, 2]) - z) / BOUNCE_H0)
    return dict(seconds=sim.sim_seconds, error=err, extra=f"steps {sim.stats['steps']}")


def run_bounce(settings, runs=LocalRuns()):
    case = Case("bounce", f"Bounce apex heights, one ball, e_w = {BOUNCE_E}, "
                f"{BOUNCE_K} bounces", "max_k |z - z_apex,k| / h0")
    scene = scene_bounce()
    apexes = bounce_apexes()
    case.ref_seconds = None
    case.note = "closed form, no reference run"
    return engine_rows(case, runs, scene, settings,
                       functools.partial(apex_error, apexes=apexes))


PRESSURE_N = 125
PRESSURE_PACKING = 0.25
PRESSURE_T = 1.0


def scene_pressure():
    return gas(PRESSURE_N, packing=PRESSURE_PACKING, periodic=True, seed=0)


def kinetic_energy(st):
    """Kinetic energy [J] of a State."""
    return 0.5 * float(np.sum(st.mass[:, None] * st.v ** 2))


def virial_pressure(scene, ke, virial, t):
    """Pressure [Pa] of an elastic gas: (N k T + W / (3 t)) / V with N k T = (2/3) KE,
    ke the kinetic energy [J], virial W the sum over the pair collisions of a run of
    t [s] of r_ij . dp_i [kg m^2/s], V the box volume [m^3]."""
    volume = float(np.prod(scene.box_size))
    return (2.0 / 3.0 * ke + virial / (3.0 * t)) / volume


def carnahan_starling(scene, ke):
    """Carnahan-Starling pressure [Pa] at the scene's packing fraction and the
    temperature given by the kinetic energy ke [J]: n k T (1+eta+eta^2-eta^3)/(1-eta)^3."""
    volume = float(np.prod(scene.box_size))
    eta = float(np.sum(4.0 / 3.0 * math.pi * np.asarray(scene.radius) ** 3)) / volume
    return 2.0 / 3.0 * ke / volume * (1 + eta + eta ** 2 - eta ** 3) / (1 - eta) ** 3


NO_VIRIAL = "engine virial not available"


def pressure_error(sim, T, p_ref):
    """Warm ``sim`` up and run it to time T [s]: |P - p_ref| / p_ref of the virial
    pressure [Pa] (NaN where the engine has no virial)."""
    warm_up(sim)
    w0 = sim.stats.get("virial", 0.0)
    sim.advance_to(T)
    stats = sim.stats
    pairs = f"pairs {stats['pair_collisions']}"
    if "virial" not in stats:
        return dict(seconds=sim.sim_seconds, error=math.nan, extra=f"{NO_VIRIAL}; {pairs}")
    p = virial_pressure(sim.scene, kinetic_energy(sim.state()), stats["virial"] - w0, T)
    return dict(seconds=sim.sim_seconds, error=abs(p - p_ref) / p_ref,
                extra=f"P {p:.6g} Pa, {pairs}")


def run_pressure(settings, runs=LocalRuns()):
    T = PRESSURE_T
    case = Case("pressure", f"Virial pressure, periodic elastic gas N={PRESSURE_N}, "
                f"packing {PRESSURE_PACKING:g}, t = {T:g} s", "|P - P_ref| / P_ref")
    scene = scene_pressure()
    ref, case.ref_seconds = timed_reference(scene, T)
    ke_ref = kinetic_energy(ref.state())
    p_ref = virial_pressure(scene, ke_ref, ref.virial, T)
    p_cs = carnahan_starling(scene, ke_ref)
    other = EventDrivenReference(perturbed(scene, 1e-12, float(scene.box_size[0])))
    other.advance_to(T)
    p_other = virial_pressure(scene, kinetic_energy(other.state()), other.virial, T)
    st = ref.stats
    z_ref = p_ref / virial_pressure(scene, ke_ref, 0.0, T)
    case.note = (f"reference: {st['pair_collisions']} pair collisions "
                 f"({2 * st['pair_collisions'] / scene.n:.1f} per sphere), P_ref = "
                 f"{p_ref:.6g} Pa, P_ref V / N k T = {z_ref:.4f}; "
                 f"Carnahan-Starling (information only, equilibrium, N -> inf): "
                 f"{p_cs:.6g} Pa ({p_ref / p_cs - 1:+.1%} from P_ref; this run starts "
                 f"from a lattice and lasts a few collision times); chaos check: a 1e-12 "
                 f"perturbation of the start changes P_ref by "
                 f"{abs(p_other - p_ref) / p_ref:.1e}")
    return engine_rows(case, runs, scene, settings,
                       functools.partial(pressure_error, T=T, p_ref=p_ref))


# ---- reference vs engine speed ----
SPEED_PACKING = 0.35
SPEED_SIZES = (125, 500, 2000)
SPEED_T = 0.5
SPEED_FRACTIONS = (0.1, 0.003)


def reference_rate(scene, horizon, budget):
    """Run the reference towards ``horizon`` [s] in steps of horizon/200, stopping once
    ``budget`` wall seconds have been spent advancing. Returns (construction wall
    seconds, advance wall seconds, simulated seconds reached, pair collisions)."""
    t0 = time.perf_counter()
    ref = EventDrivenReference(scene)
    build = time.perf_counter() - t0
    t1 = time.perf_counter()
    chunk = horizon / 200.0
    while ref.time < horizon and time.perf_counter() - t1 < budget:
        ref.advance_to(min(ref.time + chunk, horizon))
    return build, time.perf_counter() - t1, ref


def periodic_x_error(a, b, side):
    """max |a - b| / side over positions [m] on a periodic cube of that side [m]."""
    d = a - b
    d -= side * np.round(d / side)
    return float(np.abs(d).max() / side)


def run_speed(sizes, horizon, budget):
    """Dense periodic elastic gases (packing SPEED_PACKING): the reference's and the
    engine's (f64, each of SPEED_FRACTIONS) wall seconds per simulated second, and the
    engine's max |x - x_ref| / box side at the time the reference reached."""
    rows = []
    for n in sizes:
        scene = gas(n, packing=SPEED_PACKING, periodic=True, seed=0)
        build, run, ref = reference_rate(scene, horizon, budget)
        reached, pairs = ref.time, ref.stats["pair_collisions"]
        side = float(scene.box_size[0])
        row = dict(n=n, ref_build=build, ref_run=run, ref_t=reached, ref_pairs=pairs,
                   ref_rate=run / reached if reached > 0 else math.inf, engine={})
        for f in SPEED_FRACTIONS:
            sim = make_sim(scene, "f64", f)
            err = None
            if reached > 0:
                sim.advance_to(reached)
                err = periodic_x_error(sim.state().x, ref.state().x, side)
            sim.advance_to(horizon)
            row["engine"][f] = (sim.sim_seconds / horizon, err)
        rows.append(row)
        eng = ", ".join(f"engine {f:g}: {r:.3g} s/s (x err {e})"
                        for f, (r, e) in row["engine"].items())
        print(f"  speed N={n}: reference {row['ref_rate']:.3g} s/s (reached t = {reached:.3g} "
              f"in {run:.1f} s, {pairs} pairs, built in {build:.2f} s); {eng}", flush=True)
    return rows


def cheapest_below(case, thr):
    """The f64 row of the lowest engine seconds with error < thr, or None."""
    ok = [r for r in case.rows if r["precision"] == "f64" and r["error"] < thr]
    return min(ok, key=lambda r: r["seconds"]) if ok else None


def speed_lines(cases, speed, horizon, budget):
    """Markdown lines of the 'Reference vs engine speed' section."""
    lines = ["", "## Reference vs engine speed", "",
             "Wall seconds on this machine, f64. The reference's time includes building "
             "its event tables; the engine's excludes compilation.", "",
             "Same cases as above: the reference against the engine at the cheapest "
             "setting that reaches 1e-6 (the reference is exact).", "",
             "| case | reference s | engine s (cheapest error < 1e-6) | at step_fraction | "
             "faster |", "|---|---|---|---|---|"]
    for c in cases:
        if c.ref_seconds is None:
            continue
        best = cheapest_below(c, 1e-6)
        if unavailable(c):
            fastest = min(r["seconds"] for r in c.rows if r["precision"] == "f64")
            lines.append(f"| {c.name} | {c.ref_seconds:.3f} | {NO_VIRIAL} (fastest run "
                         f"{fastest:.3f}) | - | - |")
            continue
        if best is None:
            lines.append(f"| {c.name} | {c.ref_seconds:.3f} | not reached | - | reference |")
            continue
        a, b = c.ref_seconds, best["seconds"]
        faster = "reference" if a < b else "engine"
        lines.append(f"| {c.name} | {a:.3f} | {b:.3f} | {best['fraction']:g} | "
                     f"{faster} ({max(a, b) / min(a, b):.1f}x) |")
    if not speed:
        return lines
    fr = SPEED_FRACTIONS
    lines += ["", f"Denser, larger gases: periodic elastic gas at packing {SPEED_PACKING:g} "
              f"(`gas(N, packing={SPEED_PACKING:g}, periodic=True, seed=0)`), engine run to "
              f"t = {horizon:g} s, reference stopped after {budget:g} wall seconds of "
              "advancing (or at the same t). Seconds per simulated second; the reference "
              "builds its N x N event table first ('build s'). step_fraction "
              f"{fr[0]:g} is the default (statistics), {fr[-1]:g} the setting the dilute "
              "cases above need to follow the exact trajectories over ~5 collisions per "
              "sphere; 'x err' is the engine's max |x - x_ref| / box side at the time "
              "the reference reached.", "",
             "| N | reference build s | reference s / sim s | reference reached t | "
             "reference pairs | " + " | ".join(f"engine {f:g} s / sim s" for f in fr)
             + " | reference / engine " + " | reference / engine ".join(f"{f:g}" for f in fr)
             + " | " + " | ".join(f"x err {f:g}" for f in fr) + " |",
             "|---:|---:|---:|---:|---:|" + "---:|" * (3 * len(fr))]
    for r in speed:
        eng = [r["engine"][f][0] for f in fr]
        errs = ["-" if r["engine"][f][1] is None else f"{r['engine'][f][1]:.1e}" for f in fr]
        lines.append(f"| {r['n']} | {r['ref_build']:.2f} | {r['ref_rate']:.3g} | "
                     f"{r['ref_t']:.3g} | {r['ref_pairs']} | "
                     + " | ".join(f"{e:.3g}" for e in eng) + " | "
                     + " | ".join(f"{r['ref_rate'] / e:.3g}" for e in eng) + " | "
                     + " | ".join(errs) + " |")
    return lines


def scene_state(scene):
    return ts.State(x=np.asarray(scene.x, float), v=np.asarray(scene.v, float),
                    radius=np.asarray(scene.radius, float), mass=np.asarray(scene.mass, float),
                    time=0.0)


def report(case, row):
    print(f"  {case.name:8s} {row['precision']} step_fraction {row['fraction']:<6g} "
          f"{row['seconds']:8.3f} s  error {row['error']:.3e}  ({row['extra']})", flush=True)


# ---- summary ----
def unavailable(case):
    """True when a case has no engine error to show (engine virial not available)."""
    return any(math.isnan(r["error"]) for r in case.rows if r["precision"] == "f64")


def first_below(case, thr):
    if unavailable(case):
        return NO_VIRIAL
    for r in case.rows:
        if r["precision"] == "f64" and r["error"] < thr:
            return f"{r['fraction']:g}"
    return "not reached"


#: below this, growth of the error with the number of steps is taken as accumulated
#: round-off (1e-16 per step x ~1e4 steps x the chaos check's amplification)
ROUNDOFF = 1e-10


def monotone_note(case):
    if unavailable(case):
        return NO_VIRIAL
    f64 = [r for r in case.rows if r["precision"] == "f64"]
    pairs = [(a, b) for a, b in zip(f64, f64[1:]) if b["error"] >= a["error"]]
    bad = [(a, b) for a, b in pairs if b["error"] > ROUNDOFF]
    slow = [(a, b) for a, b in pairs if b["error"] <= ROUNDOFF and b["error"] > 1.5 * a["error"]]
    txt = lambda ps: "; ".join(f"{a['error']:.1e} at {a['fraction']:g} -> "
                               f"{b['error']:.1e} at {b['fraction']:g}" for a, b in ps)
    parts = []
    if bad:
        parts.append("error does NOT decrease as step_fraction tightens: " + txt(bad))
    if slow:
        parts.append("at round-off level the error grows with the number of steps: "
                     + txt(slow))
    return " ".join(parts) or "errors decrease as step_fraction tightens"


NOTES = """
- **Missed collisions dominate, not integration error.** Between collisions the
  engine's drift is the exact ballistic path and every resolved collision is rewound
  to contact, so with no missed collision the error is round-off. Large errors (~0.1)
  mean a pair collision the engine did not see or resolved differently (compare the
  pair counts with the reference's); there is nothing in between.
- **traj** (elastic gas with walls, 2 s) follows the exact reference to round-off at
  every step_fraction, 0.3 included: a pair is collided only when it is the earliest
  detected contact of both its spheres, and pairs the step carried past their closest
  approach are collided too, so the colours do not reorder a sphere's collisions.
- **gravity** (e = 0.9 under gravity) still misses or reorders a collision at 0.3 and
  0.1 and is at round-off from 0.03 on.
- **counts** (same gas as traj, 5 s) misses one collision after t = 2 s at every
  setting down to 0.01 (x err ~0.8 afterwards: the gas is chaotic); only 0.003 and 0.001
  follow the reference to t = 5 s (x err ~1e-6, the chaos-amplified round-off the chaos
  check predicts). A setting that "first reaches" a threshold in a short run is
  therefore optimistic for long runs.
- **Below ~1e-10 the error grows as the settings tighten**: more steps, more round-off,
  amplified by the gas (see the chaos check). That is the f64 floor for these horizons.
- **Energy** is conserved to round-off (~1e-15) in f64 at every setting, even when a
  collision is missed; in f32 to ~1e-6.
- **bounce** does not discriminate between settings: wall contacts are rewound exactly
  on the parabola, so apex heights are exact to round-off (f64) or ~1e-6 (f32) at every
  step_fraction. It confirms the wall rewind, not the step control.
- **f32** rows are limited by f32 round-off (~1e-7) amplified by the collisions.
- **pressure** (periodic elastic gas, N = 125, packing 0.25, 1 s, ~7 collisions per
  sphere): the reference gives P V / N k T = 3.069, Carnahan-Starling 3.074 (-0.2 %;
  information only: a lattice start, a few collision times, finite N). The virial
  pressure is a robust statistic: a 1e-12 perturbation of the start changes it by
  ~3e-13. Engine rows show "engine virial not available" where the engine has no
  ``stats["virial"]`` yet (timings only).
- **Reference vs engine speed.** The reference's cost per event grows with N (an
  O(N) update of the rows of the two spheres and an O(N^2) argmin over the pair
  table), and the events per simulated second grow with N, so at fixed packing its
  seconds per simulated second grow roughly as N^2 to N^3 (0.5-0.9 s at N = 125,
  3-8 s at N = 500, 60-100 s at N = 2000, packing 0.35, across runs on this VM),
  while the engine's grow slowly (its small-N cost is kernel launches). The
  reference is faster on the dilute N = 64 cases whenever they need step_fraction
  0.03 or finer, and it is about even with the engine at 0.003 at N = 125 (packing
  0.35; either is ahead by up to 1.2x depending on the run); from N = 500 the engine
  is faster even at 0.003 (about 4x at N = 500, about 40x at N = 2000) and about 30x,
  80x and 700x faster at the default 0.1 (N = 125, 500, 2000), which is what
  statistics need. The dense gases are followed to round-off at 0.003 (x err
  column); at 0.1 they diverge (collisions missed or reordered), as in the dilute
  cases.
"""


def write_markdown(path, cases, command, elapsed, speed=None, speed_args=None,
                   png=None):
    now = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
    lines = ["# Work-precision", "",
             f"- date: {now}",
             f"- machine: {cpu_name()}, {os.cpu_count()} CPU threads (arch cpu)",
             f"- command: `{command}`",
             f"- total tool run time: {elapsed:.0f} s", "",
             "Seconds are `Simulation.sim_seconds` (wall time inside `advance_to`), "
             "excluding Taichi compilation: each Simulation is first advanced until it "
             "has done pair and wall collisions (compiling every kernel the run uses), "
             "then restored to its t = 0 checkpoint with `sim_seconds` reset. "
             "\"ref s\" is the exact event-driven numpy reference's own run time for "
             "the same case (construction + advance).", ""]
    if png:
        lines += [f"![error against engine seconds]({os.path.basename(png)})", "",
                  f"`{os.path.basename(png)}`: error against engine seconds, log-log, made by "
                  f"the command above (`{command}`); one colour per case, f64 solid with "
                  "circles, f32 dashed with squares; errors of exactly 0 are drawn at 1e-17.",
                  ""]
    lines += ["## Summary", "",
             "| case | ref s | error < 1e-6 first at step_fraction | error < 1e-9 first at "
             "step_fraction | behaviour |",
             "|---|---|---|---|---|"]
    for c in cases:
        ref = "-" if c.ref_seconds is None else f"{c.ref_seconds:.3f}"
        lines.append(f"| {c.name} | {ref} | {first_below(c, 1e-6)} | {first_below(c, 1e-9)} "
                     f"| {monotone_note(c)} |")
    lines.append("")
    lines.append("(thresholds and the behaviour column use the f64 rows only; an increase "
                 f"that stays below {ROUNDOFF:g} is listed as round-off growth)")
    if speed is not None:
        lines += speed_lines(cases, speed, *speed_args)
    lines += ["", "## Notes (on the run recorded here)", "", NOTES.strip()]
    for c in cases:
        lines += ["", f"## {c.name}: {c.title}", "", f"Error: {c.metric}. {c.note}.", "",
                  "| precision | step_fraction | seconds | error | details |",
                  "|---|---|---|---|---|"]
        for r in c.rows:
            err = "n/a" if math.isnan(r["error"]) else f"{r['error']:.2e}"
            lines.append(f"| {r['precision']} | {r['fraction']:g} | {r['seconds']:.3f} | "
                         f"{err} | {r['extra']} |")
        if c.ref_seconds is not None:
            lines.append(f"| reference | exact | {c.ref_seconds:.3f} | 0 | event-driven numpy |")
    with open(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")


def write_plot(path, cases):
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except Exception:
        return False
    fig, ax = plt.subplots(figsize=(7, 5))
    for k, c in enumerate(cases):
        colour = f"C{k}"
        for prec, style in (("f64", "o-"), ("f32", "s--")):
            rows = [r for r in c.rows if r["precision"] == prec and not math.isnan(r["error"])]
            if not rows:
                continue
            ax.loglog([max(r["seconds"], 1e-4) for r in rows],
                      [max(r["error"], 1e-17) for r in rows], style, color=colour,
                      label=f"{c.name} {prec}", mfc="none" if prec == "f32" else colour)
    missing = [c.name for c in cases if unavailable(c)]
    if missing:
        ax.text(0.02, 0.02, f"{', '.join(missing)}: {NO_VIRIAL}", transform=ax.transAxes,
                fontsize=8)
    ax.set_xlabel("engine seconds (Simulation.sim_seconds)")
    ax.set_ylabel("error (see each case)")
    ax.set_title("work-precision: engine vs exact answers (cpu)")
    ax.legend(fontsize=8, ncol=2)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    return True


@contextlib.contextmanager
def engine_runs(workers, scheduler):
    """LocalRuns, or DaskRuns on the scheduler at ``scheduler`` or on a LocalCluster of
    ``workers`` processes (closed at the end)."""
    if not workers and not scheduler:
        yield LocalRuns()
        return
    from distributed import Client, LocalCluster
    cluster = None if scheduler else LocalCluster(
        n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None)
    client = Client(scheduler or cluster)
    try:
        print(f"engine runs on Dask: {scheduler or f'local cluster of {workers} workers'}",
              flush=True)
        yield DaskRuns(client)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def run_all(names, fractions, f32, counts_T, sizes, budget, runs):
    """The cases ``names`` (f64 at ``fractions``, then f32 at ``f32``) with their engine
    runs on ``runs``, and the speed rows of ``sizes`` (run here); (cases, speed)."""
    runners = dict(traj=run_traj, gravity=run_gravity,
                   counts=lambda s, r: run_counts(s, counts_T, r), bounce=run_bounce,
                   pressure=run_pressure)
    # all f64 runs first: switching precision re-initialises Taichi
    cases = []
    for name in names:
        print(f"{name}:", flush=True)
        cases.append(runners[name]([("f64", f) for f in fractions], runs))
    speed = None
    if sizes:
        print("reference vs engine speed:", flush=True)
        speed = run_speed(sizes, SPEED_T, budget)
    if f32:
        for name, c in zip(names, cases):
            print(f"{name} (f32):", flush=True)
            extra = runners[name]([("f32", f) for f in f32], runs)
            c.rows += extra.rows
    return cases, speed


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer settings, shorter runs")
    ap.add_argument("--fractions", type=float, nargs="+", default=None)
    ap.add_argument("--no-f32", action="store_true", help="skip the f32 rows")
    names = ["traj", "gravity", "counts", "bounce", "pressure"]
    ap.add_argument("--cases", nargs="+", default=names, choices=names)
    ap.add_argument("--speed-sizes", type=int, nargs="*", default=None,
                    help=f"N of the reference-vs-engine speed gases [{SPEED_SIZES}; "
                         "--quick: the first two]; none given: skip")
    ap.add_argument("--speed-budget", type=float, default=None,
                    help="wall seconds the reference may advance per speed gas [40; --quick 5]")
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "work_precision.md"))
    ap.add_argument("--no-write", action="store_true")
    ap.add_argument("--workers", type=int, default=0,
                    help="run the engine runs of each case through ts.sweep on a local Dask "
                         "cluster of this many worker processes (one Taichi thread each); "
                         "0: here, one after another [0]")
    ap.add_argument("--scheduler", default=None, metavar="ADDRESS",
                    help="run the engine runs on the Dask scheduler at ADDRESS "
                         "(tcp://host:8786) instead")
    args = ap.parse_args(argv)
    fractions = tuple(args.fractions or (QUICK_FRACTIONS if args.quick else FRACTIONS))
    f32 = () if args.no_f32 else ((F32_FRACTIONS[:1]) if args.quick else F32_FRACTIONS)
    counts_T = 4.0 if args.quick else 5.0
    command = "python tools/work_precision.py" + (" " + " ".join(sys.argv[1:])
                                                   if argv is None and sys.argv[1:] else "")
    t_start = time.perf_counter()
    sizes = args.speed_sizes if args.speed_sizes is not None else \
        (SPEED_SIZES[:2] if args.quick else SPEED_SIZES)
    budget = args.speed_budget or (5.0 if args.quick else 40.0)
    with engine_runs(args.workers, args.scheduler) as runs:
        cases, speed = run_all(args.cases, fractions, f32, counts_T, sizes, budget, runs)
    elapsed = time.perf_counter() - t_start
    print(f"total {elapsed:.1f} s")
    for c in cases:
        print(f"  {c.name}: ref {c.ref_seconds}, <1e-6 at {first_below(c, 1e-6)}, "
              f"<1e-9 at {first_below(c, 1e-9)}; {monotone_note(c)}")
    if not args.no_write:
        os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
        png = os.path.splitext(args.out)[0] + ".png"
        if write_plot(png, cases):
            print(f"wrote {png}")
        else:
            png = None
            print("matplotlib not importable: no plot (pip install -e .[plot])")
        write_markdown(args.out, cases, command, elapsed, speed, (SPEED_T, budget), png)
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
