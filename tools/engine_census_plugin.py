"""pytest plugin of ``tools/suite_time.py --census``: one JSON line per compiled engine
the tests build (taichi_spheres/engine.py), written by each pytest(-xdist) worker to
``$ENGINE_CENSUS_DIR/<worker>.jsonl``: the test that built it, the Taichi runtime's
generation, the engine's kind (its key without the generation, the precision by name)
and its room for spheres and cells; and ``<worker>.kernels.json``: per Taichi kernel
name, the seconds its compiles took (the Python AST pass, and the first launch of each
compiled instance: LLVM's compile and one run) and how many instances compiled. Loaded
with ``-p engine_census_plugin`` (tools/ on PYTHONPATH); without ENGINE_CENSUS_DIR it
does nothing."""
from __future__ import annotations

import collections
import dataclasses
import json
import os
import time

CENSUS_ENV = "ENGINE_CENSUS_DIR"


def engine_kind(key) -> str:
    """An engine key (engine.EngineKey) as text, without the runtime's generation (a
    re-initialised runtime builds the same kind again) and with the precision by name."""
    return repr(dataclasses.replace(key, generation=0, real=str(key.real)))


def pytest_configure(config):
    out_dir = os.environ.get(CENSUS_ENV)
    if not out_dir:
        return
    from taichi_spheres import engine
    built = engine.Engine.__init__
    path = os.path.join(out_dir, os.environ.get("PYTEST_XDIST_WORKER", "main") + ".jsonl")

    def logged(self, key, capacity, cell_capacity):
        built(self, key, capacity, cell_capacity)
        test = os.environ.get("PYTEST_CURRENT_TEST", "").split(" ")[0]
        with open(path, "a", encoding="utf-8") as out:
            out.write(json.dumps(dict(test=test, generation=key.generation,
                                      kind=engine_kind(key), spheres=capacity,
                                      cells=cell_capacity)) + "\n")

    engine.Engine.__init__ = logged
    config._kernel_seconds = log_kernel_compiles()


def log_kernel_compiles() -> dict:
    """Wrap Taichi's Kernel.materialize (the AST pass of a new instance) and
    Kernel.launch_kernel (the first launch of an instance compiles it) to sum their
    seconds per kernel name: {name: [AST seconds, first-launch seconds, instances]}."""
    from taichi.lang import kernel_impl
    seconds = collections.defaultdict(lambda: [0.0, 0.0, 0])   # ast, first launch, instances
    # the compiled instances not launched yet (alive until then: their ids are unique;
    # a re-initialised Taichi frees the older ones, whose ids may come again)
    pending = set()
    materialize, launch = kernel_impl.Kernel.materialize, kernel_impl.Kernel.launch_kernel

    def timed_materialize(self, key=None, args=None, arg_features=None):
        before = set(map(id, self.compiled_kernels.values()))
        t0 = time.perf_counter()
        out = materialize(self, key, args, arg_features)
        new = set(map(id, self.compiled_kernels.values())) - before
        if new:
            row = seconds[self.func.__name__]
            row[0] += time.perf_counter() - t0
            row[2] += len(new)
            pending.update(new)
        return out

    def timed_launch(self, t_kernel, *args):
        if id(t_kernel) not in pending:
            return launch(self, t_kernel, *args)
        pending.discard(id(t_kernel))
        t0 = time.perf_counter()
        out = launch(self, t_kernel, *args)
        seconds[self.func.__name__][1] += time.perf_counter() - t0
        return out

    kernel_impl.Kernel.materialize = timed_materialize
    kernel_impl.Kernel.launch_kernel = timed_launch
    return seconds


def pytest_unconfigure(config):
    """Write the kernel compile seconds (``<worker>.kernels.json``)."""
    out_dir = os.environ.get(CENSUS_ENV)
    seconds = getattr(config, "_kernel_seconds", None)
    if out_dir and seconds:
        name = os.environ.get("PYTEST_XDIST_WORKER", "main") + ".kernels.json"
        with open(os.path.join(out_dir, name), "w", encoding="utf-8") as out:
            json.dump(dict(seconds), out)
