"""Taichi runtime management: ``ti.init`` happens here, on demand, never at import.

Taichi has one runtime per process. Simulations with the same arch, precision,
thread count and compile mode share it; asking for a different one re-initialises
Taichi, which frees every field, so older Simulations are marked stale and refuse to
run (``RuntimeError``) instead of crashing inside a kernel.
"""
from __future__ import annotations

import contextlib
import dataclasses
import io
import os

import numpy as np
import taichi as ti

from . import frontend

ARCHS = ("cpu", "gpu", "cuda", "vulkan", "metal")
PRECISIONS = ("f32", "f64")

#: How Taichi compiles kernels (extra ``ti.init`` options). "optimized" (the default):
#: Taichi's own IR optimisations, then LLVM's. "fast": Taichi's "advanced" IR passes
#: (CFG store forwarding, whole-kernel CSE ...) left to LLVM: kernels compile about 3x
#: faster (first run of a two-sphere scene on 2 cores 17.2 -> 5.8 s, of a 1e5-sphere
#: gas 16.1 -> 7.5 s), to the same bits (tested in f64), and steps run 1.08x slower at
#: N = 1e5 on one thread (``python tools/compile_options.py``, CPU; GPUs not
#: measured). Chosen per process when Taichi is initialised: ``ensure(compile=...)``,
#: else TAICHI_SPHERES_COMPILE.
COMPILE_MODES = {"optimized": {}, "fast": {"advanced_optimization": False}}
COMPILE_ENV = "TAICHI_SPHERES_COMPILE"
#: Taichi's fast_math (its default is True) lets LLVM contract a*b+c into one fused
#: multiply-add and reassociate floating point wherever the CPU has the instructions
#: and its cost model likes it: which expressions it fuses differs between CPUs
#: (AVX2/AVX-512 FMA, ARM), compile modes and loop shapes, so the same scene gave
#: other bits on another CPU or in the other compile mode. Off, every operation
#: rounds as written (IEEE 754), and the results depend only on the scene, precision
#: and thread count (tests/test_same_bits.py). Cost at N = 1e5: docs/bench.md. On
#: CUDA, Taichi 1.7 marks every kernel function with LLVM's unsafe-fp-math (for its
#: fast square roots) whatever fast_math says, so multiply-adds may fuse there as the
#: code's shape allows: GPU bits can differ between compile modes (docs/backends.md).
FAST_MATH = False
#: Taichi's make_thread_local (its default is True) gives each thread of a parallel
#: loop a private copy of every global scalar the loop only adds to or takes the
#: maximum into (the step's counters, the largest move and overlap), and every
#: launched thread folds its copy into the global one at its end. On a GPU a loop
#: whose bounds are read from a field is launched on a fixed, device-filling number of
#: threads (~540,000 on an H200), so with the copies every such kernel pays ~540,000
#: contended atomics, ~3.5 ms, even with nothing to do (the resolve, re-detection and
#: near-list kernels). Off on GPUs, only the iterations that count something touch the
#: global scalars: a 10^4-sphere gas step on an H200 takes 4.4 ms instead of 76 with
#: Taichi's kernel profiler on (``python tools/kernel_profile.py --gas 10000 --arch cuda --window
#: 0.1``, docs/bench.md). Vulkan and Metal launch such loops on a fixed number of
#: threads too and get the same setting (not measured there). The CPU keeps Taichi's
#: default: its few threads fold a few copies, and its bits (tests/same_bits.json) stay
#: as they are.
GPU_THREAD_LOCAL = False
#: "off" leaves Taichi's frontend without the source memos of frontend.py (for
#: measuring them: tools/compile_frontend.py); anything else, or unset, installs them.
FRONTEND_MEMO_ENV = "TAICHI_SPHERES_FRONTEND_MEMO"


@dataclasses.dataclass(frozen=True)
class Runtime:
    arch: str          # what was asked: cpu|gpu|cuda|vulkan|metal
    actual: str        # what Taichi runs on: x64|arm64|cuda|vulkan|metal|...
    precision: str     # f32|f64 (Taichi's default_fp)
    threads: int | None   # CPU threads: asked for, else Taichi's default (a GPU: as asked)
    generation: int
    compile: str = "optimized"   # COMPILE_MODES key

    @property
    def is_cpu(self) -> bool:
        return self.actual in ("x64", "arm64")


_current: Runtime | None = None
_generation = 0


def _taichi_arch(name):
    return {"cpu": ti.cpu, "gpu": ti.gpu, "cuda": ti.cuda, "vulkan": ti.vulkan,
            "metal": ti.metal}[name]


def default_precision(arch: str) -> str:
    """f64 on CPU and CUDA, f32 on Vulkan and Metal (f64 there is missing or slow)."""
    return "f32" if arch in ("vulkan", "metal") else "f64"


def frontend_memos_wanted() -> bool:
    """Whether ensure installs frontend.py's memos: unless FRONTEND_MEMO_ENV is "off"."""
    return os.environ.get(FRONTEND_MEMO_ENV, "").strip().lower() != "off"


def compile_mode_from_env(default: str = "optimized") -> str:
    """The compile mode TAICHI_SPHERES_COMPILE asks for (``default`` when unset)."""
    mode = os.environ.get(COMPILE_ENV, "").strip().lower() or default
    if mode not in COMPILE_MODES:
        raise ValueError(f"{COMPILE_ENV} must be one of {', '.join(COMPILE_MODES)}, got {mode!r}")
    return mode


def ensure(arch: str = "cpu", precision: str | None = None, threads: int | None = None,
           compile: str | None = None) -> Runtime:
    """Initialise Taichi for (arch, precision, threads, compile mode) unless it already
    is; return it. threads None: any thread count if the current runtime fits, else
    Taichi's default (a CPU runtime started with the default keeps the count it got,
    so that asking for that count later keeps it); compile None: the current
    runtime's mode, also when Taichi is re-initialised for another arch or precision
    (for the first runtime, TAICHI_SPHERES_COMPILE's, else "optimized"). A
    re-initialisation makes earlier Simulations stale (see check)."""
    global _current, _generation
    if compile is not None and compile not in COMPILE_MODES:
        raise ValueError(f"compile must be one of {', '.join(COMPILE_MODES)}, got {compile!r}")
    if arch not in ARCHS:
        raise ValueError(f"arch must be one of {', '.join(ARCHS)}, got {arch!r}")
    if precision is not None and precision not in PRECISIONS:
        raise ValueError(f"precision must be 'f32' or 'f64', got {precision!r}")
    if threads is not None and (not isinstance(threads, int) or threads < 1):
        raise ValueError(f"threads must be a positive int, got {threads!r}")
    want = precision or default_precision(arch)
    cur = _current
    if cur is not None and _alive(cur) and cur.arch == arch and cur.precision == want \
            and (threads is None or cur.threads == threads) \
            and (compile is None or cur.compile == compile):
        return cur
    mode = compile or (cur.compile if cur is not None else compile_mode_from_env())
    if arch == "metal" and want == "f64":
        raise ValueError("precision f64 is not available on Metal; use precision='f32'")
    kwargs = init_options(arch, want, mode, threads)
    if frontend_memos_wanted():
        frontend.memoize_source_lookups()
    with contextlib.redirect_stdout(io.StringIO()):
        ti.init(**kwargs)    # (its "[Taichi] Starting on arch=..." line: Runtime.actual says it)
    actual = ti.lang.impl.current_cfg().arch.name
    if arch != "cpu" and actual in ("x64", "arm64"):
        ti.reset()
        _current = None
        raise RuntimeError(f"arch {arch!r} is not available on this machine "
                           f"(Taichi fell back to the CPU); use arch='cpu'")
    if actual not in ("x64", "arm64"):
        refuse_broken_loops(arch, actual, probe_loops())
    _generation += 1
    if threads is None and actual in ("x64", "arm64"):
        threads = ti.lang.impl.current_cfg().cpu_max_num_threads
    _current = Runtime(arch=arch, actual=actual, precision=want, threads=threads,
                       generation=_generation, compile=mode)
    return _current


def init_options(arch: str, precision: str, mode: str, threads: int | None) -> dict:
    """The ``ti.init`` keyword arguments of a runtime: arch, precision ("f32"/"f64"),
    compile mode (COMPILE_MODES key), CPU threads (None: Taichi's default); FAST_MATH
    off everywhere, GPU_THREAD_LOCAL on GPUs."""
    kwargs = dict(arch=_taichi_arch(arch), default_fp=ti.f64 if precision == "f64" else ti.f32,
                  default_ip=ti.i32, offline_cache=True, log_level=ti.WARN, random_seed=0,
                  fast_math=FAST_MATH)
    kwargs.update(COMPILE_MODES[mode])
    if arch != "cpu":
        kwargs["make_thread_local"] = GPU_THREAD_LOCAL
    if threads is not None:
        kwargs["cpu_max_num_threads"] = threads
    return kwargs


#: The loop nest of probe_loops: parallel iterations x rows x spheres per row.
PROBE_SHAPE = (4, 5, 2)


def probe_loops() -> tuple:
    """(counted, expected) of a probe of the pattern every grid walk of the engine
    relies on: a parallel loop (over spheres), in it a loop over stencil rows, in that
    a loop over the spheres of a row (bounds read from a field) holding integer
    atomics, onto one counter and onto per-sphere counts. Mesa's lavapipe 22.3
    (Debian 12's Vulkan for machines without a GPU) leaves the row loop after its
    first row here (and Mesa 25 does not), which would silently drop most pairs from
    the detection. Run right after ti.init (allocates and frees its own fields)."""
    outer, rows, per_row = PROBE_SHAPE
    builder = ti.FieldsBuilder()
    start = ti.field(ti.i32)
    hits = ti.field(ti.i32)
    total = ti.field(ti.i32)
    builder.dense(ti.i, rows + 1).place(start)
    builder.dense(ti.i, rows * per_row).place(hits)
    builder.place(total)
    tree = builder.finalize()
    try:
        start.from_numpy(np.arange(0, rows * per_row + 1, per_row, dtype=np.int32))

        @ti.kernel
        def walk():
            for _t in range(outer):
                for k in range(rows):
                    for q in range(start[k], start[k + 1]):
                        ti.atomic_add(hits[q], 1)
                        ti.atomic_add(total[None], 1)

        walk()
        per_sphere = hits.to_numpy()
        # the counter's total, or when a sphere's own count is off, the visits it got
        # (capped, so that an extra visit cannot make up for a missing one)
        counted = int(total[None])
        if (per_sphere != outer).any():
            counted = int(np.minimum(per_sphere, outer).sum()) - int((per_sphere > outer).sum())
    finally:
        tree.destroy()
    return counted, outer * rows * per_row


def refuse_broken_loops(arch: str, actual: str, probe: tuple) -> None:
    """Reset Taichi and raise RuntimeError when ``probe`` (probe_loops' counted,
    expected) shows the backend runs the grid's loop nests wrongly."""
    global _current
    counted, expected = probe
    if counted == expected:
        return
    ti.reset()
    _current = None
    raise RuntimeError(
        f"arch {arch!r}: this {actual} driver runs integer atomics inside nested loops "
        f"wrongly (a probe of the grid's loop pattern counted {counted} of {expected}), so "
        f"the simulation would silently miss collisions. Mesa's lavapipe 22.x (Debian 12's "
        f"Vulkan without a GPU) does this; use arch='cpu' (faster there anyway) or a GPU "
        f"driver.")


def _alive(rt: Runtime) -> bool:
    """False when someone else called ti.reset()/ti.init() behind our back."""
    prog = ti.lang.impl.get_runtime().prog
    return prog is not None and ti.lang.impl.current_cfg().arch.name == rt.actual


def check(rt: Runtime) -> None:
    """Raise if the runtime ``rt`` was replaced since a Simulation was built on it."""
    if _current is None or _current.generation != rt.generation or not _alive(rt):
        raise RuntimeError(
            "Taichi was re-initialised (another Simulation with a different arch, precision "
            "or thread count, an ensure() with another compile mode, or a ti.init/ti.reset "
            "call) after this Simulation was built; "
            "its fields are gone. Build the Simulation again.")
