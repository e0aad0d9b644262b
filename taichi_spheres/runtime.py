"""Taichi runtime management: ``ti.init`` happens here, on demand, never at import.

Taichi has one runtime per process. Simulations with the same arch, precision and
thread count share it; asking for a different one re-initialises Taichi, which
frees every field, so older Simulations are marked stale and refuse to run
(``RuntimeError``) instead of crashing inside a kernel.
"""
from __future__ import annotations

import dataclasses

import taichi as ti

ARCHS = ("cpu", "gpu", "cuda", "vulkan", "metal")
PRECISIONS = ("f32", "f64")


@dataclasses.dataclass(frozen=True)
class Runtime:
    arch: str          # what was asked: cpu|gpu|cuda|vulkan|metal
    actual: str        # what Taichi runs on: x64|arm64|cuda|vulkan|metal|...
    precision: str     # f32|f64 (Taichi's default_fp)
    threads: int | None
    generation: int

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


def ensure(arch: str = "cpu", precision: str | None = None, threads: int | None = None) -> Runtime:
    """Initialise Taichi for (arch, precision, threads) unless it already is; return it."""
    global _current, _generation
    if arch not in ARCHS:
        raise ValueError(f"arch must be one of {', '.join(ARCHS)}, got {arch!r}")
    if precision is not None and precision not in PRECISIONS:
        raise ValueError(f"precision must be 'f32' or 'f64', got {precision!r}")
    if threads is not None and (not isinstance(threads, int) or threads < 1):
        raise ValueError(f"threads must be a positive int, got {threads!r}")
    want = precision or default_precision(arch)
    cur = _current
    if cur is not None and _alive(cur) and cur.arch == arch and cur.precision == want \
            and (threads is None or cur.threads == threads):
        return cur
    if arch == "metal" and want == "f64":
        raise ValueError("precision f64 is not available on Metal; use precision='f32'")
    fp = ti.f64 if want == "f64" else ti.f32
    kwargs = dict(arch=_taichi_arch(arch), default_fp=fp, default_ip=ti.i32,
                  offline_cache=True, log_level=ti.WARN, random_seed=0)
    if threads is not None:
        kwargs["cpu_max_num_threads"] = threads
    ti.init(**kwargs)
    actual = ti.lang.impl.current_cfg().arch.name
    if arch != "cpu" and actual in ("x64", "arm64"):
        ti.reset()
        _current = None
        raise RuntimeError(f"arch {arch!r} is not available on this machine "
                           f"(Taichi fell back to the CPU); use arch='cpu'")
    _generation += 1
    _current = Runtime(arch=arch, actual=actual, precision=want, threads=threads,
                       generation=_generation)
    return _current


def _alive(rt: Runtime) -> bool:
    """False when someone else called ti.reset()/ti.init() behind our back."""
    prog = ti.lang.impl.get_runtime().prog
    return prog is not None and ti.lang.impl.current_cfg().arch.name == rt.actual


def check(rt: Runtime) -> None:
    """Raise if the runtime ``rt`` was replaced since a Simulation was built on it."""
    if _current is None or _current.generation != rt.generation or not _alive(rt):
        raise RuntimeError(
            "Taichi was re-initialised (another Simulation with a different arch, precision "
            "or thread count, or a ti.init/ti.reset call) after this Simulation was built; "
            "its fields are gone. Build the Simulation again.")
