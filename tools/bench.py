#!/usr/bin/env python3
"""Scale benchmark: elastic gas at packing fraction 0.3 (periodic cube), N = 1e3 ... 1e6.

Per N and precision: sphere-steps/s, collisions/s, simulated seconds per wall second,
measured memory per sphere (process RSS delta around building and first stepping a
Simulation; the bytes of its Taichi fields as a cross-check), the cost of each stage of
one step (drift + walls, grid build, detection, resolve sweeps; a rendered frame with
--render) against the full step, the full step against a bare grid pass, how the cost
grows with N (fitted exponent), and the effect of each compiled-out feature.
Writes docs/bench.md (date, hardware, the command) unless --no-write or --quick.

    python tools/bench.py                  # CPU, N = 1e3 ... 1e6, f64 and f32 (~15 min, 2 cores)
    python tools/bench.py --quick          # N = 1e3, 1e4, short timing, writes nothing
    python tools/bench.py --render         # also time one rendered frame (needs Vulkan)
    python tools/bench.py --arch cuda --sizes 1000000 10000000
"""
from __future__ import annotations

import argparse
import dataclasses
import gc
import os
import sys
import time
from unittest import mock

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import taichi as ti  # noqa: E402

import taichi_spheres as ts  # noqa: E402
from taichi_spheres import runtime as ts_runtime  # noqa: E402
from taichi_spheres.builders import gas  # noqa: E402
from taichi_spheres.state import Features  # noqa: E402
import bench_report  # noqa: E402  (tools/bench_report.py)
from machine import kept_sections  # noqa: E402  (tools/machine.py)

DEFAULT_SIZES = [1_000, 10_000, 100_000, 1_000_000]
QUICK_SIZES = [1_000, 10_000]
#: stages of one step, in the order Simulation.step runs them; "counters" is the step's
#: reading back of its counters (Python reads of small fields, one sync each)
STAGES = ("drift", "grid", "detect", "sweeps", "counters")
#: one feature compiled in at a time (the scene does not need it: same results)
FEATURE_FLIPS = (
    ("gravity", "no gravity (compiled out) vs gravity compiled in, g = 0",
     dict(gravity_axes=(True, True, True))),
    ("radii", "equal radii (one constant) vs per-sphere radius field, all equal",
     dict(equal_radii=False)),
    ("restitution", "e = 1 (compiled out) vs restitution compiled in, e = 1",
     dict(elastic=False)),
)


# ---- memory ----
def rss_bytes() -> int | None:
    """Resident set size of this process [bytes], from /proc/self/statm (None if absent)."""
    try:
        with open("/proc/self/statm") as fh:
            return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return None


def build(make_sim, warm_steps=3):
    """Build a Simulation with ``make_sim()`` and take ``warm_steps`` steps (compiling
    its kernels). Returns (sim, info): compile_s [s] (build + warm-up), rss_build and
    rss_warm [bytes] (RSS growth after building, and after the warm-up steps too;
    None without /proc), fields [bytes]."""
    gc.collect()
    r0 = rss_bytes()
    t0 = time.perf_counter()
    sim = make_sim()
    r1 = rss_bytes()
    for _ in range(warm_steps):
        sim.step(sim.max_step())
    ti.sync()
    compile_s = time.perf_counter() - t0
    r2 = rss_bytes()
    grow = (lambda r: None if r0 is None else r - r0)
    return sim, dict(compile_s=compile_s, rss_build=grow(r1), rss_warm=grow(r2),
                     fields=sim.field_bytes())


# ---- other guests on the machine ----
def cpu_jiffies():
    """(steal, total) CPU time of the whole machine since boot [jiffies], from the
    ``cpu`` line of /proc/stat (None without it). Steal is time the hypervisor gave to
    other guests while this one had work to run."""
    try:
        with open("/proc/stat") as fh:
            fields = [int(v) for v in fh.readline().split()[1:]]
    except (OSError, ValueError):
        return None
    return (fields[7], sum(fields[:8])) if len(fields) >= 8 else None


def steal_share(before, after):
    """Share of the machine's CPU time stolen between two cpu_jiffies() readings (None
    when either is missing or no time passed)."""
    if before is None or after is None or after[1] <= before[1]:
        return None
    return (after[0] - before[0]) / (after[1] - before[1])


# ---- stage timing ----
def _timed(times, stage, fn, *args):
    """Run fn(*args), ti.sync(), add the wall seconds to times[stage]; return its result."""
    t0 = time.perf_counter()
    out = fn(*args)
    ti.sync()
    times[stage] += time.perf_counter() - t0
    return out


def _status(packed: int) -> tuple:
    """(remaining, rebuild) of the i32 a detection or sweep kernel of
    ``debug_view().contacts`` returns: 2 x remaining approaching overlaps + 1 when a
    sphere moved past the grid's slack (contacts.Status, as Simulation.step reads it)."""
    return packed >> 1, bool(packed & 1)


def staged_step(sim, h, times) -> int:
    """One step of length h [s] run stage by stage with the kernels and the loop of
    Simulation.step, with ti.sync() after each stage; adds wall seconds per stage to
    ``times`` (keys STAGES) and returns the sweeps run. sim.stats is left alone; a
    re-binning inside the sweep loop counts as grid build and detection."""
    view = sim.debug_view()
    motion, grid, contacts, params = view.motion, view.grid, view.contacts, view.params

    def drift():
        params.h[None] = h
        motion.drift()

    ti.sync()
    _timed(times, "drift", drift)
    _timed(times, "grid", grid.build)
    remaining, _ = _status(_timed(times, "detect", contacts.detect_all))
    sweeps = 0
    while remaining > 0 and sweeps < sim.max_sweeps:
        remaining, far = _status(_timed(times, "sweeps", contacts.sweep, remaining))
        sweeps += 1
        if far:
            _timed(times, "grid", grid.build)
            remaining, _ = _status(_timed(times, "detect", contacts.detect_all))
    _timed(times, "counters", params.read_back)
    return sweeps


def plain_block(sim, min_seconds, min_steps) -> dict:
    """Consecutive steps of length sim.max_step(), as advance() takes them, until both
    minima are met. Returns steps, full [s], sim_time [s] (sum of h), collisions, sweeps."""
    c0, s0 = sim.stats["pair_collisions"], sim.stats["sweeps"]
    l0 = sim.stats["near_list_detections"]
    out = dict(steps=0, full=0.0, sim_time=0.0)
    ti.sync()
    while out["steps"] < min_steps or out["full"] < min_seconds:
        h = sim.max_step()
        t0 = time.perf_counter()
        sim.step(h)
        ti.sync()
        out["full"] += time.perf_counter() - t0
        out["sim_time"] += h
        out["steps"] += 1
    out["collisions"] = sim.stats["pair_collisions"] - c0
    out["sweeps"] = sim.stats["sweeps"] - s0
    out["near"] = sim.stats["near_list_detections"] - l0
    return out


def _restore(sim, snapshot):
    """Put a Simulation back to a checkpoint() snapshot (state, step bound, counters;
    untimed). Its near lists are dropped: a pass right after a restore would otherwise
    find lists made at the same positions by the pass before it, fresher than a run
    ever has them, so staged passes and the full steps compared with them all detect by
    a full scan."""
    sim.restore(snapshot)
    sim.debug_view().contacts.near_ready = False
    ti.sync()


def staged_block(sim, min_seconds, min_steps) -> dict:
    """Alternate, on the same states, a staged pass (staged_step) and a full
    Simulation.step, each right after the same untimed restore of the state (so both
    start alike), until both minima are met. Returns steps, full [s], stages {stage: s}."""
    out = dict(steps=0, full=0.0, stages=dict.fromkeys(STAGES, 0.0))
    while out["steps"] < min_steps or out["full"] < min_seconds:
        h = sim.max_step()
        snapshot = sim.checkpoint()
        _restore(sim, snapshot)
        staged_step(sim, h, out["stages"])
        _restore(sim, snapshot)
        t0 = time.perf_counter()
        sim.step(h)
        ti.sync()
        out["full"] += time.perf_counter() - t0
        out["steps"] += 1
    return out


def render_ms(sim, scene, frames=3):
    """Best wall milliseconds of ``frames`` offscreen 640x480 frames of the current state
    (snapshot copy + GGUI draw + read-back, as `taichi-spheres run` does per frame).
    Returns (ms, None), or (None, why) when GGUI is unavailable (no Vulkan)."""
    from taichi_spheres.render import Renderer, RenderUnavailable   # lazily: optional
    try:
        renderer = Renderer(scene)
    except RenderUnavailable as exc:
        return None, str(exc)
    try:
        renderer.frame(sim.state())          # untimed: the first frame builds the pipeline
        best = float("inf")
        for _ in range(frames):
            t0 = time.perf_counter()
            renderer.frame(sim.state())
            best = min(best, time.perf_counter() - t0)
        return best * 1e3, None
    finally:
        renderer.close()


def measure(scene, arch, precision, min_seconds, blocks=3, render=False) -> dict:
    """One row: build and warm up, then ``blocks`` plain blocks (throughput) interleaved
    with ``blocks`` staged blocks (stage costs), each of >= 10 steps and
    min_seconds / blocks s. Every figure is the fastest of its blocks (the least
    disturbed by other load on a shared machine). Rates are per wall second, step and
    stage times in ms per step, memory in bytes."""
    ts_runtime.ensure(arch, precision)      # a re-initialisation frees memory: not here
    sim, info = build(lambda: ts.Simulation(scene, arch=arch, precision=precision, fused=True))
    plain, staged = [], []
    for _ in range(blocks):
        plain.append(plain_block(sim, min_seconds / blocks, 10))
        staged.append(staged_block(sim, min_seconds / blocks, 10))
    best = min(plain, key=lambda b: b["full"] / b["steps"])
    n, steps, secs = scene.n, best["steps"], best["full"]
    stages_ms = {k: min(b["stages"][k] / b["steps"] for b in staged) * 1e3 for k in STAGES}
    same_ms = min(b["full"] / b["steps"] for b in staged) * 1e3
    bare_ms = stages_ms["drift"] + stages_ms["grid"] + stages_ms["detect"]
    row = dict(n=n, precision=precision, steps=steps, sphere_steps=n * steps / secs,
               collisions=best["collisions"] / secs, sim_per_wall=best["sim_time"] / secs,
               step_ms=secs / steps * 1e3, stages_ms=stages_ms, same_ms=same_ms,
               stage_sum_ms=sum(stages_ms.values()), bare_ms=bare_ms,
               ratio=secs / steps * 1e3 / bare_ms, sweeps=best["sweeps"] / steps,
               near_share=best["near"] / steps,
               fused=sim.fused, **info)
    if render:
        row["render_ms"], row["render_error"] = render_ms(sim, scene)
    return row


# ---- scaling ----
def fit_exponent(ns, seconds) -> float:
    """Least-squares slope of log(seconds per step) against log(N): 1.0 is linear."""
    return float(np.polyfit(np.log(np.asarray(ns, float)), np.log(np.asarray(seconds)), 1)[0])


def scaling(rows) -> dict:
    """Per precision with >= 2 sizes: (Ns, exponent over all Ns, exponent over N >= 1e4
    or None when fewer than 2 such sizes)."""
    out = {}
    for precision in dict.fromkeys(r["precision"] for r in rows):
        mine = [r for r in rows if r["precision"] == precision]
        if len(mine) < 2:
            continue
        big = [r for r in mine if r["n"] >= 10_000]
        fit = (lambda rs: fit_exponent([r["n"] for r in rs], [r["step_ms"] for r in rs]))
        out[precision] = dict(all=fit(mine), big=fit(big) if len(big) >= 2 else None,
                              sizes=[r["n"] for r in mine], big_sizes=[r["n"] for r in big])
    return out


# ---- compiled-out features ----
def simulation_with(scene, arch, precision, flip):
    """A Simulation of ``scene`` with the Features fields in ``flip`` forced (e.g.
    {'equal_radii': False}) and every other feature as the scene needs it. The forced
    features are not used by the scene (g = 0, equal radii, e = 1 are still its values),
    so results are the same; only the compiled code and the fields differ."""
    wanted = dataclasses.replace(Features.from_scene(scene), **flip)
    with mock.patch.object(Features, "from_scene", classmethod(lambda cls, _scene, *_a, **_k: wanted)):
        sim = ts.Simulation(scene, arch=arch, precision=precision)
    if sim.features != wanted:
        raise RuntimeError("Simulation no longer takes its Features from Features.from_scene:"
                           " update simulation_with() in tools/bench.py")
    return sim


def step_seconds(sim, steps) -> float:
    """Mean wall seconds per step over ``steps`` steps."""
    ti.sync()
    t0 = time.perf_counter()
    for _ in range(steps):
        sim.step(sim.max_step())
    ti.sync()
    return (time.perf_counter() - t0) / steps


def compare_features(make_off, make_on, repeats=5, steps=20) -> dict:
    """Pairs of adjacent blocks of ``steps`` steps of two builds of one scene (compiled
    out: make_off(), compiled in: make_on()) from the same states, in alternating order.
    Returns off/on: best sphere-steps/s of each; speedup: median over the pairs of
    (compiled-in time / compiled-out time), with its quartiles (q1, q3), which other
    load disturbs less than a ratio of two bests; off_bytes/on_bytes: field bytes per
    sphere; same: whether the final states are identical."""
    sims = {"off": make_off(), "on": make_on()}
    for sim in sims.values():
        sim.step(sim.max_step())
    best, ratios = dict.fromkeys(sims, float("inf")), []
    for rep in range(repeats):
        st = sims["off"].state()
        secs = {}
        for key in (("off", "on") if rep % 2 == 0 else ("on", "off")):
            sims[key].set_state(st.x, st.v)
            secs[key] = step_seconds(sims[key], steps)
            best[key] = min(best[key], secs[key])
        ratios.append(secs["on"] / secs["off"])
    n = sims["off"].n
    q1, med, q3 = np.percentile(ratios, [25, 50, 75])
    return dict(off=n / best["off"], on=n / best["on"], speedup=float(med), q1=float(q1),
                q3=float(q3), off_bytes=sims["off"].field_bytes() / n,
                on_bytes=sims["on"].field_bytes() / n,
                same=bool(np.array_equal(sims["off"].state().x, sims["on"].state().x)))


def feature_comparisons(n, arch, precision, repeats, steps):
    """(label, result) for every feature compiled in at once (compile_all: periodic and
    walled gas), then each feature of FEATURE_FLIPS alone (periodic gas)."""
    periodic = gas(n, packing=0.3, periodic=True, seed=0)
    walled = gas(n, packing=0.3, periodic=False, seed=0)
    cases = [(f"all at once (compile_all), {kind} gas", scene,
              lambda s: ts.Simulation(s, arch=arch, precision=precision, compile_all=True))
             for kind, scene in (("periodic", periodic), ("walled", walled))]
    cases += [(label, periodic, lambda s, f=flip: simulation_with(s, arch, precision, f))
              for _key, label, flip in FEATURE_FLIPS]
    for label, scene, make_on in cases:
        res = compare_features(lambda: ts.Simulation(scene, arch=arch, precision=precision),
                               lambda: make_on(scene), repeats, steps)
        yield label, res


# ---- command line ----
def parse_args(argv=None):
    """Command-line options; --quick fills in what was not given and implies --no-write."""
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--arch", default="cpu")
    ap.add_argument("--sizes", type=int, nargs="+", default=None,
                    help=f"sphere counts (default {DEFAULT_SIZES}; --quick: {QUICK_SIZES})")
    ap.add_argument("--precisions", nargs="+", default=None)
    ap.add_argument("--feature-n", type=int, default=10000,
                    help="sphere count for the feature comparison (0: skip)")
    ap.add_argument("--seconds", type=float, default=None,
                    help="minimum timed seconds per row, split into 3 blocks (default 4.5; "
                         "--quick: 1)")
    ap.add_argument("--render", action="store_true",
                    help="also time one rendered 640x480 frame per row (needs Vulkan)")
    ap.add_argument("--quick", action="store_true",
                    help="development run: N up to 1e4, short timing, writes nothing")
    ap.add_argument("--out", default=os.path.join("docs", "bench.md"))
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    args.sizes = args.sizes or (QUICK_SIZES if args.quick else DEFAULT_SIZES)
    args.seconds = args.seconds or (1.0 if args.quick else 4.5)
    args.feature_repeats, args.feature_steps = (3, 10) if args.quick else (15, 20)
    args.no_write = args.no_write or args.quick
    args.precisions = args.precisions or (["f32"] if args.arch in ("vulkan", "metal")
                                          else ["f64", "f32"])
    return args


def run_rows(args) -> list:
    """Throughput, memory and stage rows for every precision and size (printed as they
    come); rendering is dropped with a message once GGUI proves unavailable."""
    rows, render = [], args.render
    for precision in args.precisions:
        for n in args.sizes:
            scene = gas(n, packing=0.3, periodic=True, seed=0)
            before = cpu_jiffies()
            row = measure(scene, args.arch, precision, args.seconds, render=render)
            row["steal"] = steal_share(before, cpu_jiffies())
            if row.get("render_error"):
                print(f"render skipped: {row['render_error']}", flush=True)
                render = False
            rows.append(row)
            print(bench_report.row_line(row), flush=True)
    return rows


def main(argv=None):
    args = parse_args(argv)
    load_start, jiffies_start = os.getloadavg()[0], cpu_jiffies()
    runtime = ts.Simulation(gas(8, packing=0.01), arch=args.arch,
                            precision=args.precisions[0]).runtime
    baseline = rss_bytes()
    rows = run_rows(args)
    fits = scaling(rows)
    for precision, fit in fits.items():
        print(bench_report.fit_line(precision, fit), flush=True)
    feats = []
    if args.feature_n:
        for label, res in feature_comparisons(args.feature_n, args.arch, args.precisions[0],
                                              args.feature_repeats, args.feature_steps):
            feats.append((label, res))
            print(bench_report.feature_line(label, res), flush=True)
    loads = (load_start, os.getloadavg()[0])
    steal = steal_share(jiffies_start, cpu_jiffies())
    text = bench_report.markdown(args, runtime, baseline, rows, fits, feats, loads, steal)
    print(text)
    if not args.no_write:
        os.makedirs(os.path.dirname(args.out) or ".", exist_ok=True)
        try:    # sections other tools write into the same report stay
            with open(args.out) as fh:
                kept = kept_sections(fh.read())
        except FileNotFoundError:
            kept = ""
        with open(args.out, "w") as fh:
            fh.write(text + ("\n" + kept if kept else ""))
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
