"""Simulation: the public engine object (scene -> state -> step loop).

One step of length h (docs/design.md, "One step, in parallel"):
  1. drift every sphere on its exact ballistic path and apply walls (walls.py);
  2. build the uniform grid with a deterministic counting sort (grid.py);
  3. detect overlapping approaching pairs in parallel (contacts.py);
  4. sweep: resolve them colour by colour, rewinding each pair to contact; repeat
     detection around the spheres that changed until none is left or
     ``max_sweeps`` is reached; what is left is counted in ``stats['unresolved']``;
  5. with the contact solver (inelastic pairs under gravity): solve the persistent
     contacts, the pairs and walls touching or nearly touching that approach slower
     than the impact speed (contacts/solver.py);
  6. adaptive h: no sphere moves more than ``step_fraction`` x the smallest radius
     in one step (including the g h^2/2 of gravity), and steps end exactly on the
     times asked for.
"""
from __future__ import annotations

import dataclasses
import math
import time as _time
import types

import numpy as np
import taichi as ti
from taichi.lang.util import to_numpy_type

from . import engine as engines
from . import runtime
from .config import DEFAULT, Performance, Tuning
from .contacts import near_allowance
from .contacts.packed import packed_row_bytes, packs_rows
from .grid import GridGeometry
from . import discharge, observe, stepping
from .checkpoint import scene_digest
from .scene import (Scene, check_state, scene_precision_problems, speed_problem,
                    spin_problem)
from .state import Features, State

__all__ = ["Simulation", "DEFAULT_STEP_FRACTION", "DEFAULT_MAX_SWEEPS", "rest_speed_for",
           "estimate_field_bytes", "field_bytes_for"]

#: Default largest move per step as a fraction of the smallest radius. Two spheres
#: then close in by at most 0.2 r per step, so a pair can only pass through each
#: other unseen if its chord through the overlap is shorter than that: impact
#: parameters within (0.1)^2/4 = 0.25 % of sigma^2 of grazing, which exchange almost
#: no momentum. Tighter values trade speed for accuracy (tools/work_precision.py).
DEFAULT_STEP_FRACTION = 0.1
#: Default limit on detect/resolve sweeps per step.
DEFAULT_MAX_SWEEPS = 32


def rest_speed_for(scene: Scene, step_fraction: float = DEFAULT_STEP_FRACTION,
                   tuning: Tuning = DEFAULT) -> float:
    """The impact speed a Simulation uses [m/s] (contacts/solver.py): approaches faster
    than it are impacts (exact rewind with restitution), slower ones at touching or
    nearly touching pairs and walls are persistent contacts. With gravity
    Rules.impact_factor x sqrt(2 |g| D), D = step_fraction x r_min: sqrt(2 g D) is
    the speed gravity adds in the longest step a resting scene takes (g h for h =
    sqrt(2 D / g)); the scene's ``rest_speed`` if larger; 0 (no contact solver)
    without either, and always for elastic pairs without friction (e = 1 stays
    exactly elastic)."""
    elastic = getattr(scene, "elastic_pairs", scene.restitution == 1.0)
    if elastic and not getattr(scene, "frictional", False):
        return 0.0
    g = float(np.linalg.norm(scene.gravity))
    speed = tuning.physics.impact_factor * \
        math.sqrt(2.0 * g * step_fraction * float(scene.radius.min()))
    return max(speed, float(scene.rest_speed or 0.0))


def _scene_spins(scene: Scene) -> np.ndarray:
    """The scene's initial spins (N, 3) [rad/s] (zeros when it gives none)."""
    omega = getattr(scene, "omega", None)
    return np.zeros_like(scene.v) if omega is None else omega


def estimate_field_bytes(scene: Scene, precision: str = "f64",
                         step_fraction: float = DEFAULT_STEP_FRACTION,
                         tuning: Tuning = DEFAULT) -> int:
    """Device memory a Simulation of ``scene`` allocates for its Taichi fields [bytes]
    when it builds a new engine (room for engine.capacity_for its spheres and cells),
    counted per sphere and per grid cell without initialising Taichi (``cli info``).
    tests/test_gas.py holds it to within 3 % of :meth:`Simulation.field_bytes`."""
    geom = GridGeometry.for_scene(scene, step_fraction, tuning.performance)
    features = Features.from_scene(scene, rest_speed_for(scene, step_fraction, tuning))
    return field_bytes_for(engines.capacity_for(scene.n, engines.MIN_SPHERES),
                           engines.capacity_for(geom.n_cells, engines.MIN_CELLS), features,
                           _keeps_near_lists(scene, geom, tuning.performance), precision,
                           tuning.performance)


def field_bytes_for(spheres: int, cells: int, features: Features, near_lists: bool,
                    precision: str, perf: Performance = DEFAULT.performance,
                    cpu: bool = True) -> int:
    """Bytes of an engine's fields with room for ``spheres`` and ``cells`` [bytes] (``cpu``:
    an engine on the CPU, whose contact solver also lists its rows for its sweeps)."""
    real = 8 if precision == "f64" else 4
    # x, v, grid.xs, projection push (4 vec3), moved, earliest, projection rmax; hits,
    # marked, touched, order, cell_of, slot, projection involved/near/stamp
    per_sphere = 12 * real + 3 * real + 9 * 4
    per_sphere += (0 if features.equal_radii else real) + (0 if features.equal_masses else real)
    if near_lists:
        per_sphere += (perf.near_capacity + 2) * 4 + 3 * real   # near, near_id, n_near; x_near
    per_cell = 9 * 4   # start, cursor; active, cell_pairs (2 x 2), active_list, by_colour
    if features.contacts:
        # solver rows (a, b; normal, gap, targets, meff, lam, mu), v_pre, x_pre, w, warm
        # table; warm_n, unrowed, the state's loaded and near flags
        per_sphere += perf.contacts_per_sphere * (2 * 4 + 9 * real) + 9 * real \
            + perf.warm_slots * (4 + real) + 4 * 4
        if features.gravity:
            per_sphere += real      # drop (ContactSolver.close_support_gaps)
        if cpu:
            per_sphere += perf.contacts_per_sphere * 4    # schedule (pgs.schedule_rows)
        if packs_rows(features, spheres, cpu):             # contacts/packed.py
            per_sphere += perf.contacts_per_sphere * packed_row_bytes(real)
        per_cell += 4 * 4   # cell_count, cell_fill, cell_start, active_cells
    return spheres * per_sphere + cells * per_cell


def _keeps_near_lists(scene: Scene, geom: GridGeometry, perf: Performance) -> bool:
    """Whether a Simulation of ``scene`` on grid ``geom`` keeps near lists: from
    perf.near_lists_from spheres on, where the cells leave room for moves."""
    return scene.n >= perf.near_lists_from and \
        near_allowance(geom, float(scene.radius.max()), perf.near_safety)[1] > 0


def scene_simulation_settings(scene: Scene, step_fraction=None, max_sweeps=None,
                              precision=None) -> tuple:
    """(step_fraction, max_sweeps, precision) of a Simulation: each argument given,
    else the scene file's ``[physics]`` value (``scene.meta["physics"]``), else the
    default (DEFAULT_STEP_FRACTION, DEFAULT_MAX_SWEEPS; precision None: the arch's)."""
    physics = scene.meta.get("physics", {}) if isinstance(scene, Scene) else {}
    if step_fraction is None:
        step_fraction = physics.get("step_fraction", DEFAULT_STEP_FRACTION)
    if max_sweeps is None:
        max_sweeps = physics.get("max_sweeps", DEFAULT_MAX_SWEEPS)
    if precision is None:
        precision = physics.get("precision")
    return step_fraction, max_sweeps, precision


def check_step_fraction(step_fraction) -> float:
    """``step_fraction`` (a Simulation's largest move per step / smallest radius) as a
    float; ValueError unless it is a number in (0, 1] (a bool or a string is not). The
    one check of a Simulation's argument and of the tools' options."""
    message = "step_fraction must be a number in (0, 1], got {!r}"
    if isinstance(step_fraction, (bool, np.bool_, str, bytes, bytearray)):
        raise ValueError(message.format(step_fraction))
    try:
        value = float(step_fraction)
    except (TypeError, ValueError):
        raise ValueError(message.format(step_fraction)) from None
    if not 0.0 < value <= 1.0:
        raise ValueError(message.format(value))
    return value


def _check_precision(scene: Scene, precision: str, step_fraction: float) -> None:
    """ValueError naming the sphere whose speed, radius (for the box and step bound) or
    mass ``precision`` cannot hold (scene.scene_precision_problems), as ``taichi-spheres
    run`` refuses them."""
    problems = scene_precision_problems(scene, precision, step_fraction)
    if problems:
        raise ValueError("; ".join(problems))


def _checked_arguments(scene, step_fraction, max_sweeps, fused, compile_all, tuning) -> float:
    """Raise ValueError naming a bad Simulation argument; returns step_fraction."""
    if not isinstance(scene, Scene):
        raise ValueError(f"scene must be a taichi_spheres.Scene, got {type(scene).__name__}")
    step_fraction = check_step_fraction(step_fraction)
    if not isinstance(max_sweeps, int) or max_sweeps < 1:
        raise ValueError(f"max_sweeps must be a positive int, got {max_sweeps!r}")
    if not isinstance(fused, bool):
        raise ValueError(f"fused must be True or False, got {fused!r}")
    if not isinstance(compile_all, bool):
        raise ValueError(f"compile_all must be True or False, got {compile_all!r}")
    if tuning is not None and not isinstance(tuning, Tuning):
        raise ValueError(f"tuning must be a taichi_spheres.config.Tuning, got "
                         f"{type(tuning).__name__}")
    return step_fraction


def _field_nbytes(field) -> int:
    """Bytes of one Taichi field [bytes]: elements x components x dtype size."""
    components = field.n * field.m if isinstance(field, ti.MatrixField) else 1
    return int(np.prod(field.shape, dtype=np.int64)) * components * \
        np.dtype(to_numpy_type(field.dtype)).itemsize


class Simulation:
    """Hard-sphere simulation of a :class:`Scene` on a Taichi backend.

    arch: 'cpu' | 'gpu' | 'cuda' | 'vulkan' | 'metal'. precision: 'f64' (default on
    cpu/cuda) or 'f32' (default on vulkan/metal). step_fraction: largest move per
    step / smallest radius, in (0, 1] (default 0.1). max_sweeps: detect/resolve sweeps
    per step (default 32). precision, step_fraction and max_sweeps left None take the
    scene file's ``[physics]`` values where it has them (scene_simulation_settings), as
    ``taichi-spheres run`` does.
    threads: CPU threads (None: Taichi's default). compile_all: compile every
    optional feature in even when the scene does not need it (same results; for
    measuring what compiling them out saves). fused: for systems small enough that
    the CPU runs every loop serially (below 3,000 spheres), run each step as one or
    two kernel launches (fused.py; same bits; 1,000 spheres piling up ran 1.45x
    faster in tools/peer_lammps.py), at the price of compiling its kernels once per scene
    (~10-60 s on 2 cores; Taichi's offline cache keeps them for later runs); ignored
    elsewhere. Off by default: worth it for long or repeated runs. tuning: the
    engine's options (config.Tuning: physics rules and performance knobs; default: the
    scene file's [tuning] table, ``scene.meta["tuning"]``, on config.DEFAULT).
    """

    def __init__(self, scene: Scene, arch: str = "cpu", precision: str | None = None,
                 step_fraction: float | None = None,
                 max_sweeps: int | None = None, threads: int | None = None,
                 compile_all: bool = False, fused: bool = False, tuning: Tuning | None = None):
        step_fraction, max_sweeps, precision = scene_simulation_settings(
            scene, step_fraction, max_sweeps, precision)
        step_fraction = _checked_arguments(scene, step_fraction, max_sweeps, fused,
                                           compile_all, tuning)
        self.scene = scene
        self.step_fraction = step_fraction
        self.max_sweeps = max_sweeps
        self.tuning = tuning or DEFAULT.with_(**scene.meta.get("tuning", {}))
        self.rest_speed = rest_speed_for(scene, step_fraction, self.tuning)
        self.features = Features.from_scene(scene, self.rest_speed)
        if compile_all:
            self.features = Features(gravity_axes=(True, True, True),
                                     wall_axes=self.features.wall_axes, equal_radii=False,
                                     equal_masses=False, elastic=False, elastic_walls=False,
                                     smid=self.features.smid, contacts=self.features.contacts,
                                     friction=self.features.friction,
                                     rolling=self.features.rolling,
                                     geometry=self.features.geometry)
        self.geometry = GridGeometry.for_scene(scene, step_fraction, self.tuning.performance)
        self.runtime = runtime.ensure(arch, precision, threads)
        self.precision = self.runtime.precision
        _check_precision(scene, self.precision, step_fraction)
        #: which path a step takes (engine.Schedule)
        self.schedule = engines.Schedule.plan(
            scene.n, self.runtime.is_cpu,
            _keeps_near_lists(scene, self.geometry, self.tuning.performance), fused,
            self.tuning.performance)
        self._engine = engines.acquire(self._engine_key(self.schedule), scene.n,
                                       self.geometry.n_cells)
        self._parked = (scene.x, scene.v, _scene_spins(scene), None)
        self._bind()
        #: spheres left in sinks by the last discharge (recycled, no free spot found)
        self._stuck_in_sinks = 0
        #: drift and impacts in substeps, the contact solver once per step (Rules.substeps)
        self._substeps = bool(self.tuning.physics.substeps and self._engine.solver is not None
                              and self.rest_speed > 0)
        self._r_min = float(scene.radius.min())
        self._g = float(np.linalg.norm(scene.gravity))
        self.time = 0.0
        self._totals = dict(steps=0, pair_collisions=0, wall_collisions=0, wall_rests=0,
                            sweeps=0, unresolved=0, max_overlap=0.0, sweep_limit_hits=0,
                            grid_rebuilds=0, multi_collision_spheres=0,
                            collapse_collisions=0, energy_pair_restitution=0.0,
                            energy_wall_restitution=0.0, energy_collapse=0.0,
                            energy_contacts=0.0, virial=0.0, projected_steps=0,
                            projected_pairs=0, near_list_detections=0, contacts=0,
                            contact_iterations=0, position_iterations=0,
                            contact_residual=0.0, contact_steps=0, discharged=0,
                            discharged_mass=0.0, energy_discharged=0.0,
                            warm_starts_scaled=0, substeps=0)
        self._sink_rng = np.random.default_rng(12345)   # free spots of recycled spheres
        #: scene indices of the spheres still simulated (sinks take some out)
        self.sphere_ids = np.arange(scene.n)
        self._original_scene = scene
        # how a step runs (stepping.py): kernel by kernel, or fused for small CPU systems
        self._stepper = stepping.Stepper(self, fused=self.schedule.fused)
        self.initial_energy = observe.total_energy(scene, scene.gravity)
        self.last_step = dict(h=0.0, unresolved=0, max_overlap=0.0, sweeps=0)
        self.sim_seconds = 0.0   # wall-clock time spent in advance()
        self._measure_vmax()

    # ---- public API ----
    @property
    def n(self) -> int:
        return self.scene.n

    @property
    def fused(self) -> bool:
        """True when steps run as a fused kernel (asked for, CPU, below 3,000 spheres)."""
        return self._stepper.fused

    @property
    def overlap_tolerance(self) -> float:
        """Relative overlap above which the projection pushes pairs apart (fixed when the
        kernels are built: config.Rules.overlap_tolerance)."""
        return self.tuning.physics.overlap_tolerance

    def field_bytes(self) -> int:
        """Bytes of the Taichi fields this Simulation runs on [bytes], from their shapes
        and dtypes (state, parameters and their counters, motion, grid, contacts,
        projection): those of its engine (engine.py), sized for at least its spheres and
        cells, shared with other Simulations of the same features."""
        seen, total = set(), 0
        for part in engines.field_parts(self._engine):
            for value in vars(part).values():
                for item in value if isinstance(value, (list, tuple)) else (value,):
                    if isinstance(item, ti.Field) and id(item) not in seen:
                        seen.add(id(item))
                        total += _field_nbytes(item)
        return total

    @property
    def stats(self) -> dict:
        """Counters since the start: steps, pair_collisions, wall_collisions (impacts),
        sweeps, max_overlap (largest overlap left after a step / contact distance),
        unresolved (approaching overlaps left when a step hit the sweep limit, summed
        over steps), wall_rests, sweep_limit_hits, grid_rebuilds;
        multi_collision_spheres (spheres with more than one pair or wall collision in
        a step, summed over steps: collisions of one sphere within a step are
        resolved one after another, a source of error), collapse_collisions (impacts
        made perfectly inelastic by the collapse rule); energy_pair_restitution,
        energy_wall_restitution, energy_collapse (energy removed by impacts [J]),
        energy_contacts (by the contact solver [J]; see :meth:`energy_budget`); virial
        (sum over pair collisions of r_ij . dp_i at contact [J s]: the collisional
        pressure over a time T in volume V is virial / (3 V T)); near_list_detections
        (full detections taken from the near lists instead of a grid scan: same pairs,
        see contacts.Contacts.detect); of the contact solver (contacts/solver.py):
        contact_steps (steps it ran), contacts (rows, summed over steps),
        contact_iterations and position_iterations (velocity and split-impulse sweeps,
        summed), contact_residual (largest velocity change of a last sweep [m/s]),
        warm_starts_scaled (steps whose warm start it scaled down so that it would add
        no energy: contacts/warm_energy.py); substeps (the drift and impact substeps the
        steps ran in: stepping.py); plus
        discharged, discharged_mass [kg], energy_discharged [J] (spheres that entered a
        sink: discharge.py); plus time and dt."""
        out = dict(self._totals)
        out["time"] = self.time
        out["dt"] = self.last_step["h"]
        return out

    def energy_budget(self) -> dict:
        """Where the energy went since the start [J]: initial, current (kinetic with
        rotational + potential, potential -m g.x), kinetic, potential, the losses booked
        by pair restitution, wall restitution (impacts, their friction included), the
        collapse rule and the contact solver (``contacts``), the energy the spheres took
        into sinks (``discharged``), and ``unaccounted`` = initial - current - booked losses
        (round-off; or the energy of wall rests and of overlaps the projection moved)."""
        st = self.state()
        ke = observe.kinetic_energy(st) + observe.rotational_energy(st)
        pe = observe.potential_energy(st, self.scene.gravity)
        t = self._totals
        booked = (t["energy_pair_restitution"] + t["energy_wall_restitution"]
                  + t["energy_collapse"] + t["energy_contacts"] + t["energy_discharged"])
        return dict(initial=self.initial_energy, current=ke + pe, kinetic=ke, potential=pe,
                    pair_restitution=t["energy_pair_restitution"],
                    wall_restitution=t["energy_wall_restitution"],
                    collapse=t["energy_collapse"], contacts=t["energy_contacts"],
                    discharged=t["energy_discharged"],
                    unaccounted=self.initial_energy - (ke + pe) - booked)

    def state(self) -> State:
        """Numpy (float64) copy of positions, velocities, radii, masses and time."""
        if self.n == 0:
            empty = np.zeros((0, 3))
            return State(x=empty, v=empty, radius=np.zeros(0), mass=np.zeros(0),
                         time=self.time, omega=empty)
        self._check()
        return State(x=self._engine.state.positions(), v=self._engine.state.velocities(),
                     radius=self.scene.radius.copy(), mass=self.scene.mass.copy(),
                     time=self.time, omega=self._engine.state.spins())

    def set_state(self, x, v, time=None, omega=None):
        """Overwrite positions x [m], velocities v [m/s] and spins omega [rad/s] (None:
        zero), each (N, 3), and the time [s] if given (e.g. from a checkpoint).
        ValueError for a wrong shape, a value that is not finite or a centre outside the
        box, or a speed the precision cannot hold, naming the sphere (scene.check_state),
        and for spins in a scene without friction (they are not simulated). Overlaps are
        not checked: a state the engine wrote may hold the small ones its steps leave."""
        self._check()
        x = np.asarray(x, dtype=np.float64)
        v = np.asarray(v, dtype=np.float64)
        omega = np.zeros_like(v) if omega is None else np.asarray(omega, dtype=np.float64)
        if x.shape != (self.n, 3) or v.shape != (self.n, 3) or omega.shape != (self.n, 3):
            raise ValueError(f"x, v and omega must have shape ({self.n}, 3)")
        if time is not None and not math.isfinite(float(time)):
            raise ValueError(f"time must be finite, got {time!r}")
        check_state(x, v, omega, self.scene.box_lo, self.scene.box_hi, self.scene.periodic,
                    self.sphere_ids)
        too_fast = speed_problem(self.precision, v)
        problem = too_fast or spin_problem(omega, self.features.friction, self.sphere_ids)
        if problem:
            raise ValueError(problem)
        if time is not None:
            self.time = float(time)
        if self.n == 0:        # every sphere has left (a sink): nothing is bound
            self._vmax2 = self._vmax2_near = 0.0
            return
        self._engine.state.load(x, v, self.scene.radius, self.scene.mass, omega)
        self._measure_vmax()

    @property
    def original_scene(self) -> Scene:
        """The scene this Simulation was made from, every sphere in it: ``sphere_ids``
        index it, where sinks took spheres out of ``scene``."""
        return self._original_scene

    def checkpoint(self) -> dict:
        """Everything needed to continue bit-for-bit: state, time, step bound, counters,
        and ``scene``, the digest of the scene it was made from (checkpoint.scene_digest)."""
        st = self.state()
        return dict(scene=scene_digest(self._original_scene),
                    x=st.x, v=st.v, omega=st.omega, radius=self.scene.radius.copy(),
                    mass=self.scene.mass.copy(), sphere_ids=self.sphere_ids.copy(),
                    time=self.time,
                    vmax2=self._vmax2, vmax2_near=self._vmax2_near,
                    stuck_in_sinks=self._stuck_in_sinks,
                    totals=dict(self._totals),
                    last_step=dict(self.last_step), n=self.n, precision=self.precision,
                    step_fraction=self.step_fraction, max_sweeps=self.max_sweeps,
                    warm=self._warm_rows() if self.n else None)

    def restore(self, ckpt: dict) -> None:
        """Continue from :meth:`checkpoint` output of a Simulation of the same scene,
        precision and settings (ValueError otherwise). A scene with sinks continues
        with the spheres the checkpoint kept."""
        if "scene" in ckpt and ckpt["scene"] != scene_digest(self._original_scene):
            raise ValueError("the checkpoint was made from a different scene than this "
                             "Simulation's")
        if ckpt["n"] != self.n and getattr(self.scene, "sinks", ()) and "radius" in ckpt:
            self._load_checkpoint_spheres(ckpt)
        for key in ("n", "precision", "step_fraction", "max_sweeps"):
            mine = getattr(self, key)
            if ckpt[key] != mine:
                raise ValueError(f"checkpoint {key} = {ckpt[key]!r} does not match this "
                                 f"simulation's {mine!r}")
        self.set_state(ckpt["x"], ckpt["v"], ckpt["time"], ckpt.get("omega"))
        self._vmax2 = float(ckpt["vmax2"])
        warm = ckpt.get("warm") if self.n > 0 else None
        substeps_ready = warm is None or "near" in warm or not self._substeps
        # a checkpoint of a run without substeps: every sphere counts as near
        self._vmax2_near = float(ckpt.get("vmax2_near", ckpt["vmax2"])) \
            if substeps_ready else self._vmax2
        self._stuck_in_sinks = int(ckpt.get("stuck_in_sinks", 0))
        if warm is not None and self._engine.solver is not None:
            self._engine.solver.load_warm(warm)
        self._totals.update(ckpt["totals"])
        self.last_step = dict(ckpt["last_step"])

    def advance(self, duration: float) -> None:
        """Advance simulated time by ``duration`` seconds with adaptive steps."""
        duration = float(duration)
        if not (duration >= 0.0) or not math.isfinite(duration):
            raise ValueError(f"duration must be a finite number >= 0, got {duration}")
        self.advance_to(self.time + duration)

    def advance_to(self, t_end: float) -> None:
        """Advance to the absolute time ``t_end`` [s]; the last step ends exactly there."""
        if self.n:
            self._check()
        t_end = float(t_end)
        if not math.isfinite(t_end) or t_end < self.time:
            raise ValueError(f"cannot advance to t={t_end} from t={self.time}")
        if self.n == 0:
            self.time = t_end
            return
        t0 = _time.perf_counter()
        while self.time < t_end:
            self._step_toward(t_end)
        self.sim_seconds += _time.perf_counter() - t0

    def step_toward(self, t_end: float) -> float:
        """One of :meth:`advance_to`'s steps toward the absolute time ``t_end`` [s]: the
        adaptive step, or what is left to ``t_end`` if that is shorter; advances
        ``time`` and returns the step's length [s] (0 at ``t_end``). For observing a run
        step by step: a loop of these takes the same steps, with the same bits, as
        ``advance_to(t_end)``."""
        t_end = float(t_end)
        if not math.isfinite(t_end) or t_end < self.time:
            raise ValueError(f"cannot step toward t={t_end} from t={self.time}")
        if self.time >= t_end:
            return 0.0
        if self.n == 0:
            h, self.time = t_end - self.time, t_end
            return h
        self._check()
        t0 = _time.perf_counter()
        h = self._step_toward(t_end)
        self.sim_seconds += _time.perf_counter() - t0
        return h

    def _step_toward(self, t_end: float) -> float:
        """The step of advance_to's loop (time < t_end, spheres left); returns h [s]."""
        h = self.max_step()
        remaining = t_end - self.time
        last = h >= remaining
        if last:
            h = remaining
        self.step(h)
        if self._substeps and self.last_step["h"] < h:     # ended at an impact
            last, h = False, self.last_step["h"]
        self.time = t_end if last or self.n == 0 else self.time + h
        return h

    def max_step(self) -> float:
        """Largest h such that no sphere moves more than D = step_fraction * r_min [s]
        (move_bound). With substeps (Rules.substeps, a contact solver) the largest h
        such that no sphere the contact rows held in the last step (a row impulse > 0)
        moves more than D, at most (contact_margin - 1) D / impact speed (never less
        than without substeps): the other spheres take substeps
        (stepping.Stepper.step; docs/algorithm.md, "Substeps")."""
        h = self.move_bound(self._vmax2)
        if self._substeps:
            reach = self.tuning.physics.contact_margin - 1.0
            cap = reach * self.step_fraction * self._r_min / self.rest_speed
            h = max(h, min(cap, self.move_bound(self._vmax2_near)))
        return h

    def move_bound(self, vmax2: float) -> float:
        """Largest h such that no sphere moves more than D = step_fraction * r_min [s]
        at largest squared speed vmax2 [m^2/s^2]: v_max h + g h^2/2 <= D, i.e. h = 2 D /
        (v_max + sqrt(v_max^2 + 2 g D))."""
        dist = self.step_fraction * self._r_min
        vmax = math.sqrt(max(vmax2, 0.0))
        denom = vmax + math.sqrt(vmax * vmax + 2.0 * self._g * dist)
        return math.inf if denom == 0.0 else 2.0 * dist / denom

    def step(self, h: float) -> float:
        """One step of length h [s] (does not advance ``time``; use advance); returns
        the length it took [s]: h, or less where its substeps (Rules.substeps) ended it
        at an impact."""
        if self.n == 0:
            return h
        self._check()
        c, sweeps, remaining, overlap = self._stepper.step(
            h, self.max_sweeps, self.move_bound if self._substeps else None)
        self._book_step(c, c.length, sweeps, remaining, overlap)
        if c.in_sinks > 0:
            self._discharge()
        return c.length

    def _load_checkpoint_spheres(self, ckpt: dict) -> None:
        """Continue with the spheres of a checkpoint taken after a discharge (their
        materials those of the original scene's spheres of the same ids)."""
        ids = np.asarray(ckpt.get("sphere_ids", np.arange(len(ckpt["mass"]))))
        material = self._original_scene.material[ids]
        self.scene = dataclasses.replace(
            self.scene, x=np.asarray(ckpt["x"], dtype=np.float64),
            v=np.asarray(ckpt["v"], dtype=np.float64),
            radius=np.asarray(ckpt["radius"], dtype=np.float64),
            mass=np.asarray(ckpt["mass"], dtype=np.float64),
            omega=np.asarray(ckpt["omega"], dtype=np.float64), material=material)
        self._parked = (self.scene.x, self.scene.v, self.scene.omega, None)
        if "sphere_ids" in ckpt:
            self.sphere_ids = np.asarray(ckpt["sphere_ids"])
        self._engine.release(self)
        self._bind()

    def _discharge(self):
        """Take the spheres in sinks out and continue with the others on the same engine:
        with Performance.discharge_in_place in the engine's fields (Engine.take_out;
        on the CPU with a recycling sink on the host, discharge.py, their warm start
        moved down in the fields, Engine.keep_spheres), or with every table read to
        the host, renumbered there and loaded again with the scene (the same bits)."""
        dtype = np.float64 if self.precision == "f64" else np.float32
        in_place = self.tuning.performance.discharge_in_place
        if in_place and not any(s.recycle for s in self.scene.sinks):
            self._take_out_in_place()
            return
        # a recycling sink: the warm start moves down in the fields on the CPU
        # (keep_spheres' move is one serial loop: a GPU reloads through the host instead)
        warm_in_fields = in_place and self.runtime.is_cpu
        scene, rows, warm, gone = discharge.discharge(
            self.scene, self._engine.state.rows(),
            None if warm_in_fields else self._warm_rows(), dtype, self._sink_rng)
        self._book_discharge(gone)
        self.scene = scene
        if not warm_in_fields or scene.n == 0:
            self._parked = rows + (warm,)
            self._engine.release(self)
        if scene.n == 0:           # every sphere has left: time still runs, nothing moves
            self._vmax2 = self._vmax2_near = 0.0
            return
        if warm_in_fields:
            self._engine.keep_spheres(self, *rows, gone.kept, self._reach())
        else:
            self._bind()
        near = self._vmax2_near
        self._measure_vmax()
        # fewer spheres (and recycled ones at rest): the bound can only go down
        self._vmax2_near = min(near, self._vmax2)
        # recycled spheres that found no free spot stay in their sink: substeps end a
        # step only where more spheres than these are in sinks
        self._stuck_in_sinks = int(discharge.in_sinks(rows[0], scene.sinks, dtype).sum())

    def _take_out_in_place(self):
        """_discharge for sinks that do not recycle, in the engine's fields (one launch,
        Engine.take_out); only the taken spheres' rows come to the host."""
        taken, rows = self._engine.take_out(self)
        keep = np.ones(self.n, dtype=bool)
        keep[taken] = False
        scene, gone = discharge.without(self.scene, keep, rows)
        self._book_discharge(gone)
        self.scene = scene
        self._stuck_in_sinks = 0            # every sphere in a sink has left
        if scene.n == 0:                    # every sphere has left: time still runs
            empty = np.zeros((0, 3))
            self._parked = (empty, empty, empty, None)
            self._engine.release(self)
            self._vmax2 = self._vmax2_near = 0.0
            return
        self._engine.after_take_out(self, self._reach())
        self._vmax2 = float(self._engine.params.vmax2[None])    # (the kernel measured it)
        # fewer spheres: the bound can only go down
        self._vmax2_near = min(self._vmax2_near, self._vmax2)

    def _book_discharge(self, gone) -> None:
        """Count a discharge's spheres, mass and energy in the totals; keep the ids of
        the spheres that stay."""
        t = self._totals
        t["discharged"] += gone.count
        t["discharged_mass"] += gone.mass
        t["energy_discharged"] += gone.energy
        if gone.kept is not None:
            self.sphere_ids = self.sphere_ids[gone.kept]

    #: stats totals that add up the step counter of the same name (params.COUNTS/VALUES)
    _SUMMED = ("pair_collisions", "wall_collisions", "wall_rests", "multi_collision_spheres",
               "collapse_collisions", "energy_pair_restitution", "energy_wall_restitution",
               "energy_collapse", "energy_contacts", "virial", "contacts",
               "contact_iterations", "position_iterations", "warm_starts_scaled")

    def _book_step(self, c, h, sweeps, remaining, overlap):
        """Add a step's counters ``c`` (params.read_back) to the totals; keep its step
        bound."""
        t = self._totals
        t["steps"] += 1
        t["substeps"] += c.substeps
        t["sweeps"] += sweeps
        for name in self._SUMMED:
            t[name] += getattr(c, name)
        if remaining > 0:
            t["unresolved"] += remaining
            t["sweep_limit_hits"] += 1
        t["max_overlap"] = max(t["max_overlap"], overlap)
        self._vmax2 = float(c.vmax2)
        self._vmax2_near = float(c.vmax2_near)
        if self._engine.solver is not None:
            t["contact_steps"] += 1
            t["contact_residual"] = max(t["contact_residual"], float(c.contact_residual))
        self.last_step = dict(h=h, unresolved=remaining, max_overlap=overlap, sweeps=sweeps,
                              **{k: getattr(c, k) for k in self._LAST})

    #: step counters kept in ``last_step``
    _LAST = ("pair_collisions", "wall_collisions", "multi_collision_spheres", "contacts",
             "contact_iterations", "position_iterations", "contact_residual")

    # ---- the engine this Simulation runs on ----
    def _engine_key(self, schedule: engines.Schedule) -> engines.EngineKey:
        """What this Simulation's kernels compile in (engine.EngineKey)."""
        return engines.EngineKey(
            generation=self.runtime.generation,
            real=ti.f64 if self.precision == "f64" else ti.f32, features=self.features,
            serial_light=schedule.serial_light, serial_heavy=schedule.serial_heavy,
            serial_few=schedule.serial_few, near_lists=schedule.near_lists,
            tuning=self.tuning.compiled())

    def _bind(self):
        """Load this Simulation into its engine's fields unless it is the one they hold
        (or it has no sphere left: nothing to load)."""
        if not self._engine.bound_to(self) and self.n > 0:
            x, v, omega, warm = self._parked
            self._engine.bind(self, x, v, self.geometry, self.rest_speed, warm, omega,
                              self._reach())
            self._parked = None

    def _reach(self) -> float:
        """The contact rows' reach [m]: contact_margin x D of the smallest sphere left."""
        return self.tuning.physics.contact_margin * self.step_fraction * \
            float(self.scene.radius.min())

    def _park(self):
        """Keep positions, velocities and the contact solver's warm start on the host:
        another Simulation takes the engine."""
        self._parked = self._engine.state.rows() + (self._warm_rows(),)   # x, v, omega, warm

    def _warm_rows(self):
        """The contact solver's warm-start table (ContactSolver.warm_rows) or None."""
        return self._engine.solver.warm_rows(self.n) if self._engine.solver is not None else None

    def _measure_vmax(self):
        """The step bound's largest speed from the current velocities."""
        self._engine.motion.measure_vmax()
        self._vmax2 = float(self._engine.params.vmax2[None])
        self._vmax2_near = self._vmax2      # (no rows solved yet: every sphere counts)

    # ---- introspection used by tests and tools ----
    def debug_view(self):
        """The engine's parts, bound to this Simulation, for tests and tools: engine,
        state, params, motion, grid, contacts, projection (engine.py, docs/design.md).
        Internals: names and fields may change between versions."""
        self._check()
        e = self._engine
        return types.SimpleNamespace(engine=e, state=e.state, params=e.params, motion=e.motion,
                                     grid=e.grid, contacts=e.contacts, projection=e.projection,
                                     solver=e.solver)

    def grid_overlaps(self) -> np.ndarray:
        """Rebuild the grid at the current state and list overlapping approaching pairs
        (K, 2) sorted — for comparing the grid with brute force."""
        self._check()
        self._engine.grid.build()
        return self._engine.contacts.list_overlaps()

    def _check(self):
        """Raise if Taichi was re-initialised since; bind this Simulation's engine."""
        runtime.check(self.runtime)
        self._bind()
