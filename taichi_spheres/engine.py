"""Compiled engines, shared by the Simulations of one process: kernels compile once.

Taichi compiles a kernel for the fields it touches. An :class:`Engine` is one set of
fields (state, parameters, grid, contacts, projection) with the kernels over them; the
scene's numbers (sphere count, box, cell layout, radii, masses, restitution, gravity)
are data in those fields, and only what changes the code is compiled in: the
features (``state.Features``), the serial/parallel loop variants chosen by the
sphere count, near lists, and the options (``config.Tuning.compiled``: less those only
the host reads, those that choose a variant of the contact solver's sweeping kernels
(built on first use), and the contact solver's sweep rules, which are data too). A
Simulation asks the pool for an engine with its key and room for its spheres and
cells; a later Simulation with the same key and no more spheres or cells runs on the same engine
and compiles nothing (``tools/compile_once.py`` measures it).

Several live Simulations may share one engine: the one that runs binds the engine
(:meth:`Engine.bind`) and the one it replaces parks its positions and velocities on
the host first (exact copies). Everything else an engine's fields hold is rebuilt by
every step, so a Simulation gives the same bits whichever others ran in between.

The pool lives as long as the Taichi runtime: a re-initialisation (other arch,
precision, thread count or compile mode) empties it.
"""
from __future__ import annotations

import dataclasses
import weakref

from .config import Performance, Tuning
from .contacts import Contacts
from .contacts.solver import ContactSolver
from .fused import FusedStep
from .grid import Grid, GridGeometry
from .hostload import FieldLoad
from .params import StepParams
from .projection import Projection
from .state import Features, SphereState
from .takeout import SinkTakeOut
from .walls import Motion

__all__ = ["Schedule", "EngineKey", "Engine", "acquire", "capacity_for"]


@dataclasses.dataclass(frozen=True)
class Schedule:
    """Which path a step takes, decided once per Simulation from the sphere count, the
    arch and the options (config.Performance):

    serial_light: the light loops (drift, grid build, re-binning) run serially (CPU,
        below serial_light_below spheres: a parallel launch costs more than the loop);
    serial_heavy: every loop runs serially, detection and sweeps too (CPU, below
        serial_heavy_below); the fused step is available;
    serial_few: a sweep with few pending pairs runs serially, one with more resolves
        serially and detects in parallel (CPU, above serial_heavy_below); otherwise a
        sweep launches one parallel kernel per colour (always on GPUs);
    near_lists: detection keeps near lists (from near_lists_from spheres on, where the
        cells leave room for moves);
    fused: each step is one or two kernel launches (fused.py; asked for, and
        serial_heavy)."""

    serial_light: bool
    serial_heavy: bool
    serial_few: bool
    near_lists: bool
    fused: bool

    @classmethod
    def plan(cls, n: int, cpu: bool, near_lists: bool, fused: bool,
             perf: Performance) -> "Schedule":
        """The schedule of n spheres on the CPU (cpu) or a GPU."""
        heavy = cpu and n < perf.serial_heavy_below
        return cls(serial_light=cpu and n < perf.serial_light_below, serial_heavy=heavy,
                   serial_few=cpu and not heavy, near_lists=near_lists, fused=fused and heavy)

    def describe(self) -> list:
        """Human-readable lines (``taichi-spheres info``)."""
        sweeps = ("serial, all colours in one launch" if self.serial_heavy else
                  "serial below few_pairs pending pairs, serial resolve with parallel "
                  "detection below serial_resolve_pairs, else one launch per colour"
                  if self.serial_few else "one parallel launch per colour")
        return ["step: " + ("fused (one or two kernel launches)" if self.fused
                            else "kernel by kernel"),
                "drift and grid build: " + ("serial" if self.serial_light else "parallel"),
                "detection: " + ("serial" if self.serial_heavy else "parallel") +
                (", from near lists" if self.near_lists else ", full grid scans"),
                "sweeps: " + sweeps]


@dataclasses.dataclass(frozen=True)
class EngineKey:
    """What an engine's kernels compile in: the Taichi runtime it was built on
    (runtime.Runtime.generation: arch, precision, threads, compile mode), the scene's
    features, the loop variants (serial_light: cheap loops serial; serial_heavy:
    detection and sweeps serial; serial_few: a serial sweep variant for few pairs),
    near lists, and the options (config.Tuning.compiled)."""

    generation: int
    real: object
    features: Features
    serial_light: bool
    serial_heavy: bool
    serial_few: bool
    near_lists: bool
    tuning: Tuning


class Engine:
    """Fields and kernels for up to ``capacity`` spheres and ``cell_capacity`` cells.

    Parts: state (SphereState), params (StepParams), motion (Motion), grid (Grid),
    contacts (Contacts), projection (Projection), solver (contacts.solver.ContactSolver,
    only with Features.contacts), and the fused step
    (:meth:`fused_step`, built on first use)."""

    def __init__(self, key: EngineKey, capacity: int, cell_capacity: int):
        self.key = key
        self.capacity = capacity
        self.cell_capacity = cell_capacity
        f = key.features
        self.state = SphereState(capacity, f, key.real)
        self.params = StepParams(key.real, f.materials)
        t = key.tuning
        self.motion = Motion(self.state, self.params, f, key.serial_light, t)
        periodic = tuple(not w for w in f.wall_axes)
        self.grid = Grid(cell_capacity, periodic, self.state, key.serial_light,
                         t.performance.scan_block)
        self.contacts = Contacts(self.state, self.grid, self.params, self.motion, f,
                                 key.serial_light, key.serial_heavy,
                                 serial_few=key.serial_few, near_lists=key.near_lists, tuning=t)
        self.projection = Projection(self.state, self.grid, self.contacts, self.motion, f,
                                     key.serial_light, t)
        self.solver = ContactSolver(self.state, self.grid, self.params, self.contacts, f,
                                    key.serial_heavy, t,
                                    cpu=key.serial_heavy or key.serial_few) \
            if f.contacts else None
        # every part's fields loaded from the host, in one kernel (hostload.py)
        self.host_load = FieldLoad(self._loading_parts(), key.real)
        for part in self._loading_parts():
            part.host_load = self.host_load
        self._fused = None
        self._take_out = None      # takeout.SinkTakeOut, built on first use
        self._occupant = None      # weakref to the Simulation bound last
        self._scalars = None       # what the scene's scalars were loaded from (bind)

    def _loading_parts(self) -> tuple:
        """The parts whose bind loads fields from the host (their loaded_fields)."""
        return tuple(p for p in (self.state, self.params, self.grid, self.contacts,
                                 self.solver) if p is not None)

    def release(self, sim) -> None:
        """Forget that ``sim`` is bound (its scene changed: the next bind loads it all)."""
        if self.bound_to(sim):
            self._occupant = None

    def fits(self, n: int, n_cells: int) -> bool:
        return n <= self.capacity and n_cells <= self.cell_capacity

    def fused_step(self) -> FusedStep:
        """The fused step over this engine's parts (compiled on its first launch)."""
        if self._fused is None:
            self._fused = FusedStep(self.motion, self.grid, self.contacts, self.projection,
                                    self.key.real, self.key.features.contacts,
                                    self.projection.tolerance)
        return self._fused

    def bound_to(self, sim) -> bool:
        return self._occupant is not None and self._occupant() is sim

    def bind(self, sim, x, v, geom: GridGeometry, rest_speed: float, warm=None,
             omega=None, reach=None) -> None:
        """Make ``sim`` the Simulation these fields hold: park the previous one's
        positions, velocities, spins and contact impulses on the host (its ``_park``),
        then load ``sim``'s scene, x, v [(n, 3)], grid geometry, rest speed [m/s], the
        contact solver's warm start (``warm``: ContactSolver.warm_rows, or None), the
        spins omega [(n, 3) rad/s, or None: zero] and the contact rows' reach [m] (the
        speculative margin, at most the grid's slack; None: the slack)."""
        previous = self._occupant() if self._occupant is not None else None
        if previous is not None and previous is not sim:
            previous._park()
        scene = sim.scene
        self.state.bind(scene, x, v, omega)
        self.params.bind(scene, rest_speed)
        self.grid.bind(geom)
        perf = sim.tuning.performance
        self.contacts.bind(scene, geom, perf)
        if self.solver is not None:
            self.solver.bind(scene, geom, reach, sim.tuning.physics, perf)
            if warm is not None:
                self.solver.load_warm(warm)
        self._occupant = weakref.ref(sim)
        self._scalars = scalar_sources(scene, reach)

    def keep_spheres(self, sim, x, v, omega, kept, reach=None) -> None:
        """After a sink took spheres out of ``sim`` (bound here): load ``sim.scene``, the
        spheres that stay, with their x, v, omega [(n, 3)], and move their contact
        solver's warm start down to their new indices (``kept``: (n_before,) bool, or
        None: every sphere stayed, some moved). The same fields as bind with the
        renumbered table (discharge.renumber_warm), without the host round trip of the
        tables and the scene's constants (box, materials, geometry, sinks, grid)."""
        if not self.bound_to(sim):
            raise RuntimeError("keep_spheres: the Simulation is not the one bound here")
        scene = sim.scene
        self.state.bind(scene, x, v, omega)
        self.contacts.bind(scene, sim.geometry, sim.tuning.performance)
        if self.solver is not None:
            self.solver.keep_spheres(scene, sim.geometry, reach, kept)
        self._scalars = scalar_sources(scene, reach)

    def take_out(self, sim):
        """Take the spheres in ``sim``'s sinks (bound here; none of them recycles) out
        of the fields in one launch (takeout.py); returns (indices (k,), rows (k, 9):
        x, v, omega) of the k taken, in the fields' precision. Call
        :meth:`after_take_out` once ``sim.scene`` holds the spheres that stay."""
        if not self.bound_to(sim):
            raise RuntimeError("take_out: the Simulation is not the one bound here")
        if any(s.recycle for s in sim.scene.sinks):
            raise ValueError("take_out: a recycling sink puts spheres back (discharge.py)")
        if self._take_out is None:
            self._take_out = SinkTakeOut(self.state, self.params, self.motion, self.contacts,
                                         self.solver, self.key.serial_light)
        return self._take_out.run()

    def after_take_out(self, sim, reach=None) -> None:
        """The scalars bind loads from ``sim.scene`` (now the spheres that stay) and the
        rows' reach [m], loaded again where those they follow from changed (the
        first sphere's radius and mass, the smallest and largest radius, the reach);
        the near lists forgotten (their indices are the old ones)."""
        scene = sim.scene
        self.state.n = scene.n
        sources = scalar_sources(scene, reach)
        if sources != self._scalars:
            self.state.bind_uniform(scene)
            self.contacts.bind_scalars(scene, sim.geometry)
            if self.solver is not None:
                self.solver.bind_scalars(scene, sim.geometry, reach)
            self._scalars = sources
        self.contacts.n = scene.n
        self.contacts.near_ready = False
        if self.solver is not None:
            self.solver.n = scene.n


def scalar_sources(scene, reach) -> tuple:
    """What the scalars bind loads follow from besides the grid: the first sphere's
    radius [m] and mass [kg], the smallest and largest radius [m], the rows' reach [m]."""
    return (float(scene.radius[0]), float(scene.mass[0]), float(scene.radius.min()),
            float(scene.radius.max()), reach)


#: A new engine has room for at least this many spheres and cells: small scenes share
#: one engine (a few MB of fields for a contact scene in f64), and a later scene of a
#: few thousand spheres still fits, without compiling its kernels again.
MIN_SPHERES = 4096
MIN_CELLS = 16384


def capacity_for(count: int, minimum: int) -> int:
    """Room a new engine makes for ``count`` spheres or cells: at least ``minimum``,
    rounded up to the next of 1, 1.25, 1.5, 1.75 x a power of two (at most 25 % more),
    so that later Simulations a little larger still fit."""
    count = max(int(count), minimum)
    power = 1 << (count.bit_length() - 1)
    for quarter in (4, 5, 6, 7, 8):
        room = power * quarter // 4
        if room >= count:
            return room
    return 2 * power


_pool: list = []
_pool_generation = None


def acquire(key: EngineKey, n: int, n_cells: int) -> Engine:
    """An engine of the pool with ``key`` and room for n spheres and n_cells cells (the
    smallest such), or a new one with room for them (capacity_for)."""
    global _pool_generation
    if _pool_generation != key.generation:
        _pool.clear()     # the fields of another Taichi runtime are gone
        _pool_generation = key.generation
    fitting = [e for e in _pool if e.key == key and e.fits(n, n_cells)]
    if fitting:
        return min(fitting, key=lambda e: (e.capacity, e.cell_capacity))
    engine = Engine(key, capacity_for(n, MIN_SPHERES), capacity_for(n_cells, MIN_CELLS))
    _pool.append(engine)
    return engine


def field_parts(engine: Engine) -> tuple:
    """The objects whose attributes hold an engine's Taichi fields."""
    parts = (engine.state, engine.params, engine.motion, engine.grid, engine.contacts,
             engine.projection)
    return parts + ((engine.solver,) if engine.solver is not None else ())
