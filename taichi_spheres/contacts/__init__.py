"""Pair contacts (step stages 3-4): parallel detection, rewind to contact, collide per colour.

One class, :class:`Contacts`, with its concerns in files of their own: the pair rule
(pair.py: where one collision is resolved), detection (detection.py), near lists
(near.py) and the colour sweeps (sweeps.py); this file holds the fields, the
kernels the step launches and the choice between their variants.

Near lists (:meth:`Contacts.detect`, from 3,000 spheres on): a full scan keeps each
sphere's forward neighbours closer than the narrowest cell; later detections examine
only those pairs, plus every neighbour of the spheres that moved more than half the
spare reach since (they are scanned around in the grid), until too many have.
"""

import typing

import numpy as np
import taichi as ti

from ..config import DEFAULT, Performance, Tuning
from ..params import StepParams
from ..grid import BLOCK_PAIRS, FORWARD_ROWS, Grid
from ..state import Features, SphereState
from ..walls import Motion
from .detection import Detection
from .near import NearLists, near_allowance
from .pair import PairRule
from .sweeps import MAX_COLOURS, ColourSweeps

__all__ = ["Contacts", "Status", "near_allowance", "decode_status", "MAX_COLOURS"]


class Status(typing.NamedTuple):
    """What a detection found: ``remaining`` approaching overlaps, and whether a sphere
    moved farther than the grid's slack (``rebuild``: the grid must be built again)."""

    remaining: int
    rebuild: bool


def decode_status(status: int) -> Status:
    """The Status a detection kernel returned packed in one i32 (2 x remaining +
    rebuild: one launch returns both; :meth:`Contacts.status`, ``detect_all``,
    ``sweep``)."""
    return Status(status >> 1, bool(status & 1))


@ti.data_oriented
class Contacts(PairRule, Detection, NearLists, ColourSweeps):
    """Detection and colour-by-colour resolution of overlapping approaching pairs.

    Fields: active (M,) i32 — approaching overlapping pairs owned by each cell, found
    by the last detection pass; cell_pairs (M, recorded_pairs) vec2 i32 — the first
    of them found (in thread-dependent order); active_list
    (M,) / n_active — the cells with active > 0; touched (N,) / n_touched — spheres a
    sweep changed; marked (N,) i32 — 1 at the grid slot (``grid.slot``) of each of
    them, so that scans read the flag of a neighbour from contiguous memory and the
    re-detection can visit the touched spheres in cell order.

    Near lists (near_lists=True, see :meth:`detect`), indexed by the grid slot a
    sphere had when the list was made: near_id (N,) i32 — that sphere; near (N,
    near_capacity) i32 — the spheres its forward scan found closer than
    ``near_reach``; n_near (N,) i32 — how many; x_near (N,) vec3 — its position then;
    near_ok () i32 — 1 when the last full scan fitted every sphere's list.
    """

    def __init__(self, state: SphereState, grid: Grid, params: StepParams, motion: Motion,
                 features: Features, serial_light: bool, serial_heavy: bool,
                 serial_few: bool = False, near_lists: bool = False, tuning: Tuning = DEFAULT):
        self.rules = tuning.physics
        self.perf = tuning.performance
        #: the bound Simulation's options (config.HOST_ONLY: few_pairs, serial_resolve_pairs)
        self.host = tuning.performance
        self.state = state
        self.grid = grid
        self.params = params
        self.motion = motion
        self.f = features
        self.real = state.real
        self.serial_light = serial_light
        self.serial_heavy = serial_heavy
        # only worth a second compiled variant where the loops are otherwise parallel
        self.serial_few = serial_few and not serial_heavy
        eps = float(np.finfo(np.float64 if self.real == ti.f64 else np.float32).eps)
        self.eps = eps              # machine epsilon of the precision
        self.approach_eps = 8.0 * eps
        self.near_lists = near_lists
        self._allocate_fields(grid.cell_capacity, state.capacity)
        self.host_load = None      # the engine's hostload.FieldLoad
        self.near_ready = False     # a full scan made a complete list (Python's copy)
        self._build_kernels()

    def _allocate_fields(self, cells: int, cap: int):
        """The fields (see the class docstring) for ``cells`` cells and ``cap`` spheres."""
        self.active = ti.field(ti.i32, shape=cells)
        # the first pairs the detection counted for a cell (all of them when it found
        # at most recorded_pairs), oriented as the forward scan meets them
        self.cell_pairs = ti.Vector.field(2, ti.i32, shape=(cells, self.perf.recorded_pairs))
        # stencils as small tables walked by runtime loops (unrolling them multiplies
        # compile time)
        # (both loaded by bind_scalars)
        self.fwd_rows = ti.Vector.field(4, ti.i32, shape=len(FORWARD_ROWS))
        self.block = ti.Vector.field(3, ti.i32, shape=(len(BLOCK_PAIRS), 2))
        self.colours = ()
        # colours per axis (1-3) and 1 where the last cell of an odd periodic axis has
        # a colour of its own (see colour_index), of the bound geometry
        self.axis_colours = ti.Vector.field(3, ti.i32, shape=())
        self.odd_last = ti.Vector.field(3, ti.i32, shape=())
        # compact lists, so that sweeps cost O(pairs) and not O(N + cells): the cells
        # with pending pairs, and the spheres a sweep touched (order is thread-dependent,
        # but every use is order-independent: disjoint blocks, per-sphere updates)
        self.active_list = ti.field(ti.i32, shape=cells)
        self.n_active = ti.field(ti.i32, shape=())
        # the listed cells sorted by colour (bucket_by_colour), and where each starts
        self.by_colour = ti.field(ti.i32, shape=cells)
        self.colour_start = ti.field(ti.i32, shape=MAX_COLOURS + 1)
        self.colour_fill = ti.field(ti.i32, shape=MAX_COLOURS)
        self.touched = ti.field(ti.i32, shape=cap)
        self.marked = ti.field(ti.i32, shape=cap)
        # per sphere, the earliest contact (largest time since contact) among its pairs
        # found by the last detection: a pair is collided only when it is the earliest
        # contact of both its spheres, so colours do not reorder one sphere's collisions
        self.earliest = ti.field(self.real, shape=cap)
        self.n_touched = ti.field(ti.i32, shape=())
        # scene values the kernels read (bind): half the common mass [kg] (equal
        # masses), the reach of a pruned walk beyond r_i (r_max + round-off margin) [m]
        self.half_m0 = ti.field(self.real, shape=())
        self.walk_reach = ti.field(self.real, shape=())
        self.debug_pairs = None     # allocated by list_overlaps (tests only)
        if self.near_lists:
            # squared reach and allowance of the lists [m^2] (bind)
            self.near_reach2 = ti.field(self.real, shape=())
            self.near_allowance2 = ti.field(self.real, shape=())
            # indexed by the grid slot the sphere had when its list was made, so that
            # the scan writes them in order
            self.near_id = ti.field(ti.i32, shape=cap)
            self.near = ti.field(ti.i32, shape=(cap, self.perf.near_capacity))
            self.n_near = ti.field(ti.i32, shape=cap)
            self.x_near = ti.Vector.field(3, self.real, shape=cap)
            self.near_ok = ti.field(ti.i32, shape=())


    def _build_kernels(self):
        """The kernels the step launches, as plain closures (see below)."""
        # hot kernels as plain closures: a data_oriented method kernel pays ~40 us of
        # Python dispatch per launch for its `self` template argument
        # kernels that end a detection return its status (see status()): one launch
        # instead of a launch plus two scalar reads per sweep

        @ti.kernel
        def forget():
            self.forget_pending()

        @ti.kernel
        def detect_all() -> ti.i32:
            self._detect_all_body()
            return self.status()

        @ti.kernel
        def detect_near() -> ti.i32:
            self.reset_detection_state()
            self.mark_fast_movers()
            live = self.near_live()
            self.scan_near(live)
            self.detect_around_touched(False, live)
            self.clear_marks(False)
            out = -1
            if live:
                out = self.status()
            return out

        @ti.kernel
        def bucket_parallel():
            self.bucket_by_colour(False)

        @ti.kernel
        def resolve_colour_parallel(colour: ti.i32):
            self.resolve_colour(colour, False)

        @ti.kernel
        def sweep_serial() -> ti.i32:
            self.resolve_colours_serially()
            self.after_sweep(True)
            return self.status()

        @ti.kernel
        def sweep_mixed() -> ti.i32:
            self.resolve_colours_serially()
            self.after_sweep(False)
            return self.status()

        @ti.kernel
        def after_sweep_parallel() -> ti.i32:
            self.after_sweep(False)
            return self.status()


        self.forget = forget
        self.detect_all = detect_all
        self.detect_near = detect_near if self.near_lists else None
        self.bucket_parallel = bucket_parallel
        self.resolve_colour_parallel = resolve_colour_parallel
        self.sweep_serial = sweep_serial
        self.sweep_mixed = sweep_mixed
        self.after_sweep_parallel = after_sweep_parallel

    def loaded_fields(self) -> tuple:
        """The fields bind loads (hostload.FieldLoad)."""
        return ("axis_colours", "odd_last", "half_m0", "walk_reach", "fwd_rows", "block") + (
            ("near_reach2", "near_allowance2") if self.near_lists else ())

    def bind(self, scene, geom, perf: Performance):
        """Load what the kernels read of a scene and its grid geometry ``geom`` (after
        state.bind and grid.bind), and the bound Simulation's options ``perf``
        (config.Performance: few_pairs and serial_resolve_pairs choose the path of
        sweep); forget the near lists and any pending pairs."""
        self.host = perf
        self.bind_scalars(scene, geom)
        self.forget()

    def bind_scalars(self, scene, geom):
        """bind's values that follow from the scene and ``geom``: the sphere count,
        colours, half the first sphere's mass, the walks' reach and the near lists'
        reach; the near lists are forgotten (their sphere indices are the scene's)."""
        self.n = scene.n
        self.colours = geom.colours
        # round-off allowance of the cells a walk skips (examine_around) [m]: positions
        # and cell faces carry a few eps of the largest coordinate
        extent = max(max(abs(a), abs(b)) for a, b in zip(scene.box_lo, scene.box_hi))
        r_max = float(scene.radius.max())
        values = dict(
            fwd_rows=FORWARD_ROWS, block=BLOCK_PAIRS,
            axis_colours=[len(geom.axis_colours(a)) for a in range(3)],
            odd_last=[int(p and d % 2 == 1) for p, d in zip(geom.periodic, geom.dims)],
            half_m0=0.5 * float(scene.mass[0]),
            walk_reach=r_max + 64.0 * self.eps * (extent + max(geom.cell)))
        self.near_reach, allowance = near_allowance(geom, r_max, self.perf.near_safety)
        if self.near_lists:
            if not allowance > 0:
                raise ValueError("near lists need cells wider than the largest diameter")
            values.update(near_reach2=self.near_reach ** 2,
                          near_allowance2=allowance * allowance)
        self.host_load.write(self, **values)
        self.near_ready = False

    @ti.func
    def forget_pending(self):
        """No cell owns a pending pair and no sphere is touched (kernel top level): what
        bind (through the kernel ``forget``) and the take-out (takeout.py) leave."""
        for c in range(self.active.shape[0]):
            self.active[c] = 0
        self.n_active[None] = 0
        self.n_touched[None] = 0

    # ---- the step's entry points ----
    def detect(self):
        """Full detection (fills ``active`` and params.remaining) on a freshly built
        grid; returns (status, from_list). From the near lists while they are
        complete and at most 1 sphere in near_fast_limit moved more than the allowance
        since a full scan made them (those are scanned around in the grid), else by a
        full scan, which makes new lists. Both find the same pairs and give the same bits; the list
        examines about 2 pairs per sphere in a gas at packing fraction 0.3 instead of
        the scan's 14 (and its 5 row look-ups)."""
        if self.near_ready:
            status = self.detect_near()
            if status >= 0:
                return status, True
        status = self.detect_all()
        self.near_ready = self.near_lists and bool(self.near_ok[None])
        return status, False

    def sweep(self, pending) -> int:
        """Resolve every colour in turn, then :meth:`after_sweep`; returns the status of
        the new detection (:func:`decode_status`). On the CPU, with few pending pairs
        the loops run serially (a parallel launch there costs more than the work; a
        second compiled variant, built on first use), with more the resolution runs
        serially and the detection in parallel, in one launch; otherwise (and on GPUs)
        the colours run in parallel one launch each. (A kernel looping over sweeps
        would save a launch per sweep but doubles the compile time: see fused.py.)"""
        if self.serial_heavy or (self.serial_few and pending <= self.host.few_pairs):
            return self.sweep_serial()
        if self.serial_few and pending <= self.host.serial_resolve_pairs:
            return self.sweep_mixed()
        self.bucket_parallel()
        for k in range(len(self.colours)):
            self.resolve_colour_parallel(k)
        return self.after_sweep_parallel()

    # ---- debugging / tests ----
    def list_overlaps(self):
        """Sorted (K, 2) int array of the overlapping approaching pairs that the
        detection scan finds (same code path as detect_all, recording instead)."""
        if self.debug_pairs is None:
            self.debug_pairs = ti.Vector.field(2, ti.i32, shape=8 * self.state.capacity + 16)
            self.debug_count = ti.field(ti.i32, shape=())

            @ti.kernel
            def record():
                self.debug_count[None] = 0
                self.scan_forward(True)

            self._record = record
        self._record()
        k = int(self.debug_count[None])
        if k > self.debug_pairs.shape[0]:
            raise RuntimeError(f"{k} overlapping pairs: more than the debug list holds")
        pairs = self.debug_pairs.to_numpy()[:k]
        return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]

    @ti.kernel
    def _block_touches(self, sx: ti.i32, dx: ti.i32, nx: ti.i32, sy: ti.i32, dy: ti.i32,
                       ny: ti.i32, sz: ti.i32, dz: ti.i32, nz: ti.i32,
                       touches: ti.types.ndarray()):
        """touches[i] += 1 for each owner cell of one colour whose block holds sphere i."""
        for I in ti.grouped(ti.ndrange(nx, ny, nz)):
            c = ti.Vector([sx + dx * I[0], sy + dy * I[1], sz + dz * I[2]])
            for a in ti.static(range(2)):
                for b in ti.static(range(2)):
                    for e in ti.static(range(2)):
                        cb, ok = self.grid.shifted(c, ti.Vector([a, b, e]))
                        if ok:
                            kb = self.grid.linear(cb)
                            for q in range(self.grid.start[kb], self.grid.start[kb + 1]):
                                ti.atomic_add(touches[self.grid.order[q]], 1)

    def block_touches(self, colour_index):
        """(N,) int: how many owner cells of colour ``colour_index`` may touch each sphere."""
        touches = np.zeros(self.n, dtype=np.int32)
        col = self.colours[colour_index]
        self._block_touches(*col[0], *col[1], *col[2], touches)
        return touches
