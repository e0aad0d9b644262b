"""Contact solver for persistent contacts (step stage 5, docs/design.md "Persistent
contacts"): Moreau–Jean nonsmooth contact dynamics solved by projected Gauss–Seidel,
colour by colour, with warm starting and split-impulse position correction.

After the drift and the impacts of a step (exact rewinds, contacts/pair.py), every
pair closer than a speculative margin and every sphere closer than it to a wall
becomes one *contact row* unless it approaches faster than the impact speed (a
future impact). With ``x', v'`` the state after the impacts, ``n`` the contact
normal, ``u_n`` the normal relative velocity (separating > 0), ``gap`` the distance
between the surfaces (< 0: overlap):

- velocity rows: impulses ``lambda >= 0`` with ``u_n(end) >= -max(gap - delta, 0)/h``
  (a touching contact stops approaching; a speculative one may close exactly its
  gap in the next step; gaps below delta, a tenth of Rules.overlap_tolerance of the
  smallest diameter, count as touching so that round-off in the gaps makes no
  targets), accumulated over projected Gauss–Seidel iterations and
  clamped (Catto's sequential impulses), warm-started from the same pair's
  lambda of the previous step (scaled by h / h_prev), and as a whole scaled down
  where it would leave the solve more kinetic energy than it started with
  (contacts/warm_energy.py);
- positions follow the trapezoidal rule of Moreau–Jean with theta = 1/2:
  ``x += h/2 dv`` for the velocity change ``dv`` of the contact impulses. Free
  flight stays exact (``dv = 0``) and a sphere resting under gravity, which the
  drift moved down by ``g h^2/2`` at speed ``g h``, is put back exactly where it was
  with zero velocity. Where that move would raise a sphere's potential energy by
  more than the solve took from its kinetic energy (a speculative row slowing an
  approach from above), it is shortened to the break-even length, so the move adds
  no sphere more energy than its own velocity change took (the sum can still rise:
  the solve passes momentum between spheres). A sphere a support (wall or object)
  held that the move put back above it, at a start gap the drift had closed, is
  lowered onto it (close_support_gaps): otherwise it rested there, above the floor;
- split impulse (Catto; Bullet): overlap left after that is removed by
  pseudo-velocities ``w`` solved the same way (``w_n >= -gap/h``, no warm start),
  which move positions (``x += h w``) and never change velocities. Pair
  pseudo-impulses conserve sum m x, so they do not change potential energy; wall
  rows lift spheres out of the floor, which does.

Parallel scheme: a contact is owned by the grid cell that owns the pair (the cell
of the sphere for a wall row); cells of one colour have disjoint 2x2x2 blocks
(grid.py), so one thread per cell sweeps its rows serially, in a fixed order
(pairs by sphere ids, then wall rows: Box2D solves them last), with no races, and
the result does not depend on the thread count (where the sweeps run on one CPU
thread, it sweeps a few cells of a colour interleaved, the same bits:
pgs.sweep_cells). Velocity iterations stop when no row changed a velocity by more
than ``Rules.contact_tolerance`` x the impact speed, position iterations when no row
they met still overlapped by more than half of ``Rules.overlap_tolerance`` of the
smallest diameter, at most ``Rules.contact_iterations`` / ``position_iterations``
(with ``Rules.step_scaled_sweeps``, caps scaled to the step: pgs.set_cap); a position
pass whose pseudo-velocities would still leave a row overlapping by more than that
(overlap_left; at its cap, or where a sweep's later updates reopened a row it had met
within) runs up to ``Rules.position_extension`` more sweeps (50 by default).

A mixin-free class over the engine's state, grid, parameters and pair geometry.
"""

import taichi as ti

from ..config import DEFAULT, Tuning
from ..grid import Grid
from ..params import StepParams
from ..state import Features, SphereState
from .friction_rows import FrictionRows
from .overlaps import OverlapMeasure
from .packed import PackedRows, packs_rows
from .pgs import POSITION, VELOCITY, WARM, GaussSeidel, next_sweep, plain_sweep
from .rows import ContactRows
from .shock import ShockPropagation, shock_compiled
from .sweeps import MAX_COLOURS
from .position_energy import PositionEnergy
from .warm_energy import WarmStartEnergy
from .warm_table import WarmTable

__all__ = ["ContactSolver", "SOLVE_STAGES"]

#: the stages of a serial solve, in order (ContactSolver.solve_stage)
SOLVE_STAGES = ("gather", "list_cells", "prepare", "warm_start", "velocity_sweeps",
                "position_targets", "position_sweeps", "finish")



@ti.data_oriented
class ContactSolver(ContactRows, GaussSeidel, PackedRows, FrictionRows, ShockPropagation,
                    WarmStartEnergy, PositionEnergy, OverlapMeasure, WarmTable):
    """Contact rows and their projected Gauss–Seidel solve (module docstring).

    Fields (K = contacts_per_sphere x capacity rows, M = cells, N = spheres):
        row_a, row_b: (K,) i32 — the rows' spheres, a < b; b = -1 - wall for a wall
            row (wall = 2 x axis + side, side 0 at lo and 1 at hi; wall = 6 + k for
            geometry object k: surfaces.py)
        normal: (K,) vec3 — unit normal from b to a (into the box for a wall, from
            the surface for geometry)
        gap, target, pos_target: (K,) real — surface gap [m], velocity and
            pseudo-velocity targets [m/s]
        meff: (K,) real — effective mass of the row [kg]
        lam, mu: (K,) real — accumulated impulse and pseudo-impulse [N s]
        lam_t: (K,) vec3, only with friction — accumulated tangential impulse on a [N s]
        lam_r: (K,) vec3, only with rolling friction — accumulated rolling angular
            impulse on a [N m s]
        row_mu: (K,) real, only with friction — the row's friction coefficient;
        row_roll: (K,) real, only with rolling friction — its mu_r r_eff [m]
            (friction_rows.py keep_row_coefficients)
        cell_count, cell_fill: (M,) i32, cell_start: (M+1,) i32 — rows per owner cell
        v_pre, w: (N,) vec3 — velocities before the solve, pseudo-velocities [m/s]
        unrowed: (N,) i32 — 1 for a sphere with an impact to come and no row for it
            this step (rows.py; overlaps.py measures its pairs and walls, then clears
            it)
        w_pre: (N,) vec3, only with friction — spins before the solve [rad/s]
        x_pre: (N,) vec3 — positions before the solve [m]
        drop: (N,) real, only with gravity — how far close_support_gaps lowers a
            sphere [m]
        warm_key, warm_lam: (N, warm_slots) — last step's rows keyed at their sphere
            a: b and lambda; warm_n: (N,) i32 rows kept (more than warm_slots: none);
            warm_t, warm_r: (N, warm_slots) vec3 — lam_t and lam_r of those rows
        active_cells: (M,) i32, colour_active: (MAX_COLOURS + 1,) i32 — the cells that
            own rows, colour by colour (pgs.list_active_cells); colour_fill:
            (MAX_COLOURS,) i32 its counts
        schedule: (K,) i32, schedule_start: (MAX_COLOURS + 1,) i32, only on the CPU —
            the rows in the serial sweeps' order, colour by colour (pgs.schedule_rows)
        pack_a, pack_b, pack_n, pack_meff, pack_goal, pack_acc: (K,), only where
            packs_rows — the rows in that order, for the serial sweeps (packed.py)
        scan_bufs: cell_start and the block sums of its scan (grid.scan_buffers)
        staged: (K,) vec3 i32, only on serial engines — the rows in the order the
            gathering found them: owner cell, a, b (rows.py gather); n_staged their count
    """

    def __init__(self, state: SphereState, grid: Grid, params: StepParams, pairs,
                 features: Features, serial: bool, tuning: Tuning = DEFAULT,
                 cpu: bool = True):
        self.state, self.grid, self.params, self.pairs = state, grid, params, pairs
        self.f = features
        self.real = state.real
        self.serial = serial
        self.cpu = cpu
        self.rules = tuning.physics
        self.perf = tuning.performance
        self.capacity = self.perf.contacts_per_sphere * state.capacity
        self.load_host_options(self.perf)
        self.shock = shock_compiled(features, self.rules)
        # warm_energy.py: the warm start scaled so that it adds no energy
        bound = self.rules.bounded_warm_start
        self.bounded_warm_start = self.rules.warm_start and (
            bound == "on" or (bound == "auto" and not features.friction))
        # position_energy.py: the position pass lifts no more than the step dissipated
        self.bounded_position_pass = self.rules.bounded_position_pass and features.gravity
        # equal masses without friction: the row updates return their residuals halved,
        # two operations fewer per pair row (pgs.push_halved, full_residual)
        self.halved_residual = features.equal_masses and not features.friction
        self.packed = packs_rows(features, state.capacity, cpu)
        self._allocate(state.capacity, grid.cell_capacity)
        self.host_load = None      # the engine's hostload.FieldLoad
        self.relaxation = self.rules.relaxation     # (each bind loads its Simulation's)
        self.extension = self.rules.position_extension
        self._build_kernels()

    def _allocate(self, cap: int, cells: int):
        """The fields of the class docstring."""
        real, k, slots = self.real, self.capacity, self.perf.warm_slots
        self.row_a = ti.field(ti.i32, shape=k)
        self.row_b = ti.field(ti.i32, shape=k)
        self.normal = ti.Vector.field(3, real, shape=k)
        self.gap = ti.field(real, shape=k)
        self.target = ti.field(real, shape=k)
        self.pos_target = ti.field(real, shape=k)
        self.meff = ti.field(real, shape=k)
        self.lam = ti.field(real, shape=k)
        self.mu = ti.field(real, shape=k)
        self.cell_count = ti.field(ti.i32, shape=cells)
        self.cell_fill = ti.field(ti.i32, shape=cells)
        self.cell_start = ti.field(ti.i32, shape=cells + 1)
        self.v_pre = ti.Vector.field(3, real, shape=cap)
        self.x_pre = ti.Vector.field(3, real, shape=cap)
        self.w = ti.Vector.field(3, real, shape=cap)
        self.unrowed = ti.field(ti.i32, shape=cap)
        self.drop = ti.field(real, shape=cap) if self.f.gravity else None
        self.warm_key = ti.field(ti.i32, shape=(cap, slots))
        self.warm_lam = ti.field(real, shape=(cap, slots))
        self.warm_n = ti.field(ti.i32, shape=cap)
        friction, rolling = self.f.friction, self.f.rolling
        self.lam_t = ti.Vector.field(3, real, shape=k) if friction else None
        self.lam_r = ti.Vector.field(3, real, shape=k) if rolling else None
        self.row_mu = ti.field(real, shape=k) if friction else None
        self.row_roll = ti.field(real, shape=k) if rolling else None
        self.w_pre = ti.Vector.field(3, real, shape=cap) if friction else None
        self.warm_t = ti.Vector.field(3, real, shape=(cap, slots)) if friction else None
        self.warm_r = ti.Vector.field(3, real, shape=(cap, slots)) if rolling else None
        self.active_cells = ti.field(ti.i32, shape=cells)
        # the serial solve's order of the rows (pgs.schedule_rows)
        serial_solve = self.serial or self.cpu
        self.schedule = ti.field(ti.i32, shape=k) if serial_solve else None
        self.schedule_start = ti.field(ti.i32, shape=MAX_COLOURS + 1) if serial_solve else None
        self.allocate_packed(k)
        self.colour_active = ti.field(ti.i32, shape=MAX_COLOURS + 1)
        self.colour_fill = ti.field(ti.i32, shape=MAX_COLOURS)
        self.scan_bufs = self.grid.scan_buffers(self.cell_start)
        # serial gathering stages each row as found (rows.py gather): (owner, a, b)
        self.staged = ti.Vector.field(3, ti.i32, shape=k) if self.serial else None
        self.n_staged = ti.field(ti.i32, shape=()) if self.serial else None
        self.n_colours = 0
        self.margin = ti.field(real, shape=())       # speculative margin [m]
        self.h_prev = ti.field(real, shape=())       # length of the last solved step [s]
        # the last sweep's residual: its largest velocity change, or in the position
        # pass the largest overlap it met (per step) [m/s]
        self.residual = ti.field(real, shape=())
        self.n_rows = ti.field(ti.i32, shape=())
        self.tol_v = ti.field(real, shape=())        # velocity tolerance of this step [m/s]
        self.tol_w = ti.field(real, shape=())        # overlap left per step [m/s]
        self.n_colours_f = ti.field(ti.i32, shape=())
        self.tol_len = ti.field(real, shape=())      # position tolerance [m] (bind)
        self._allocate_sweep_control()
        self._allocate_warm_energy(cap, k)
        if self.bounded_position_pass:
            self._allocate_position_energy()
        if self.shock:
            self._allocate_shock()

    def _allocate_sweep_control(self):
        """0-d fields that steer a solve's sweeps: this step's caps (pgs.set_cap) and
        a batched solve's state (pgs.batched_sweep)."""
        # this step's sweep caps and plain sweeps (velocity, position: pgs.set_cap)
        self.cap_v = ti.field(ti.i32, shape=())
        self.cap_w = ti.field(ti.i32, shape=())
        # Rules.position_extension's sweeps (run where overlap_left exceeds tol_w) and
        # overlap_left's result [m/s]
        self.cap_x = ti.field(ti.i32, shape=())
        self.left_x = ti.field(self.real, shape=())
        self.cap_p = ti.field(ti.i32, shape=())      # the running position pass's cap
        self.plain_v = ti.field(ti.i32, shape=())
        self.plain_w = ti.field(ti.i32, shape=())
        self.quiet_len = ti.field(self.real, shape=())    # (contact_margin - 1) D [m] (bind)
        # the bound Simulation's sweep rules (config.SOLVER_VALUES: load_sweep_rules):
        # relaxation omega, velocity and position sweep caps, plain sweeps, fewest
        # scaled sweeps
        self.omega_relax = ti.field(self.real, shape=())
        self.relax_on = ti.field(ti.i32, shape=())     # 1 where relaxation != 1
        self.full_v = ti.field(ti.i32, shape=())
        self.full_w = ti.field(ti.i32, shape=())
        self.plain_sweeps = ti.field(ti.i32, shape=())
        self.min_scaled = ti.field(ti.i32, shape=())
        # a batched solve (pgs.batched_sweep): its sweeps so far,
        # over-relaxing still, done; this sweep's omega and plainness
        self.batch_it = ti.field(ti.i32, shape=())
        self.batch_relaxed = ti.field(ti.i32, shape=())
        self.batch_done = ti.field(ti.i32, shape=())
        self.batch_plain = ti.field(ti.i32, shape=())
        self.batch_omega = ti.field(self.real, shape=())

    def bind(self, scene, geom, reach, rules, perf):
        """Load a scene's grid geometry ``geom`` (colours; the speculative margin: the
        grid's slack, or ``reach`` [m] if smaller; None: the slack), the Simulation's
        sweep ``rules`` (config.Rules: the engine's own hold the defaults of
        config.SOLVER_VALUES) and its host-only options ``perf`` (config.Performance:
        load_host_options), and forget the warm start."""
        self.bind_scalars(scene, geom, reach)
        self.load_sweep_rules(rules)
        self.load_host_options(perf)
        self._forget_warm_start()

    @staticmethod
    def loaded_fields() -> tuple:
        """The fields bind loads (hostload.FieldLoad): the sweep rules and the scalars
        of the scene."""
        return ("omega_relax", "relax_on", "full_v", "full_w", "cap_x", "plain_sweeps",
                "min_scaled", "n_colours_f", "tol_len", "margin", "quiet_len")

    def load_host_options(self, perf) -> None:
        """The options of ``perf`` (config.Performance) that solve() reads
        (config.HOST_ONLY): the spheres below which a parallel engine on the CPU solves
        in one launch, and the sweeps a parallel solve launches before it waits
        (pgs.batched_sweep; sweeps_per_wait on the CPU, gpu_sweeps_per_wait on a GPU);
        and those that choose the variant of the sweeping kernels it launches
        (config.KERNEL_VARIANTS, each variant built on first use: _serial_solve,
        _sweep): whether the serial solve launches in stages (staged_solve), and the
        cells one thread sweeps interleaved (pgs.sweep_cells). Serial
        sweeps, and parallel ones on a one-thread runtime, take
        Performance.solver_interleave (frictional_interleave with friction), parallel
        ones on several threads parallel_interleave; a GPU hides latency with more
        threads instead (one cell each)."""
        self.serial_solver_below = perf.serial_solver_below
        self.batch = perf.sweeps_per_wait if self.cpu else perf.gpu_sweeps_per_wait
        self.solve_in_stages = perf.staged_solve
        cfg = ti.lang.impl.current_cfg()
        one_thread = perf.frictional_interleave if self.f.friction else perf.solver_interleave
        self.interleave = one_thread if self.cpu else 1
        self.interleave_parallel = (self.interleave if cfg.cpu_max_num_threads == 1 else
                                    perf.parallel_interleave) if self.cpu else 1
        # loop iterations per task of a parallel sweep on the CPU: as many cells as
        # Taichi's default block (32), as block / interleave iterations (a power of
        # two), so that a colour still splits into as many tasks; a GPU keeps its default
        per_task = max(1, cfg.default_cpu_block_dim // self.interleave_parallel)
        self.sweep_block = 1 << (per_task.bit_length() - 1) if self.cpu else None

    def load_sweep_rules(self, rules) -> None:
        """The sweep rules (config.SOLVER_VALUES) of ``rules`` (config.Rules), which the
        kernels read from fields: relaxation, sweep caps, plain sweeps, fewest scaled
        sweeps (pgs.set_cap, pgs.sweep_relaxation)."""
        self.relaxation = rules.relaxation
        self.extension = rules.position_extension
        self.host_load.write(
            self, omega_relax=rules.relaxation,
            # (decided on the double, as the host's loop decides it, not on a rounded f32)
            relax_on=int(rules.relaxation != 1),
            full_v=rules.contact_iterations, full_w=rules.position_iterations,
            cap_x=rules.position_extension, plain_sweeps=rules.plain_sweeps,
            min_scaled=rules.min_scaled_sweeps)

    def bind_scalars(self, scene, geom, reach=None):
        """bind's values that follow from the scene and ``geom``: colours, tolerances,
        margins and the sphere count (the warm start stays)."""
        self.n_colours = len(geom.colours)
        # reach = contact_margin D (Simulation._bind): a held bed's step moves at most
        # (contact_margin - 1) D; without reach it is unknown (0: pgs.set_cap's full caps)
        margin = self.rules.contact_margin
        self.host_load.write(
            self, n_colours_f=self.n_colours,
            # a tenth of the overlap tolerance of the smallest contact distance [m]
            tol_len=0.1 * self.rules.overlap_tolerance * 2.0 * float(scene.radius.min()),
            margin=geom.slack if reach is None else min(geom.slack, reach),
            quiet_len=0.0 if reach is None else max(margin - 1.0, 0.0) * reach / margin)
        self.n = scene.n

    @ti.func
    def impact_speed(self):
        """Approach speed from which a contact is an impact [m/s] (PairRule.impact_speed)."""
        return self.pairs.impact_speed()

    @ti.func
    def kinetic_spent(self, i):
        """The kinetic energy per unit mass the solve took from sphere i so far, spin
        included [J/kg]: (|v_pre|^2 - |v|^2) / 2 (+ (|w_pre|^2 - |omega|^2) / (2 m I^-1))."""
        spent = ti.cast(0.5, self.real) * (self.v_pre[i].norm_sqr() - self.state.v[i].norm_sqr())
        if ti.static(self.f.friction):     # the spin's kinetic energy too (per unit mass)
            spent += ti.cast(0.5, self.real) / self.state.mass_of(i) * \
                (self.w_pre[i].norm_sqr() - self.state.omega[i].norm_sqr()) / \
                self.state.inv_inertia_of(i)
        return spent

    @ti.func
    def trapezoidal_move(self, i, h):
        """x_i += h/2 (v_i - v_pre_i) (Moreau-Jean, theta = 1/2), shortened where it
        would raise the sphere's potential energy by more than the solve took from
        its kinetic energy, spin included (module docstring)."""
        move = ti.cast(0.5, self.real) * h * (self.state.v[i] - self.v_pre[i])
        if ti.static(self.f.gravity):
            lift = -self.params.gravity[None].dot(move)
            spent = self.kinetic_spent(i)
            if lift > 0 and lift > spent:
                move *= ti.max(spent, 0) / lift
        self.state.x[i] += move

    @ti.func
    def position_targets(self):
        """The trapezoidal move, then pseudo-velocity targets from the gaps it leaves
        (kernel top level)."""
        h = self.params.h[None]
        ti.loop_config(serialize=ti.static(self.serial))
        for i in range(self.state.n_spheres[None]):
            self.trapezoidal_move(i, h)
        if ti.static(self.f.gravity):
            self.close_support_gaps()
        ti.loop_config(serialize=ti.static(self.serial))
        for s in range(ti.min(self.n_rows[None], ti.static(self.capacity))):
            n, gap, meff = self.row_geometry(s)
            self.normal[s] = n
            self.gap[s] = gap
            self.pos_target[s] = -gap / h
            self.mu[s] = 0

    @ti.func
    def close_support_gaps(self):
        """After the trapezoidal move: a sphere a supporting wall or object row held
        (lambda > 0, normal at least 60 degrees from horizontal, upwards) that the
        move lifted to a gap above delta is lowered back, vertically, by the smaller
        of what closes that gap to delta and what the move lifted it (the largest over
        its support rows: order-free). The rows see the drifted positions, where a
        resting sphere overlaps its support by g h^2/2, so the move put such a sphere
        back at any start gap below that: it rested above the floor (docs/algorithm.md,
        "Closing support gaps"). Lowering only lowers potential energy and changes no
        velocity."""
        ti.loop_config(serialize=ti.static(self.serial))
        for i in range(self.state.n_spheres[None]):
            self.drop[i] = 0
        ti.loop_config(serialize=ti.static(self.serial))
        for s in range(ti.min(self.n_rows[None], ti.static(self.capacity))):
            if self.row_b[s] < 0 and self.lam[s] > 0:
                up = self.upwards()
                n, gap, meff = self.row_geometry(s)
                slope = n.dot(up)
                if slope >= 0.5 and gap > self.tol_len[None]:
                    a = self.row_a[s]
                    lifted = (self.state.x[a] - self.x_pre[a]).dot(up)
                    d = ti.min((gap - self.tol_len[None]) / slope, lifted)
                    if d > 0:
                        ti.atomic_max(self.drop[a], d)
        ti.loop_config(serialize=ti.static(self.serial))
        for i in range(self.state.n_spheres[None]):
            if self.drop[i] > 0:
                self.state.x[i] -= self.drop[i] * self.upwards()

    @ti.func
    def upwards(self):
        """The unit vector against gravity, computed in each loop that uses it: a vector
        computed at a kernel's top level and read in a later loop would be kept in
        Taichi's global temporaries, where Taichi 1.7 does not align vectors, and CUDA
        refuses an unaligned f64 load (docs/backends.md, "Values shared between a
        kernel's loops")."""
        return -self.params.gravity[None].normalized()

    @ti.func
    def finish(self):
        """x += h w (w first scaled by lift_scale with Rules.bounded_position_pass); book
        the energy the solve removed (kinetic, and the potential energy of its moves),
        the largest speed and the largest overlap (on the rows, then over every pair,
        wall and object: overlaps.py); keep the impulses for the next step's warm start;
        with Rules.substeps, mark_near (kernel top level)."""
        if ti.static(self.bounded_position_pass):
            self.bound_position_pass()
        h = self.params.h[None]
        self.params.vmax2[None] = 0      # measured again: the solve changed velocities
        if ti.static(self.rules.substeps):
            self.params.vmax2_near[None] = 0
        ti.loop_config(serialize=ti.static(self.serial))
        for i in range(self.state.n_spheres[None]):
            if ti.static(self.bounded_position_pass):
                if self.lift_scale[None] < 1:
                    self.w[i] *= self.lift_scale[None]
            self.state.x[i] += h * self.w[i]
            loss = self.kinetic_spent(i)
            if ti.static(self.f.gravity):
                loss += self.params.gravity[None].dot(self.state.x[i] - self.x_pre[i])
            if loss != 0:
                ti.atomic_add(self.params.energy_contacts[None], self.state.mass_of(i) * loss)
            ti.atomic_max(self.params.vmax2[None], self.state.v[i].norm_sqr())
            self.warm_n[i] = 0
            self.state.loaded[i] = 0
            if ti.static(self.rules.substeps):
                self.state.near[i] = 0
        ti.loop_config(serialize=ti.static(self.serial))
        for s in range(ti.min(self.n_rows[None], ti.static(self.capacity))):
            a = self.row_a[s]
            n, gap, meff = self.row_geometry(s)
            sigma = 2 * self.state.rad(a)
            if self.row_b[s] >= 0:
                sigma = self.state.rad(a) + self.state.rad(self.row_b[s])
            ti.atomic_max(self.params.contact_overlap[None], -gap / sigma)
            if self.lam[s] > 0:
                self.state.loaded[a] = 1
                if self.row_b[s] >= 0:
                    self.state.loaded[self.row_b[s]] = 1
                t = ti.atomic_add(self.warm_n[a], 1)
                if t < ti.static(self.perf.warm_slots):
                    self.warm_key[a, t] = self.row_b[s]
                    self.warm_lam[a, t] = self.lam[s]
                    if ti.static(self.f.friction):
                        self.warm_t[a, t] = self.lam_t[s]
                    if ti.static(self.f.rolling):
                        self.warm_r[a, t] = self.lam_r[s]
        if ti.static(self.rules.substeps):
            self.mark_near()
        else:       # (with substeps every impact to come has a row: none is flagged)
            self.measure_overlaps()
        self.h_prev[None] = h
        self.params.contacts[None] = self.n_rows[None]

    @ti.func
    def mark_near(self):
        """With Rules.substeps: state.near = 1 for the spheres with a row to a wall, an
        object or a loaded sphere (or loaded themselves), the spheres that can meet
        something slower than the impact speed; params.vmax2_near = the largest |v|^2
        of the loaded ones (stepping.Stepper.collide_in_substeps; kernel top level,
        after the loop that sets state.loaded)."""
        ti.loop_config(serialize=ti.static(self.serial))
        for s in range(ti.min(self.n_rows[None], ti.static(self.capacity))):
            a = self.row_a[s]
            b = self.row_b[s]
            if b < 0:
                self.state.near[a] = 1
            elif self.state.loaded[a] != 0 or self.state.loaded[b] != 0:
                self.state.near[a] = 1
                self.state.near[b] = 1
            if self.lam[s] > 0:
                speed2 = self.state.v[a].norm_sqr()
                if b >= 0:
                    speed2 = ti.max(speed2, self.state.v[b].norm_sqr())
                ti.atomic_max(self.params.vmax2_near[None], speed2)

    @ti.func
    def solve_stage(self, stage: ti.template()):
        """Stage ``stage`` of the serial solve (SOLVE_STAGES; kernel top level): the
        rows gathered, the cells that own them listed, their geometry, targets and warm
        impulses prepared, the warm start applied, the velocity sweeps, the position
        targets, the position sweeps, and the finish."""
        if ti.static(stage == 0):
            self.set_tolerances()
            self.gather()
        elif ti.static(stage == 1):
            self.list_active_cells()
            self.schedule_rows()
        elif ti.static(stage == 2):
            self.prepare_rows()
        elif ti.static(stage == 3):
            self.warm_start_serially()
            if ti.static(self.bounded_warm_start):
                self.bound_warm_start()
        elif ti.static(stage == 4):
            self.pack_rows(self.target, self.lam, True)
            self.params.contact_iterations[None] = self.iterate_serially(
                VELOCITY, self.cap_v, self.plain_v, self.tol_v)
            self.params.contact_residual[None] = self.residual[None]
            self.unpack_impulses(self.lam)
        elif ti.static(stage == 5):
            if ti.static(self.shock):
                self.shock_pass()
            self.position_targets()
        elif ti.static(stage == 6):
            self.pack_rows(self.pos_target, self.mu, False)
            self.params.position_iterations[None] = self.position_pass_serially()
        else:
            self.finish()

    @ti.func
    def position_pass_serially(self):
        """The position sweeps (iterate_serially, capped at cap_w), and where they stop
        leaving an overlap above tol_w (overlap_left), up to cap_x more
        (Rules.position_extension; one inlined copy of the sweeps); returns the sweeps
        run."""
        self.cap_p[None] = self.cap_w[None]
        n = 0
        rounds = 0
        while rounds >= 0:
            n += self.iterate_serially(POSITION, self.cap_p, self.plain_w, self.tol_w)
            rounds += 1
            extend = 0
            if rounds == 1 and self.cap_x[None] > 0:     # (nested: Taichi evaluates
                if self.overlap_left() > self.tol_w[None]:   # every operand of `and`)
                    extend = 1
            if extend != 0:
                self.cap_p[None] = self.cap_x[None]
            else:
                rounds = -1
        return n

    @ti.func
    def overlap_left(self):
        """The largest overlap the position pass's pseudo-velocities so far would leave
        on a row, per step [m/s]: max over the rows of -(gap / h + (w_a - w_b).n)
        (linearised, as the pass's targets; 0 where none; a max: any loop order)."""
        h = self.params.h[None]
        self.left_x[None] = 0
        ti.loop_config(serialize=ti.static(self.serial))
        for s in range(ti.min(self.n_rows[None], ti.static(self.capacity))):
            a = self.row_a[s]
            b = self.row_b[s]
            rel = self.w[a]
            if b >= 0:
                rel = rel - self.w[b]
            ti.atomic_max(self.left_x[None], -(self.gap[s] / h + rel.dot(self.normal[s])))
        return self.left_x[None]

    def _build_kernels(self):
        """The kernels solve() launches (plain closures: no per-launch `self` dispatch)."""
        params = self.params

        def serial_solve_kernel():
            """The one-launch solve for the bound interleave (self.interleave, read when
            it compiles: _serial_solve keeps one per interleave)."""
            @ti.kernel
            def solve_serial():
                for stage in ti.static(range(len(SOLVE_STAGES))):
                    self.solve_stage(stage)
            return solve_serial

        def staged_solve_kernels():
            """The same solve as one kernel per stage (SOLVE_STAGES, each named
            ``solve_<stage>``), launched in turn: Performance.staged_solve, for
            profiles that show each stage's time."""
            def stage_kernel(stage):
                def body():
                    self.solve_stage(stage)
                body.__name__ = "solve_" + SOLVE_STAGES[stage]
                return ti.kernel(body)
            kernels = [stage_kernel(stage) for stage in range(len(SOLVE_STAGES))]

            def launch_stages():
                for kernel in kernels:
                    kernel()
            return launch_stages

        @ti.kernel
        def start() -> ti.i32:
            self.set_tolerances()
            self.gather()
            self.list_active_cells()
            self.prepare_rows()
            return self.n_rows[None]

        self._build_sweep_kernels()

        @ti.kernel
        def forget_warm_start():
            self.h_prev[None] = 0
            for i in range(self.warm_n.shape[0]):
                self.warm_n[i] = 0
                self.state.loaded[i] = 0
                self.state.near[i] = 0

        @ti.kernel
        def bound_warm():
            self.bound_warm_start()

        @ti.kernel
        def middle():
            if ti.static(self.shock):
                self.shock_pass()
            self.position_targets()

        @ti.kernel
        def end(iterations: ti.i32, positions: ti.i32):
            params.contact_iterations[None] = iterations
            params.position_iterations[None] = positions
            self.finish()

        @ti.kernel
        def overlap_left() -> self.real:
            return self.overlap_left()

        self._overlap_left = overlap_left
        self._serial_solve_kernel = serial_solve_kernel
        self._staged_solve_kernels = staged_solve_kernels
        self._serial_solves = {}
        self._start, self._middle, self._end = start, middle, end
        self._bound_warm = bound_warm
        self._forget_warm_start = forget_warm_start

    def _build_sweep_kernels(self):
        """The kernel factories of the parallel sweeps (built per mode and colour count
        on first use: _sweep, _iterate) and batch_result."""
        real = self.real
        # one kernel per mode and colour count (a template argument costs Python
        # dispatch per launch): a launch is one sweep, every colour in turn (each
        # colour's loop a parallel task of its own), and returns the residual
        def sweep_kernel(mode, colours):
            @ti.kernel
            def sweep(omega: real) -> real:
                self.residual[None] = 0
                for colour in ti.static(range(colours)):
                    self.sweep_colour(colour, mode, omega)
                return self.residual[None]
            return sweep

        # and one per mode and colour count for a sweep of a batch (pgs.batched_sweep),
        # which returns nothing: a GPU queues the launches without the host waiting
        def batched_kernel(mode, colours, cap, last, tol):
            @ti.kernel
            def sweep(first: ti.i32):
                self.batched_sweep(first, mode, colours, cap, last, tol)
            return sweep

        @ti.kernel
        def batch_result() -> ti.i32:
            return self.batch_result()

        self._sweep_kernel = sweep_kernel
        self._batched_kernel = batched_kernel
        self._batch_result = batch_result
        self._sweeps = {}

    def _serial_solve(self):
        """The one-launch solve kernel of the bound interleave, or with
        Performance.staged_solve its stages one kernel each (built once per interleave
        and staging: load_host_options)."""
        key = (self.interleave, self.solve_in_stages)
        if key not in self._serial_solves:
            self._serial_solves[key] = (self._staged_solve_kernels() if self.solve_in_stages
                                        else self._serial_solve_kernel())
        return self._serial_solves[key]

    def _sweep(self, mode, batched=None):
        """The one-sweep kernel of ``mode`` for the bound colour count and parallel
        interleave (built once each: load_host_options); ``batched``: (caps, last, tol)
        of a batched solve, whose sweep kernel it is."""
        # (a batched kernel reads its caps, plain sweeps and tolerance fields: one per set)
        key = (mode, self.n_colours, None if batched is None else tuple(map(id, batched)),
               self.interleave_parallel)
        if key not in self._sweeps:
            self._sweeps[key] = (self._sweep_kernel(mode, self.n_colours) if batched is None
                                 else self._batched_kernel(mode, self.n_colours, *batched))
        return self._sweeps[key]

    def solve(self) -> None:
        """Gather the rows of the current state (grid freshly built) and solve them for a
        step of length params.h; counters go to params (contacts, contact_iterations,
        contact_residual, position_iterations, energy_contacts, contact_overlap). On
        the CPU below Performance.serial_solver_below spheres the sweeps run serially
        in one launch (a parallel launch per sweep costs ~150 us there)."""
        if self.serial or (self.cpu and self.n < self.serial_solver_below):
            self._serial_solve()()      # the same sweeps in one launch: the same bits
            return
        self._start()
        if self.rules.warm_start:
            self._sweep(WARM)(1.0)
            if self.bounded_warm_start:
                self._bound_warm()
        iterations = self._iterate(VELOCITY, self.cap_v, self.plain_v, self.tol_v)
        self.params.contact_residual[None] = self.residual[None]
        self._middle()
        positions = self._iterate(POSITION, self.cap_w, self.plain_w, self.tol_w)
        if self.extension > 0 and self._overlap_left() > self.tol_w[None]:
            positions += self._iterate(POSITION, self.cap_x, self.plain_w, self.tol_w)
        self._end(iterations, positions)

    def _iterate(self, mode, caps, last, tol) -> int:
        """iterate_serially with one launch per sweep, each returning its residual, or
        (self.batch > 1) batches of self.batch launches and one wait for whether the
        solve is done (same sweeps, same bits)."""
        if self.batch > 1:
            sweep, first = self._sweep(mode, (caps, last, tol)), 1
            while True:
                for _ in range(self.batch):
                    sweep(first)
                    first = 0
                ran = self._batch_result()
                if ran:
                    return ran
        limit, cap, plain_sweeps = tol[None], caps[None], last[None]
        sweep = self._sweep(mode)
        it, relaxed, done = 0, int(self.relaxation != 1), 0
        while done == 0:      # iterate_serially's loop (pgs.plain_sweep, pgs.next_sweep)
            plain = plain_sweep(it, relaxed, cap, plain_sweeps)
            residual = sweep(1.0 if plain else self.relaxation)
            it, relaxed, done = next_sweep(it, relaxed, plain, cap, int(not residual > limit))
        return it
