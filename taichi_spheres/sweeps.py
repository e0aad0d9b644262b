"""Parameter sweeps: many independent runs of one scene, on Dask.

``sweep(scene, grid={"restitution": [0.5, 0.9], "step_fraction": [0.1, 0.03]},
duration=2.0)`` runs every combination of the grid's values and returns one row (a
dict) per run: its index, the parameters, ``error`` (None, or what went wrong: a bad
parameter, non-finite positions), ``setup_s`` (building the Simulation: compiling when
its worker has not compiled these features yet), ``wall_s`` (advancing), the
Simulation's ``stats``, its energy books (``energy_*``, J) and what ``measure(sim)``
returned. A failed run is reported in its row; the sweep goes on.

Where the runs go: ``client=None`` starts a ``dask.distributed.LocalCluster`` with one
worker process per core, each running Taichi on one thread (Taichi has one runtime per
process, so processes, not threads, run in parallel); a ``distributed.Client`` or a
scheduler address (``"tcp://host:8786"``, e.g. a ``dask-jobqueue`` cluster) runs them
there; ``serial=True`` runs them one after another in this process, without Dask. A
worker compiles the kernels for the first run of a set of compiled features and later
runs of the same features reuse them (engine.py). Rows are handed to ``on_row`` and
written to ``out`` (CSV) as they finish, so an interrupted sweep keeps them.
"""
from __future__ import annotations

import csv
import inspect
import itertools
import math
import os
import sys
import time
import uuid

import numpy as np

__all__ = ["sweep", "grid_runs", "run_one", "SweepTable", "SIMULATION_PARAMETERS"]

#: grid keys that are arguments of Simulation, not of the scene
SIMULATION_PARAMETERS = ("step_fraction", "max_sweeps", "precision", "fused")
#: what a failed run's row says when a worker died under it
_LOST = "the worker running it was lost"


def grid_runs(grid: dict) -> list[dict]:
    """Every combination of the grid's values, the last key varying fastest."""
    if not isinstance(grid, dict) or not grid:
        raise ValueError("grid must be a non-empty dict: parameter name -> list of values")
    values = []
    for key, items in grid.items():
        if isinstance(items, (str, bytes)) or not hasattr(items, "__iter__"):
            raise ValueError(f"grid[{key!r}] must be a list of values, got {items!r}")
        items = list(items)
        if not items:
            raise ValueError(f"grid[{key!r}] has no values")
        values.append(items)
    return [dict(zip(grid, combo)) for combo in itertools.product(*values)]


def _check_names(scene, grid):
    """ValueError naming a grid key that neither the scene nor Simulation takes."""
    if callable(scene):
        params = inspect.signature(scene).parameters
        if any(p.kind is p.VAR_KEYWORD for p in params.values()):
            return
        known = set(params)
    else:
        from .scene import Scene
        known = set(inspect.signature(Scene.from_arrays).parameters) - {"cls", "x", "v"}
    known |= set(SIMULATION_PARAMETERS)
    for key in grid:
        if key not in known:
            raise ValueError(f"unknown sweep parameter {key!r} (known: "
                             f"{', '.join(sorted(known))})")


def _scene_for(spec, params):
    """The Scene of one run: spec is a Scene, a scene file path or a builder."""
    from .scene import Scene
    from .scenefile import load_scene
    scene_params = {k: v for k, v in params.items() if k not in SIMULATION_PARAMETERS}
    if isinstance(spec, Scene):
        return spec.replace(**scene_params) if scene_params else spec
    if isinstance(spec, (str, os.PathLike)):
        scene = load_scene(spec)
        return scene.replace(**scene_params) if scene_params else scene
    return spec(**scene_params)


def _simulation_args(scene, params, options) -> dict:
    """Simulation arguments of one run: the grid's, else the scene file's [physics]."""
    from .simulation import scene_simulation_settings
    fraction, sweeps, precision = scene_simulation_settings(
        scene, precision=options.get("precision"))
    args = dict(step_fraction=fraction, max_sweeps=sweeps, precision=precision,
                arch=options.get("arch", "cpu"), threads=options.get("threads"))
    args.update({k: v for k, v in params.items() if k in SIMULATION_PARAMETERS})
    return args


def _measured(measure, sim) -> dict:
    if measure is None:
        return {}
    value = measure(sim)
    return dict(value) if isinstance(value, dict) else {"measure": value}


def _finite_state(sim):
    st = sim.state()
    if not (np.isfinite(st.x).all() and np.isfinite(st.v).all()):
        raise FloatingPointError(f"non-finite positions or velocities at t = {sim.time:g} s")


def run_one(spec, params: dict, duration: float, measure=None, options=None) -> dict:
    """One run of a sweep (in a worker process, or here): build the scene and the
    Simulation, advance ``duration`` seconds, and return its row (module docstring).
    Exceptions become the row's ``error``."""
    os.environ.setdefault("ENABLE_TAICHI_HEADER_PRINT", "0")
    options = dict(options or {})
    row = {**params, "error": None, "setup_s": math.nan, "wall_s": math.nan}
    try:
        from . import runtime
        from .cli import compile_mode
        from .simulation import Simulation
        t0 = time.perf_counter()
        scene = _scene_for(spec, params)
        args = _simulation_args(scene, params, options)
        runtime.ensure(args["arch"], args["precision"], args["threads"],
                       compile=compile_mode(options.get("compile", "auto"), scene.n))
        sim = Simulation(scene, **args)
        row["setup_s"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        sim.advance(duration)
        row["wall_s"] = time.perf_counter() - t0
        _finite_state(sim)
        row.update(sim.stats)
        row.update({f"energy_{k}": v for k, v in sim.energy_budget().items()})
        row.update(_measured(measure, sim))
    except Exception as exc:   # the row reports it; the sweep goes on
        row["error"] = f"{type(exc).__name__}: {exc}"
    return row


class SweepTable:
    """The rows of a sweep, written to a CSV file (``path``, or None) as they arrive.

    Columns: run, the parameters, error, setup_s, wall_s, then the keys of the first
    row without an error (rows with errors wait for it, or for close()); later keys
    that are not columns stay in the returned rows only."""

    def __init__(self, path, parameters):
        self.path = None if path is None else os.fspath(path)
        self.lead = ["run", *parameters, "error", "setup_s", "wall_s"]
        self.rows, self._waiting = [], []
        self._fh = self._csv = None
        if self.path is not None:
            from .output import check_writable
            check_writable(self.path)

    def add(self, row: dict) -> None:
        self.rows.append(row)
        if self.path is None:
            return
        self._waiting.append(row)
        if self._csv is None and row["error"] is None:
            self._start(list(row))
        if self._csv is not None:
            self._flush()

    def _start(self, keys):
        columns = self.lead + [k for k in keys if k not in self.lead]
        self._fh = open(self.path, "w", newline="")
        self._csv = csv.DictWriter(self._fh, columns, extrasaction="ignore")
        self._csv.writeheader()

    def _flush(self):
        from .interrupts import hold_interrupts
        with hold_interrupts():
            self._csv.writerows(self._waiting)
            self._fh.flush()
        self._waiting = []

    def close(self) -> list[dict]:
        """Write what waits, close the file; the rows in run order."""
        if self.path is not None:
            if self._csv is None:
                self._start([])
            self._flush()
            self._fh.close()
        return sorted(self.rows, key=lambda r: r["run"])


def _progress(total, parameters, stream=sys.stderr):
    """on_row callback printing a line per finished run."""
    done = [0]

    def report(row):
        done[0] += 1
        params = ", ".join(f"{k}={row[k]}" for k in parameters)
        status = f"error: {row['error']}" if row["error"] else f"{row['wall_s']:.2f} s"
        print(f"sweep: {done[0]}/{total} done (run {row['run']}: {params}; {status})",
              file=stream, flush=True)
    return report


def sweep(scene, grid: dict, duration: float, measure=None, client=None, *,
          serial: bool = False, workers: int | None = None, threads: int | None = 1,
          arch: str = "cpu", precision: str | None = None, compile: str = "auto",
          out=None, on_row=None, progress: bool = False) -> list[dict]:
    """Run ``scene`` once per combination of ``grid``'s values for ``duration`` seconds
    of simulated time; the rows in run order (module docstring).

    scene: a Scene (grid keys: arguments of Scene.from_arrays such as restitution,
    wall_restitution, gravity, restitution_model, rest_speed), a scene file path, or a
    builder ``f(**params) -> Scene`` (picklable, e.g. a module-level function);
    grid keys in SIMULATION_PARAMETERS go to Simulation. measure: ``f(sim) -> dict or
    number`` after the run (picklable). client: None (a LocalCluster of ``workers``
    processes, default one per core), a ``distributed.Client``, or a scheduler
    address. serial: run here, one after another, without Dask. threads: Taichi CPU
    threads per run. compile: "auto", "fast" or "optimized" (as the command line).
    out: CSV path written as rows finish. on_row: called with each finished row.
    progress: print a line per finished run on stderr.
    """
    duration = float(duration)
    if not (math.isfinite(duration) and duration >= 0.0):
        raise ValueError(f"duration must be a finite number >= 0 s, got {duration}")
    _check_names(scene, grid)
    runs = grid_runs(grid)
    options = dict(arch=arch, precision=precision, threads=threads, compile=compile)
    table = SweepTable(out, list(grid))
    callbacks = [f for f in (on_row, _progress(len(runs), list(grid)) if progress else None)
                 if f]

    def finished(row):
        table.add(row)
        for f in callbacks:
            f(row)
    try:
        if serial:
            for k, params in enumerate(runs):
                finished({"run": k, **run_one(scene, params, duration, measure, options)})
        else:
            _run_on_dask(scene, runs, duration, measure, options, client, workers, finished)
    finally:
        rows = table.close()
    return rows


def _distributed():
    try:
        import distributed
    except ImportError:
        raise RuntimeError("sweeps on Dask need dask.distributed: pip install "
                           "'taichi_spheres[sweep]' (or pass serial=True)") from None
    return distributed


def _run_on_dask(spec, runs, duration, measure, options, client, workers, finished):
    """Submit every run to a Dask cluster and hand each row to ``finished`` as it ends."""
    distributed = _distributed()
    own = None
    if client is None:
        own = distributed.LocalCluster(n_workers=workers or os.cpu_count() or 1,
                                       threads_per_worker=1, processes=True,
                                       dashboard_address=None)
        client = distributed.Client(own)
    elif isinstance(client, str):
        client = own = distributed.Client(client)
    index, pending = {}, []
    sweep_id = uuid.uuid4().hex[:8]   # keys of its own: later sweeps on the same client
    try:
        for k, params in enumerate(runs):
            fut = client.submit(run_one, spec, params, duration, measure, options,
                                pure=False, key=f"taichi-spheres-{sweep_id}-run-{k}")
            index[fut.key] = (k, params)
            pending.append(fut)
        for fut in distributed.as_completed(pending):
            k, params = index[fut.key]
            finished({"run": k, **_result(fut, params)})
    finally:
        if own is not None:
            client.close()
            own.close()
        else:
            client.cancel(pending)


def _result(fut, params) -> dict:
    """The row a finished future holds; a row with the error if the task itself failed
    (a worker that died under it)."""
    try:
        return fut.result()
    except Exception as exc:
        return {**params, "error": f"{_LOST}: {type(exc).__name__}: {exc}",
                "setup_s": math.nan, "wall_s": math.nan}
