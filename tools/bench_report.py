"""Text of the scale benchmark (tools/bench.py): console lines and docs/bench.md."""
from __future__ import annotations

import datetime
import os
import platform
import sys

import taichi as ti

from machine import cpu_name, gpu_name  # tools/machine.py

MIB = 2.0 ** 20


def _per_sphere(value, n) -> str:
    """Bytes per sphere of a byte count, or n/a when it was not measured."""
    return "n/a" if value is None else f"{value / n:.0f}"


def row_line(r) -> str:
    """One console line for a measured row."""
    s = r["stages_ms"]
    render = f", render {r['render_ms']:.1f} ms/frame" if r.get("render_ms") else ""
    return (f"N={r['n']:>9} {r['precision']}: {r['sphere_steps']:.3e} sphere-steps/s, "
            f"{r['collisions']:.3e} collisions/s, {r['sim_per_wall']:.3g} sim s/wall s, "
            f"step {r['step_ms']:.3f} ms (stages: drift {s['drift']:.3f}, grid {s['grid']:.3f}, "
            f"detect {s['detect']:.3f}, sweeps {s['sweeps']:.3f}, counters {s['counters']:.3f}; "
            f"sum {r['stage_sum_ms']:.3f} against a full step {r['same_ms']:.3f} on the same "
            f"states), full/bare {r['ratio']:.2f}, memory "
            f"{_per_sphere(r['rss_warm'], r['n'])} B/sphere RSS, "
            f"{_per_sphere(r['fields'], r['n'])} B/sphere fields{render}, "
            f"CPU stolen {_percent(r.get('steal'))}")


def fit_line(precision, fit) -> str:
    """Console line for the fitted exponents of one precision."""
    big = "" if fit["big"] is None or fit["big_sizes"] == fit["sizes"] else \
        f", {fit['big']:.2f} over N >= 1e4"
    return f"{precision}: step time ~ N^{fit['all']:.2f} over N = {_sizes(fit['sizes'])}{big}"


def feature_line(label, res) -> str:
    """Console line for one compiled-out feature comparison."""
    return (f"{label}: {res['off']:.3e} compiled out, {res['on']:.3e} compiled in, "
            f"speed-up {res['speedup']:.2f} (quartiles {res['q1']:.2f}-{res['q3']:.2f}), "
            f"fields {res['off_bytes']:.0f} vs {res['on_bytes']:.0f} B/sphere, "
            f"identical states {res['same']}")


def _sizes(ns) -> str:
    return ", ".join(f"{n:,}" for n in ns)


def _table(head, align, body) -> list:
    """Markdown table lines from a header list, an alignment row string and row lists."""
    return ["| " + " | ".join(head) + " |", align] + \
        ["| " + " | ".join(cells) + " |" for cells in body]


def _percent(share) -> str:
    """A share as a percentage with one decimal ('n/a' for None)."""
    return "n/a" if share is None else f"{100 * share:.1f} %"


def header(args, runtime, loads, steal=None) -> list:
    """Title, provenance (date, command, hardware, versions, load) and the scene.
    loads: 1-minute load averages at the start and the end of the run; steal: share of
    the CPU time the hypervisor gave to other guests during the run (None: unknown)."""
    hw = gpu_name() if runtime.actual == "cuda" else None
    hardware = f"{hw} (GPU)" if hw else f"{cpu_name()}, {os.cpu_count()} cores"
    cmd = " ".join(["python tools/bench.py"] + sys.argv[1:])
    return [
        "# Benchmark: elastic hard-sphere gas, N = " + _sizes(args.sizes), "",
        f"Generated {datetime.date.today().isoformat()} by `{cmd}` on {hardware}, arch "
        f"{runtime.arch} (Taichi {'.'.join(map(str, ti.__version__))}, {runtime.actual}, "
        f"{runtime.compile} compile mode), "
        f"Python {platform.python_version()}. Load average (1 min, all processes on the "
        f"machine) {loads[0]:.1f} at the start and {loads[1]:.1f} at the end of the run; "
        f"CPU time stolen by the hypervisor for other guests (/proc/stat) during the run: "
        f"{_percent(steal)}.", "",
        "Scene: N spheres of radius 0.5 m on a jittered lattice in a periodic cube at packing "
        "fraction 0.3, Gaussian velocities (rms 1 m/s per component), no gravity, e = 1; "
        "default step_fraction 0.1. A *sphere-step* is one sphere advanced by one adaptive "
        "step. Each row runs 3 timed blocks of at least 10 steps and "
        f"{args.seconds / 3:.2g} s each and keeps the fastest (the least disturbed). The "
        "machine is a shared VM: its cores also run other people's processes, and its "
        "speed drifts by up to ±25 % from minute to minute and by up to a factor of two "
        "from one day to another, so differences of that size between rows or runs are "
        "noise.", ""]


def throughput_table(rows) -> list:
    """Rates, step time and the full step against a bare grid pass."""
    body = [[f"{r['n']:,}" + ("*" if r.get("fused") else ""), r["precision"],
             f"{r['sphere_steps']:.3g}", f"{r['collisions']:.3g}",
             f"{r['sim_per_wall']:.3g}", f"{r['step_ms']:.3f}", f"{r['bare_ms']:.3f}",
             f"{r['ratio']:.2f}", f"{r['sweeps']:.2f}", f"{100 * r['near_share']:.0f} %",
             f"{r['compile_s']:.1f}", _percent(r.get("steal"))] for r in rows]
    return ["## Throughput", "",
            "*ms/step* and the rates: consecutive steps, as `advance` takes them. "
            "*Simulated s / wall s*: simulated time advanced per second of wall time (the "
            "step length h shrinks as N grows because the fastest sphere is faster). *Bare "
            "pass* = drift + grid build + neighbour scan (a full scan of the grid, from the "
            "stage table); *full/bare* = ms/step / bare pass. *Near lists*: share of the "
            "steps whose detection used the near lists a full scan made a few steps before "
            "instead of scanning the grid (same pairs and bits; `Contacts.detect`, from "
            "3,000 spheres on). Rows marked *: the full step is the fused step (one kernel "
            "besides the counter read-back), the bare pass three launches, which favours "
            "the full step by a few launch costs (~0.1 ms). *CPU stolen*: share of the "
            "machine's CPU time the hypervisor gave to other guests while the row ran "
            "(/proc/stat; other guests can also slow a row through shared caches and "
            "memory without stealing time).", ""] + \
        _table(["N", "precision", "sphere-steps/s", "collisions/s", "simulated s / wall s",
                "ms/step", "bare pass ms", "full/bare", "sweeps/step", "near lists",
                "compile+warm-up s", "CPU stolen"],
               "|---:|:---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|", body) + [""]


def memory_table(rows, baseline) -> list:
    """Measured RSS growth per sphere next to the bytes of the Taichi fields."""
    body = [[f"{r['n']:,}", r["precision"], _per_sphere(r["rss_build"], r["n"]),
             _per_sphere(r["rss_warm"], r["n"]), _per_sphere(r["fields"], r["n"]),
             "n/a" if r["rss_warm"] is None else f"{r['rss_warm'] / MIB:.1f}"] for r in rows]
    base = "n/a" if baseline is None else f"{baseline / MIB:.0f} MiB"
    return ["## Memory per sphere", "",
            "Measured: growth of the process's resident set size (/proc/self/statm) around "
            "building a Simulation, and around building it and taking its first 3 steps "
            "(which compiles its kernels, or loads them from Taichi's offline cache when an "
            "earlier run compiled them: a cost that does not grow with N and dominates at "
            "small N). Cross-check: bytes of the Taichi fields the Simulation allocated, "
            "from their shapes and dtypes (per-sphere fields plus about one grid cell per "
            "sphere). The Python process itself (interpreter, Taichi, runtime) held "
            f"{base} before the first Simulation. Simulations are built in this order in "
            "one process, so a later row can reuse memory an earlier one freed.", ""] + \
        _table(["N", "precision", "RSS after build, B/sphere", "RSS after build + 3 steps, "
                "B/sphere", "Taichi fields, B/sphere", "RSS after build + 3 steps, MiB"],
               "|---:|:---:|---:|---:|---:|---:|", body) + [""]


def stage_table(rows) -> list:
    """Milliseconds per stage of one step, their sum and the full step."""
    render = any(r.get("render_ms") for r in rows)
    body = []
    for r in rows:
        s = r["stages_ms"]
        cells = [f"{r['n']:,}" + ("*" if r.get("fused") else ""), r["precision"]] + \
            [f"{s[k]:.3f}" for k in ("drift", "grid", "detect", "sweeps", "counters")] + \
            [f"{r['stage_sum_ms']:.3f}", f"{r['same_ms']:.3f}",
             f"{r['stage_sum_ms'] / r['same_ms']:.2f}"]
        if render:
            cells.append(f"{r['render_ms']:.1f}" if r.get("render_ms") else "n/a")
        body.append(cells)
    head = ["N", "precision", "drift + walls", "grid build", "detection", "resolve sweeps",
            "counter reads", "sum of stages", "full step", "sum / full"]
    align = "|---:|:---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    if render:
        head, align = head + ["render ms/frame"], align + "---:|"
    note = ("Render: one offscreen 640×480 GGUI frame of the state (snapshot + draw + "
            "read-back), best of 3; once per output frame, not per step." if render else
            "Render was not timed (`--render` times one offscreen GGUI frame when Vulkan "
            "is available).")
    return ["## Cost of each stage of a step (ms per step)", "",
            "The kernels of `Simulation.step` called one by one in its order (drift and "
            "walls are one kernel; the sweeps column is every resolve sweep of the step "
            "with the detection around the spheres it changed; *counter reads* is the step "
            "reading its counters back), with `ti.sync()` after each, on the same states as "
            "the full steps they are compared with (each pass starts right after the same "
            "untimed restore of the state, which drops the near lists, so these steps all "
            "detect by a full scan: the *detection* column is the bare pass's scan); each "
            "figure is its fastest of the 3 blocks. "
            "Rows marked * run their full step as the fused step (below 3,000 spheres on "
            "the CPU: `taichi_spheres/fused.py`), so their stages, launched one by one, pay "
            "launch and read-back costs the full step does not. " +
            note, ""] + _table(head, align, body) + [""] + _stage_warning(rows)


def _stage_warning(rows, tolerance=0.15) -> list:
    """A line naming the rows whose sum of stages is off the full step by > tolerance."""
    off = [f"{r['n']:,} {r['precision']}" for r in rows if not r.get("fused")
           and abs(r["stage_sum_ms"] / r["same_ms"] - 1.0) > tolerance]
    if not off:
        return [f"The sum of the stages is within {tolerance:.0%} of the full step in every "
                "row not marked *.", ""]
    return [f"The sum of the stages is off the full step by more than {tolerance:.0%} at "
            f"N = {'; '.join(off)}: other load disturbed those rows.", ""]


def scaling_table(rows, fits) -> list:
    """Time per sphere-step per N and the fitted exponents."""
    body = [[f"{r['n']:,}", r["precision"], f"{1e9 / r['sphere_steps']:.0f}",
             f"{r['step_ms']:.3f}"] for r in rows]
    lines = ["## Growth with N", "",
             "A step costs time ∝ N^α; α is the least-squares slope of log(ms/step) "
             "against log N (1.0 = linear, below 1 where fixed per-step costs such as "
             "kernel launches still matter).", ""]
    lines += _table(["N", "precision", "ns per sphere-step", "ms/step"], "|---:|:---:|---:|---:|",
                    body) + [""]
    for precision, fit in fits.items():
        big = "" if fit["big"] is None or fit["big_sizes"] == fit["sizes"] else \
            f"; over N = {_sizes(fit['big_sizes'])}: α = {fit['big']:.2f}"
        lines.append(f"- {precision}: over N = {_sizes(fit['sizes'])}: α = {fit['all']:.2f}{big}")
    return lines + [""]


def feature_table(args, feats) -> list:
    """Compiled-out features: all at once, then one at a time."""
    body = [[label, f"{res['off']:.3g}", f"{res['on']:.3g}", f"{res['speedup']:.2f}",
             f"{res['q1']:.2f}–{res['q3']:.2f}",
             f"{res['off_bytes']:.0f}", f"{res['on_bytes']:.0f}", "yes" if res["same"] else "no"]
            for label, res in feats]
    return [f"## Compiled-out features (N = {args.feature_n:,}, {args.precisions[0]})", "",
            "The same scene built twice: with what it does not need compiled out "
            "(`ti.static` flags, the default) and with a feature compiled in although the "
            "scene does not use it (g = 0, equal radii, e = 1 stay its values): all of them "
            "at once (`Simulation(..., compile_all=True)`), then one at a time (the tool "
            "forces one flag of `Features`). Both builds step from the same states in "
            f"{args.feature_repeats} pairs of adjacent blocks of {args.feature_steps} steps "
            "(order alternating); sphere-steps/s is the best block of each build, the "
            "speed-up (compiled-in time / compiled-out time) the median over the pairs, "
            "with its quartiles: a spread wider than the effect means the effect is lost "
            "in the noise.", ""] + \
        _table(["comparison", "compiled out, sphere-steps/s", "compiled in", "speed-up",
                "speed-up quartiles", "fields out, B/sphere", "fields in, B/sphere",
                "identical states"], "|:---|---:|---:|---:|:---:|---:|---:|:---:|", body) + [""]


def markdown(args, runtime, baseline, rows, fits, feats, loads, steal=None) -> str:
    """The whole docs/bench.md (loads: 1-minute load averages at start and end; steal:
    share of CPU time stolen during the run)."""
    lines = header(args, runtime, loads, steal) + throughput_table(rows) + memory_table(rows, baseline) + \
        stage_table(rows) + scaling_table(rows, fits)
    if feats:
        lines += feature_table(args, feats)
    return "\n".join(lines).rstrip() + "\n"
