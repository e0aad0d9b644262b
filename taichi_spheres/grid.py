"""Uniform grid: cell geometry, colours, and a deterministic counting sort (step stage 2).

Cells are at least the largest diameter plus a margin ``2 * slack`` wide, so every
pair closer than contact lies in the same or adjacent cells even after the spheres
have moved by up to ``slack`` since the grid was built.

Ownership and colours (docs/design.md, "One step, in parallel"): a pair of spheres in cells
``a`` and ``b`` is *owned* by the cell ``c = lower(a, b)`` (component-wise lower,
periodic-aware), so cell ``c`` only ever touches the 2x2x2 block ``c + {0,1}^3``.
Cells whose coordinates have equal parity on every axis (8 colours) have disjoint
blocks, so one thread per cell of one colour can update its spheres with no race.
A periodic axis with an odd cell count gives its last cell a third colour on that
axis (up to 27 colours), because cells ``n-1`` and ``0`` are neighbours there.
``tests/test_grid.py`` checks both facts on the compiled kernels.
"""

import dataclasses
import itertools
import math

import taichi as ti

from .cells import CellArithmetic
from .config import DEFAULT, Performance
from .state import SphereState

__all__ = ["GridGeometry", "Grid", "BLOCK_PAIRS", "FORWARD_ROWS", "ALL_ROWS"]


def _block_pairs():
    """Cell pairs (alpha, beta) inside the block c + {0,1}^3 whose lower cell is c.

    alpha and beta have disjoint supports; the list starts with the cell itself
    (0,0,0)-(0,0,0) and then has the 13 pairs of distinct cells.
    """
    cube = list(itertools.product((0, 1), repeat=3))
    out = [((0, 0, 0), (0, 0, 0))]
    seen = set()
    for a in cube:
        for b in cube:
            if a == b or any(p and q for p, q in zip(a, b)):
                continue
            key = frozenset((a, b))
            if key not in seen:
                seen.add(key)
                out.append((a, b))
    assert len(out) == 14
    return tuple(out)


#: The 14 cell pairs a cell owns (itself + 13), as offsets from the owner.
BLOCK_PAIRS = _block_pairs()
#: Neighbour stencils as rows along z, (dx, dy, dz_lo, dz_hi): the cells of one row are
#: contiguous in the sorted order, so a row is one range of sphere ids (two if it wraps
#: around a periodic z axis) instead of up to three cell look-ups. FORWARD_ROWS is the
#: half stencil (the cell itself, then the 13 lexicographically positive neighbours);
#: ALL_ROWS the full 27 cells.
FORWARD_ROWS = ((0, 0, 0, 1), (0, 1, -1, 1), (1, -1, -1, 1), (1, 0, -1, 1), (1, 1, -1, 1))
ALL_ROWS = tuple((dx, dy, -1, 1) for dx in (-1, 0, 1) for dy in (-1, 0, 1))


@dataclasses.dataclass(frozen=True)
class GridGeometry:
    """Cell layout of the box (pure Python, no Taichi).

    lo: (3,) box corner [m]; cell: (3,) cell size per axis [m]; dims: (3,) cells per
    axis; periodic: per-axis bools; slack: distance a sphere may move after the
    grid was built before the grid must be rebuilt [m].
    """

    lo: tuple
    cell: tuple
    dims: tuple
    periodic: tuple
    slack: float

    @classmethod
    def for_scene(cls, scene, step_fraction, perf: Performance = DEFAULT.performance):
        """for_box for a Scene's box, radii and sphere count (what Simulation builds,
        and what the memory estimate counts)."""
        return cls.for_box(scene.box_lo, scene.box_hi, scene.periodic,
                           float(scene.radius.max()), float(scene.radius.min()), scene.n,
                           step_fraction, perf)

    @classmethod
    def for_box(cls, lo, hi, periodic, r_max, r_min, n, step_fraction,
                perf: Performance = DEFAULT.performance):
        """Cells of at least the largest diameter plus a margin for moves, aiming at
        perf.wide_margin x the largest move per step (step_fraction x r_min), at most
        about perf.max_cells_per_sphere per sphere; at least 3 on a periodic axis."""
        slack = step_fraction * r_min
        # the grid is built after the drift, so the margin is for the moves that come
        # after it: a collision carried forward can move a sphere by up to twice a step's
        # largest move (relative speed up to twice the largest speed); a narrower margin
        # makes re-binnings mid-step common in dense gases (min_cell is what the
        # stencil needs, wide_cell what the grid aims at)
        min_cell = 2.0 * r_max + 2.0 * slack
        wide_cell = 2.0 * r_max + perf.wide_margin * slack
        # no more cells than max_cells_per_sphere per sphere: dilute scenes keep memory O(N)
        volume = math.prod(h - l for l, h in zip(lo, hi))
        target = max(wide_cell, (volume / (perf.max_cells_per_sphere * max(n, 1))) ** (1 / 3))
        dims, cell = [], []
        for a in range(3):
            length = hi[a] - lo[a]
            k = max(1, int(math.floor(length / target)))
            if periodic[a] and k < 3:
                k = int(math.floor(length / min_cell))
                if k < 3:
                    raise ValueError(
                        f"periodic axis {'xyz'[a]}: box length {length:g} m must be at least 3 cells "
                        f"of {min_cell:g} m (largest diameter {2 * r_max:g} m plus margin); "
                        f"enlarge the box or use walls on that axis")
            if periodic[a] and k % 2 == 1 and k > 3:
                k -= 1   # even count: 2 colours on this axis instead of 3
            dims.append(k)
            cell.append(length / k)
        # the margin actually available once cells are rounded up to fit the box
        slack = max(slack, 0.5 * (min(cell) - 2.0 * r_max))
        return cls(lo=tuple(float(v) for v in lo), cell=tuple(cell), dims=tuple(dims),
                   periodic=tuple(bool(p) for p in periodic), slack=slack)

    @property
    def n_cells(self) -> int:
        return self.dims[0] * self.dims[1] * self.dims[2]

    def axis_colours(self, a):
        """Colours on axis a as (start, stride, count) of the cells that have it."""
        n = self.dims[a]
        if self.periodic[a] and n % 2 == 1:
            return ((0, 2, (n - 1) // 2), (1, 2, (n - 1) // 2), (n - 1, 1, 1))
        return tuple(c for c in ((0, 2, (n + 1) // 2), (1, 2, n // 2)) if c[2] > 0)

    @property
    def colours(self):
        """All colours: tuples of three (start, stride, count), one per axis."""
        return tuple(itertools.product(*(self.axis_colours(a) for a in range(3))))

    def colour_cells(self, colour):
        """Cell coordinates of one colour (Python mirror of the kernel loop)."""
        axes = [range(s, s + d * k, d) for s, d, k in colour]
        return list(itertools.product(*axes))


@ti.data_oriented
class Grid(CellArithmetic):
    """Counting-sort cell list over a :class:`SphereState`.

    The fields hold up to ``cell_capacity`` cells; the geometry (cells per axis, cell
    size, corner, slack) is data, loaded by :meth:`bind`, so that one compiled grid
    serves every box with the same periodic axes (engine.py). Only which axes are
    periodic is compiled in. The cell arithmetic on these fields (coordinates of a
    point, stencil rows, pair ownership) is in :class:`cells.CellArithmetic`.

    Fields (M = cells of the bound geometry, N = spheres):
        start: (M+1,) i32 — exclusive prefix of cell counts; sphere ids of cell c are
            ``order[start[c]:start[c+1]]``, sorted by id (deterministic on every arch)
        order: (N,) i32 sphere ids by cell;  cell_of: (N,) i32 linear cell of sphere
        cursor: (M,) i32 scatter cursors;  scan_bufs: start and the block sums of its scan
        xs: (N,) vec3 — positions in ``order`` (xs[p] = x[order[p]]) [m], so that a
            neighbour scan walks a row of cells through contiguous memory; slot: (N,)
            i32 — where sphere i sits in ``order``. Whoever moves a sphere after the
            build must call :meth:`refresh` for it (or build again) before the next
            scan.
        dims: () vec3 i32 cells per axis; cell: () vec3 real cell size [m]; lo, inv_cell:
            () vec3 real box corner [m] and 1/cell [1/m]; n_cells: () i32 = M;
            slack: () real [m] (GridGeometry); scan_size: (levels,) i32 items per level.
        all_rows: (9,) vec4 i32 — ALL_ROWS, the full stencil as rows (walked by runtime
            loops in the projection and the contact solver: unrolled, it would
            multiply their compile time); written by :meth:`bind`.
    """

    def __init__(self, cell_capacity: int, periodic: tuple, state: SphereState,
                 serial_light: bool, scan_block: int = DEFAULT.performance.scan_block):
        self.periodic = tuple(bool(p) for p in periodic)
        self.state = state
        self.real = state.real
        self.cell_capacity = cell_capacity
        self.geom = None
        self.m = 0
        self.serial_light = serial_light
        self.scan_block = scan_block
        cap = state.capacity
        self.start = ti.field(ti.i32, shape=cell_capacity + 1)
        self.cursor = ti.field(ti.i32, shape=cell_capacity)
        self.order = ti.field(ti.i32, shape=cap)
        self.cell_of = ti.field(ti.i32, shape=cap)
        self.xs = ti.Vector.field(3, self.real, shape=cap)
        self.slot = ti.field(ti.i32, shape=cap)
        # multi-level blocked exclusive scan: level k scans scan_size[k] items of
        # bufs[k]; as many levels as the capacity needs (a smaller grid leaves the top
        # levels with one item)
        self.scan_capacity = [cell_capacity]
        self.scan_bufs = [self.start]
        while self.scan_capacity[-1] > scan_block:
            size = -(-self.scan_capacity[-1] // scan_block)
            self.scan_capacity.append(size)
            self.scan_bufs.append(ti.field(ti.i32, shape=size))
        self.scan_size = ti.field(ti.i32, shape=len(self.scan_capacity))
        self.lo = ti.Vector.field(3, self.real, shape=())
        self.inv_cell = ti.Vector.field(3, self.real, shape=())
        self.cell = ti.Vector.field(3, self.real, shape=())
        self.dims = ti.Vector.field(3, ti.i32, shape=())
        self.n_cells = ti.field(ti.i32, shape=())
        self.slack = ti.field(self.real, shape=())
        self.all_rows = ti.Vector.field(4, ti.i32, shape=len(ALL_ROWS))
        self.host_load = None      # the engine's hostload.FieldLoad
        self.scan_sizes = None

        # hot kernels as plain closures: a data_oriented method kernel pays ~40 us of
        # Python dispatch per launch for its `self` template argument

        @ti.kernel
        def build():
            self._build_body()

        self.build = build

    @staticmethod
    def loaded_fields() -> tuple:
        """The fields bind loads (hostload.FieldLoad)."""
        return ("lo", "inv_cell", "cell", "dims", "n_cells", "slack", "scan_size", "all_rows")

    def bind(self, geom: GridGeometry):
        """Load the cell layout ``geom`` (at most cell_capacity cells, the periodic axes
        this grid was compiled for)."""
        if geom.n_cells > self.cell_capacity or tuple(geom.periodic) != self.periodic:
            raise ValueError("grid geometry does not fit these fields")
        self.geom = geom
        self.m = geom.n_cells
        sizes = [geom.n_cells]
        while len(sizes) < len(self.scan_capacity):
            sizes.append(-(-sizes[-1] // self.scan_block))
        self.scan_sizes = sizes          # items per scan level (Python ints)
        self.host_load.write(self, lo=geom.lo, inv_cell=[1.0 / c for c in geom.cell],
                             cell=geom.cell, dims=geom.dims, n_cells=geom.n_cells,
                             slack=geom.slack, scan_size=sizes, all_rows=ALL_ROWS)

    # ---- build ----
    def scan_buffers(self, first):
        """Level buffers for :meth:`exclusive_scan` of ``first`` (an i32 field of at least
        cell_capacity items): ``first``, then new fields for the block sums."""
        return [first] + [ti.field(ti.i32, shape=size) for size in self.scan_capacity[1:]]

    @ti.func
    def exclusive_scan(self, bufs: ti.template()):
        """In-place exclusive prefix sum of bufs[0][0:M] (blocked: parallel loops on
        every arch, serial where the grid runs light loops serially; ``bufs`` from
        :meth:`scan_buffers`; the grid's own is ``scan_bufs``, over ``start``)."""
        B = ti.static(self.scan_block)
        levels = ti.static(len(self.scan_capacity))
        for lv in ti.static(range(levels - 1)):
            buf = ti.static(bufs[lv])
            nxt = ti.static(bufs[lv + 1])
            size = self.scan_size[lv]
            ti.loop_config(serialize=ti.static(self.serial_light or self.scan_capacity[lv + 1] < 8))
            for b in range(self.scan_size[lv + 1]):
                acc = 0
                for k in range(B):
                    idx = b * B + k
                    if idx < size:
                        t = buf[idx]
                        buf[idx] = acc
                        acc += t
                nxt[b] = acc
        top = ti.static(bufs[levels - 1])
        ti.loop_config(serialize=True)
        for _ in range(1):
            acc = 0
            for k in range(self.scan_size[levels - 1]):
                t = top[k]
                top[k] = acc
                acc += t
        for lv in ti.static(range(levels - 2, -1, -1)):
            buf = ti.static(bufs[lv])
            nxt = ti.static(bufs[lv + 1])
            ti.loop_config(serialize=ti.static(self.serial_light))
            for idx in range(self.scan_size[lv]):
                buf[idx] += nxt[idx // B]

    @ti.func
    def _build_body(self):
        """Counting sort of spheres into cells: count, scan, scatter, sort each cell by id,
        then copy the positions into that order (xs) and record each sphere's slot (a
        serial scatter, in id order, leaves each cell sorted and does the copy itself).

        Also resets ``state.moved`` (distance moved since this build) to 0.
        """
        n = self.state.n_spheres[None]
        m = self.n_cells[None]
        ti.loop_config(serialize=ti.static(self.serial_light))
        for c in range(m + 1):
            self.start[c] = 0
        ti.loop_config(serialize=ti.static(self.serial_light))
        for i in range(n):
            k = self.linear(self.coords_of_position(self.state.x[i]))
            self.cell_of[i] = k
            ti.atomic_add(self.start[k], 1)
            self.state.moved[i] = 0
        self.exclusive_scan(self.scan_bufs)
        ti.loop_config(serialize=ti.static(self.serial_light))
        for c in range(m):
            self.cursor[c] = self.start[c]
        self.start[m] = n
        ti.loop_config(serialize=ti.static(self.serial_light))
        for i in range(n):
            slot = ti.atomic_add(self.cursor[self.cell_of[i]], 1)
            self.order[slot] = i
            if ti.static(self.serial_light):
                # a serial scatter fills each cell in id order: done in one pass
                self.slot[i] = slot
                self.xs[slot] = self.state.x[i]
        if ti.static(not self.serial_light):
            # atomics scatter in a thread-dependent order: sort each cell by sphere id
            for c in range(m):
                lo = self.start[c]
                hi = self.start[c + 1]
                for p in range(lo + 1, hi):
                    key = self.order[p]
                    q = p - 1
                    while q >= lo and self.order[q] > key:
                        self.order[q + 1] = self.order[q]
                        q -= 1
                    self.order[q + 1] = key
                for p in range(lo, hi):
                    i = self.order[p]
                    self.slot[i] = p
                    self.xs[p] = self.state.x[i]

    @ti.func
    def refresh(self, i):
        """Copy sphere i's current position into ``xs`` (after it moved)."""
        self.xs[self.slot[i]] = self.state.x[i]
