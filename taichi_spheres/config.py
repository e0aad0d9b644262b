"""Tuning: every constant of the engine in one options object, in two named groups.

``Tuning(physics=Rules(...), performance=Performance(...))``, passed as
``Simulation(scene, tuning=...)`` (default: ``Tuning()``). The *physics rules* change
results (impact threshold, contact solver tolerances, collapse rule, wall bounces);
the *performance*
knobs change only speed and memory (loop variants, list sizes, grid shape): the same
bits whatever their values (tests run both sides of each). Kernels compile most values
in (``ti.static``), so Simulations with other values run on another engine
(engine.py), except the values no kernel compiles in (``Tuning.compiled``: HOST_ONLY,
KERNEL_VARIANTS and SOLVER_VALUES, below). ``Tuning().with_(dense_touched=64)``
returns a copy with fields of either group replaced by name.
"""
from __future__ import annotations

import dataclasses

__all__ = ["Rules", "Performance", "Tuning", "DEFAULT"]


#: values of Rules.shock_propagation
SHOCK_MODES = ("auto", "on", "off")


def _require_at_least(group, names, low) -> None:
    """ValueError naming the first field of ``names`` in ``group`` below ``low``."""
    for name in names:
        if getattr(group, name) < low:
            raise ValueError(f"tuning {name} must be >= {low}, got {getattr(group, name)!r}")


@dataclasses.dataclass(frozen=True)
class Rules:
    """Physics rules: impacts, persistent contacts, inelastic collapse (docs/design.md).

    impact_factor: with gravity, an approach faster than impact_factor x sqrt(2 |g| D)
        (D = step_fraction x smallest radius: sqrt(2 g D) = g h is the speed gravity
        adds in the longest step a resting scene takes, h = sqrt(2 D / g)) is an
        impact, resolved by the exact rewind with restitution; a slower one at a
        touching or nearly touching pair (or wall) is a persistent contact, a row of
        the contact solver (contacts/solver.py). A scene's ``rest_speed`` raises that
        threshold.
    contact_margin: pairs and walls closer than contact_margin x D get contact rows
        (speculative contacts: two spheres close by at most 2 D in a step), or closer
        than the grid's slack if that is smaller.
    contact_tolerance: the contact solver iterates until no row changes a velocity by
        more than this fraction of the impact speed.
    contact_iterations: velocity sweeps of the contact solver per step at most.
    warm_start: start each step's impulses from the same rows' last impulses (False:
        from zero; for measuring what warm starting saves).
    bounded_warm_start: "on" scales a step's warm start down where it would leave the
        velocity solve more kinetic energy than it started with (after an impact the
        last step's impulses can be far too large, and a solve stopped at its cap then
        added energy; contacts/warm_energy.py); "off" keeps the plain warm start;
        "auto" (default): on without friction, off with it. The bound is one factor
        for all contacts, and with friction any contact whose sliding turns makes its
        warm friction impulse add energy: in a discharging silo that cut the friction
        the warm start carries from step to step (docs/algorithm.md).
    position_iterations: pseudo-velocity (split impulse) sweeps per step at most; they
        stop once a sweep meets no row overlapping by more than half of
        overlap_tolerance of the smallest diameter (per step, at the pseudo-velocities
        so far).
    position_extension: more pseudo-velocity sweeps a step may run, at most, where the
        pseudo-velocities of its capped pass would still leave a row overlapping by more
        than half of overlap_tolerance (each row's gap moved by h times its
        pseudo-velocities, linearised as the pass's targets): they run until the pass
        meets no such row or that many more ran (with plain sweeps at the end, as the
        capped pass). 50 by default (0: none): deep beds whose longest steps leave
        overlaps above the tolerance at the cap then stay within it (docs/bench.md,
        "Position sweeps extended where a step leaves overlap").
    bounded_position_pass: with gravity, scale a step's pseudo-velocities down where
        they would lift spheres by more potential energy than the step's solve took
        out (kinetic energy removed, potential energy released by its moves), so that
        the solve never raises the total energy of a step; the overlap left is pushed
        out as later steps' solves take energy out, so an overlap a resting scene
        starts with stays (contacts/position_energy.py). Off by default (measured in
        docs/bench.md, "Settings").
    relaxation: over-relaxation factor omega of the Gauss-Seidel updates, in (0, 2) (1:
        plain projected Gauss-Seidel; 1 < omega < 2 converges faster on stacks; friction
        rows stay plain). Over-relaxed sweeps overshoot: a solve counts as converged
        only once a plain sweep leaves every row within tolerance (so a converged step
        takes at least two sweeps), and a solve stopped at its cap ends with plain
        sweeps. With omega != 1 a single resting contact is solved to the tolerance,
        not to round-off (closed-form friction results within 1e-6, not 1e-14).
        The defaults (omega 1.8, 100 velocity and 60 position sweeps, substeps) hold
        the pour's bed 25x tighter than plain sweeps at 100 / 100 without substeps,
        with less kinetic energy left, in 0.8 of the wall time; fewer velocity sweeps
        let a settling block's energy rise above its start (docs/bench.md,
        "Settings").
    plain_sweeps: with relaxation != 1, the last sweeps of the cap (velocity and
        position) that run plain (omega = 1), so that a solve stopped at its cap does
        not keep the overshoot (a column of light spheres under heavy ones flies apart
        without them).
    overlap_tolerance: relative overlap the split impulse aims below (its sweeps stop
        at half of it of the smallest diameter), and above which the projection pushes
        apart the overlaps left when a step without a contact solver hit the sweep
        limit.
    shock_propagation: "auto", "on" or "off": after the velocity sweeps, one pass over
        the rows from the floor up that pushes only the upper sphere of each row where
        the sweeps left it sinking into the lower one (contacts/shock.py; scenes with
        gravity, not along a periodic axis). "auto": compiled in where the spheres'
        masses differ (mass ratios are what the sweeps converge worst on), left out for
        equal masses.
    collapse_hits: from a sphere's collapse_hits-th collision in one step on, its
        impacts are perfectly inelastic in the normal direction (inelastic pairs only;
        a time-stepped stand-in for the TC model of Luding & McNamara 1998, needed
        for inelastic collapse in a cooling gas, where no contact solver runs).
    max_wall_bounces: bounces of one sphere on one wall within a step before it is put
        to rest on the wall.
    projection_iterations: Jacobi iterations of the projection per step at most.
    projection_relaxation: fraction of every pair's overlap one iteration removes.
    substeps: with a contact solver, run drift and impacts in substeps, each bounded
        as a step is (no sphere moves more than D = step_fraction x r_min), and the
        contact solver once per step, whose length only the spheres its rows held
        bound (up to (contact_margin - 1) D / impact speed); a step ends early at a
        collision of a sphere near a held one, a wall or an object. A few fast
        spheres in flight then no longer set how often a bed is solved
        (stepping.py, docs/algorithm.md "Substeps"). On by default.
    step_scaled_sweeps: scale each step's velocity and position sweep caps (and their
        plain sweeps) by the step's length over a quiet bed's, (contact_margin - 1) D
        / impact speed, so that many short steps (a discharging silo, whose flowing
        grains in contact bound the step) run about the sweeps per simulated second of
        quiet ones, each warm-started from the last (contacts/pgs.py set_cap).
        min_scaled_sweeps: the fewest sweeps a scaled cap keeps. On by default: over
        eight fills of the pour it halves the fall's wall time and leaves the bed's
        kinetic energy at 2 s no higher (docs/bench.md, "Sweep caps scaled with the step").
    """

    impact_factor: float = 2.0
    contact_margin: float = 2.5
    contact_tolerance: float = 1e-6
    contact_iterations: int = 100
    warm_start: bool = True
    bounded_warm_start: str = "auto"
    relaxation: float = 1.8
    plain_sweeps: int = 10
    position_iterations: int = 60
    position_extension: int = 50
    bounded_position_pass: bool = False
    overlap_tolerance: float = 1e-4
    shock_propagation: str = "auto"
    collapse_hits: int = 4
    max_wall_bounces: int = 8
    projection_iterations: int = 8
    projection_relaxation: float = 0.5
    substeps: bool = True
    step_scaled_sweeps: bool = True
    min_scaled_sweeps: int = 8

    def __post_init__(self):
        """ValueError naming the field: shock_propagation or bounded_warm_start not one
        of SHOCK_MODES, relaxation outside (0, 2) (where projected Gauss-Seidel
        converges), fewer than one velocity or position sweep (or scaled sweep),
        negative plain_sweeps, a flag that is not a bool."""
        if self.bounded_warm_start not in SHOCK_MODES:
            raise ValueError(f"tuning bounded_warm_start must be one of {', '.join(SHOCK_MODES)}, "
                             f"got {self.bounded_warm_start!r}")
        if self.shock_propagation not in SHOCK_MODES:
            raise ValueError(f"tuning shock_propagation must be one of {', '.join(SHOCK_MODES)}, "
                             f"got {self.shock_propagation!r}")
        if not 0 < self.relaxation < 2:
            raise ValueError(f"tuning relaxation must be in (0, 2), got {self.relaxation!r}")
        _require_at_least(self, ("contact_iterations", "position_iterations"), 1)
        _require_at_least(self, ("plain_sweeps", "position_extension"), 0)
        _require_at_least(self, ("min_scaled_sweeps",), 1)
        for name in ("substeps", "bounded_position_pass", "step_scaled_sweeps"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"tuning {name} must be True or False, "
                                 f"got {getattr(self, name)!r}")


@dataclasses.dataclass(frozen=True)
class Performance:
    """Speed and memory knobs; results do not depend on them (same bits).

    serial_light_below: below this many spheres the CPU runs light loops (drift, grid
        build) serially: a parallel launch costs ~150 us there, more than the loop.
    serial_heavy_below: below this many spheres the CPU runs every loop serially
        (detection and sweeps too), and the fused step is available.
    near_lists_from: from this many spheres on, detection keeps near lists.
    few_pairs: below this many pending pairs a CPU sweep runs its loops serially.
    serial_resolve_pairs: below this many, a CPU sweep still resolves serially (one
        launch for all colours) but detects in parallel; above, one launch per colour.
    max_block_collisions: collisions one owner cell resolves in one sweep at most.
    recorded_pairs: pairs (1 or 2) an owner cell keeps from detection; a cell with
        no more pairs resolves them from the record instead of searching its block.
    dense_touched: a re-detection visits the touched spheres in cell order when more
        than 1 in this many were touched, else in list order.
    near_capacity: forward neighbours a near list keeps per sphere.
    near_safety: part of the move budget of a near list that is used (the rest
        absorbs round-off).
    near_fast_limit: a detection from near lists scans everything instead when more
        than 1 in this many spheres moved past the allowance.
    prune_walks: walks around one sphere skip the neighbour cells it cannot reach
        (False: all 27).
    projection_near_sets: later projection iterations examine only the neighbourhood
        of the spheres involved before (False: every sphere every iteration).
    scan_block: items per block of the grid's prefix scan.
    max_cells_per_sphere: at most about this many grid cells per sphere.
    wide_margin: cells aim at the largest diameter plus this many times the largest
        move per step.
    serial_solver_below: below this many spheres the CPU runs the contact solver's
        sweeps serially in one launch (same bits as one parallel launch per sweep).
    contacts_per_sphere: contact rows the solver has room for, per sphere (a pair
        counts once; a dense pack of equal spheres has about 3 plus walls).
    warm_slots: warm-start impulses kept per sphere (for the rows where it is the
        lower id; a sphere with more keeps none).
    solver_interleave: on the CPU, where the contact solver's sweeps run on one thread
        (the serial one-launch solver, or a one-thread runtime), cells of one colour
        whose rows that thread sweeps interleaved (contacts/pgs.py sweep_cells; a GPU
        sweeps one cell per thread): a row update waits on the previous one of its
        cell, and the processor overlaps the other cells' updates meanwhile.
    frictional_interleave: solver_interleave for scenes with friction, whose row
        updates (normal, tangential and rolling parts) keep more values in registers:
        fewer cells at a time keep them there (tools/solver_interleave.py; the same
        bits for any count).
    parallel_interleave: the same for sweeps running in parallel on several CPU
        threads (1: one cell per loop iteration; on 2 cores 8 measured no faster:
        tools/solver_interleave.py).
    sweeps_per_wait: on the CPU, sweeps of a parallel contact solve launched before
        the host waits to learn whether the solve is done (contacts/pgs.py
        batched_sweep; 1: each sweep returns its residual). A CPU runs each launch to
        its end before the host goes on, so there a batch saves no wait (default 1).
        gpu_sweeps_per_wait: the same on a GPU, which queues the launches while the
        host goes on, so that the host waits once per batch instead of after every
        sweep; a solve ends with at most gpu_sweeps_per_wait - 1 empty launches.
    discharge_in_place: when a sink takes spheres out, take them out in the engine's
        fields and move the remaining spheres down there, state and contact state
        (warm-start table, loaded and near flags) alike (takeout.py; with a
        recycling sink only the contact state, discharge.py and Engine.keep_spheres),
        instead of reading every table to the host and loading the scene again
        (False; a GPU does that with a recycling sink: keep_spheres' move is a serial
        loop). The same bits.
    staged_solve: launch the contact solver's serial solve as one kernel per stage
        (contacts/solver.py SOLVE_STAGES: gather, list cells, prepare, warm start,
        velocity sweeps, position targets, position sweeps, finish) instead of one, so
        that a kernel profile shows each stage's time (tools/kernel_profile.py
        --stages). The same bits, a few launches more per step.
    """

    serial_light_below: int = 200_000
    serial_heavy_below: int = 3_000
    near_lists_from: int = 3_000
    few_pairs: int = 1000
    serial_resolve_pairs: int = 50_000
    max_block_collisions: int = 64
    recorded_pairs: int = 2
    dense_touched: int = 4096
    near_capacity: int = 16
    near_safety: float = 0.99
    near_fast_limit: int = 8
    prune_walks: bool = True
    projection_near_sets: bool = True
    scan_block: int = 1024
    max_cells_per_sphere: float = 8.0
    wide_margin: float = 4.0
    serial_solver_below: int = 30_000
    contacts_per_sphere: int = 8
    warm_slots: int = 16
    solver_interleave: int = 8
    frictional_interleave: int = 4
    parallel_interleave: int = 1
    sweeps_per_wait: int = 1
    gpu_sweeps_per_wait: int = 8
    discharge_in_place: bool = True
    staged_solve: bool = False

    def __post_init__(self):
        """ValueError naming the field: solver_interleave, frictional_interleave,
        parallel_interleave or a sweeps_per_wait below 1."""
        _require_at_least(self, ("solver_interleave", "frictional_interleave",
                                 "parallel_interleave",
                                 "sweeps_per_wait", "gpu_sweeps_per_wait"), 1)


@dataclasses.dataclass(frozen=True)
class Tuning:
    """The engine's options: ``physics`` (Rules) and ``performance`` (Performance)."""

    physics: Rules = Rules()
    performance: Performance = Performance()

    def with_(self, **changes) -> "Tuning":
        """A copy with the named fields of either group replaced (ValueError for an
        unknown name or a value of the wrong type)."""
        groups = {"physics": {}, "performance": {}}
        for name, value in changes.items():
            group = next((g for g in groups if name in _field_names(getattr(self, g))), None)
            if group is None:
                raise ValueError(f"unknown tuning field {name!r}; fields: "
                                 f"{', '.join(sorted(_field_names(self.physics) | _field_names(self.performance)))}")
            default = getattr(getattr(self, group), name)
            if not _fits(value, default):
                raise ValueError(f"tuning {name} must be {type(default).__name__}, got {value!r}")
            groups[group][name] = type(default)(value)
        return Tuning(physics=dataclasses.replace(self.physics, **groups["physics"]),
                      performance=dataclasses.replace(self.performance, **groups["performance"]))

    def compiled(self) -> "Tuning":
        """This Tuning with the options that choose no engine (HOST_ONLY,
        KERNEL_VARIANTS, SOLVER_VALUES) at their defaults: what an engine's kernels
        compile in (engine.EngineKey), so that Simulations differing only in those
        share compiled engines."""
        return Tuning(
            physics=dataclasses.replace(
                self.physics, **{name: getattr(Rules(), name) for name in SOLVER_VALUES}),
            performance=dataclasses.replace(
                self.performance, **{name: getattr(Performance(), name)
                                     for name in HOST_ONLY + KERNEL_VARIANTS}))


#: Performance options that only the host reads: the Simulation (the schedule's sphere
#: counts, which the key holds as engine.Schedule's flags; the discharge), or the engine's
#: parts from the Simulation bound to them (Engine.bind: the impact sweep's path by its
#: pending pairs, the contact solver's one-launch path and sweeps per wait). They do not
#: enter the compiled engines' key (Tuning.compiled), so Simulations that differ only in
#: them share an engine
HOST_ONLY = ("serial_light_below", "serial_heavy_below", "near_lists_from", "few_pairs",
             "serial_resolve_pairs", "serial_solver_below", "sweeps_per_wait",
             "gpu_sweeps_per_wait", "discharge_in_place")
#: Performance options that choose among variants of a few of an engine's kernels, each
#: variant built on first use by the Simulation bound to the engine (the contact
#: solver's sweeping kernels by their interleaving, and its serial solve as one kernel
#: or one per stage: ContactSolver.load_host_options): Simulations that differ only in
#: them share an engine, and each variant compiles only those kernels
KERNEL_VARIANTS = ("solver_interleave", "frictional_interleave", "parallel_interleave",
                   "staged_solve")
#: Rules the contact solver's kernels read as values in fields, loaded when a
#: Simulation binds its engine (contacts/solver.py ContactSolver.load_sweep_rules):
#: Simulations that differ only in these share compiled engines
SOLVER_VALUES = ("relaxation", "contact_iterations", "position_iterations", "plain_sweeps",
                 "min_scaled_sweeps", "position_extension")


def field_types() -> dict:
    """Every Tuning field name (Rules and Performance) and the type of its value (bool,
    int, float or str)."""
    return {f.name: type(getattr(group, f.name))
            for group in (Rules(), Performance()) for f in dataclasses.fields(group)}


def _fits(value, default) -> bool:
    """value can stand for default: a bool for a bool, an int for an int, a number for a
    float, a string for a string."""
    if isinstance(default, str):
        return isinstance(value, str)
    if isinstance(default, bool) or isinstance(value, bool):
        return isinstance(value, bool) and isinstance(default, bool)
    if isinstance(default, int):
        return isinstance(value, int)
    return isinstance(value, (int, float))


def _field_names(group) -> set:
    return {f.name for f in dataclasses.fields(group)}


#: The default options.
DEFAULT = Tuning()
