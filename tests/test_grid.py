"""Grid, ownership and colours: the parallel path finds what brute force finds, and no
sphere can be touched by two threads of one colour."""
import itertools

import numpy as np
import pytest

import taichi_spheres as ts
from taichi_spheres.config import DEFAULT
from taichi_spheres.builders import gas
from taichi_spheres.grid import BLOCK_PAIRS, GridGeometry


def brute_force_overlaps(st, box_lo, box_hi, periodic, eps, h):
    """All pairs (i < j) to resolve, by the engine's rule, over all N^2 pairs (minimum
    image): overlapping, and approaching (d.u < -eps |d| sqrt(|u|^2 + |v_i|^2 +
    |v_j|^2)), or entered within the last h while approaching at the entry point."""
    x, v, r = st.x, st.v, st.radius
    size = box_hi - box_lo
    d = x[:, None, :] - x[None, :, :]
    for a in range(3):
        if periodic[a]:
            d[..., a] -= size[a] * np.round(d[..., a] / size[a])
    u = v[:, None, :] - v[None, :, :]
    dd = (d * d).sum(-1)
    du = (d * u).sum(-1)
    uu = (u * u).sum(-1)
    speed2 = (v * v).sum(-1)
    scale = uu + speed2[:, None] + speed2[None, :]
    sig = r[:, None] + r[None, :]
    overlap = dd < sig * sig
    approach = du < -eps * np.sqrt(dd * scale)
    with np.errstate(divide="ignore", invalid="ignore"):
        c = sig * sig - dd
        s = c / (np.sqrt(du * du + uu * c) - du)
        dc = d - u * s[..., None]
        entry_approach = (dc * u).sum(-1) < -eps * np.sqrt((dc * dc).sum(-1) * scale)
    hit = overlap & (uu > 0) & (approach | ((s <= h) & entry_approach))
    i, j = np.nonzero(np.triu(hit, 1))
    return np.stack([i, j], 1)


def _overlapping_scene(n, periodic, seed, poly=0.0):
    """A gas whose spheres are then pushed towards each other so many pairs overlap."""
    base = gas(n, packing=0.1 if poly else 0.25, periodic=periodic, seed=seed, polydispersity=poly,
               gravity=(0, 0, 0))
    return base


@pytest.mark.parametrize("periodic,poly", [(True, 0.0), (False, 0.0), ((True, False, True), 0.6)])
def test_grid_detection_matches_brute_force(arch, periodic, poly):
    scene = _overlapping_scene(400, periodic, seed=3, poly=poly)
    sim = ts.Simulation(scene, arch=arch)
    # a long free flight creates many overlaps without resolving them
    h = (60 if poly else 20) * sim.max_step()
    sim.debug_view().params.h[None] = h
    sim.debug_view().motion.drift()
    pairs = sim.grid_overlaps()
    st = sim.state()
    ref = brute_force_overlaps(st, scene.box_lo, scene.box_hi, scene.periodic,
                               sim.debug_view().contacts.approach_eps, h)
    assert len(ref) > 10, "the set-up must produce overlaps to compare"
    np.testing.assert_array_equal(pairs, ref)
    # the production pass: every pair counted once, each for exactly one owner cell
    sim.debug_view().contacts.detect_all()
    assert sim.debug_view().params.remaining[None] == len(ref)
    assert sim.debug_view().contacts.active.to_numpy().sum() == len(ref)
    contacts = sim.debug_view().contacts
    assert contacts.n_active[None] == np.count_nonzero(contacts.active.to_numpy())


@pytest.mark.parametrize("periodic,poly,prune", [(True, 0.0, True), ((True, False, True), 0.6, True),
                                                 (True, 0.0, False)])
def test_walks_around_touched_spheres_match_brute_force(arch, precision, periodic, poly, prune):
    """The walk around a touched sphere (Contacts.examine_around, which skips the cells
    across faces farther than r_i + r_max + M, M the farthest move since the grid was
    built; with prune_walks = False it walks all 27) finds every pair brute force
    finds: overlaps from a long free flight, then every sphere moved by M after
    binning (all alike, so that many pairs reach across a face only by that move), and
    every sphere touched (each pair is then examined once, from its lower id). Leaving
    M out of the reach fails this test."""
    import taichi as ti

    scene = _overlapping_scene(3000, periodic, seed=4, poly=poly)
    sim = ts.Simulation(scene, arch=arch, precision=precision,
                        tuning=DEFAULT.with_(prune_walks=prune))
    h = (60 if poly else 20) * sim.max_step()
    sim.debug_view().params.h[None] = h
    sim.debug_view().motion.drift()
    sim.debug_view().grid.build()
    moved = 0.9 * sim.geometry.slack
    x = sim.debug_view().state.positions() + moved * np.array([0.6, -0.48, 0.64])
    sim.debug_view().state.load(x, sim.debug_view().state.velocities(), scene.radius, scene.mass)
    c = sim.debug_view().contacts

    @ti.kernel
    def walk_around_all() -> ti.i32:
        c.reset_detection_state()
        c.params.moved[None] = ti.cast(moved, c.real)
        for i in range(c.n):
            c.grid.refresh(i)
            c.mark_touched(i)
        c.detect_around_touched(False)
        c.clear_marks(False)
        return c.params.remaining[None]

    found = walk_around_all()
    st = sim.state()
    ref = brute_force_overlaps(st, scene.box_lo, scene.box_hi, scene.periodic,
                               c.approach_eps, h)
    assert len(ref) > 10, "the set-up must produce overlaps to compare"
    assert found == len(ref)
    assert c.active.to_numpy().sum() == len(ref)


@pytest.mark.parametrize("dims,periodic", [
    ((4, 4, 4), (True, True, True)),
    ((5, 3, 7), (True, True, True)),      # odd periodic counts: a third colour
    ((5, 2, 1), (False, False, False)),
    ((6, 3, 4), (False, True, False)),
])
def test_colours_partition_adjacent_cell_pairs(dims, periodic):
    """Every pair of equal-or-adjacent cells is owned by exactly one (owner, block pair),
    and owner cells of one colour have disjoint 2x2x2 blocks."""
    geom = GridGeometry(lo=(0, 0, 0), cell=(1, 1, 1), dims=dims, periodic=periodic, slack=0)

    def wrap(c):
        out = []
        for a in range(3):
            k = c[a]
            if periodic[a]:
                k %= dims[a]
            elif not 0 <= k < dims[a]:
                return None
            out.append(k)
        return tuple(out)

    cells = list(itertools.product(*(range(n) for n in dims)))
    owned = {}
    for c in cells:
        for a_off, b_off in BLOCK_PAIRS:
            a = wrap(tuple(ci + o for ci, o in zip(c, a_off)))
            b = wrap(tuple(ci + o for ci, o in zip(c, b_off)))
            if a is None or b is None:
                continue
            key = frozenset((a, b))
            owned.setdefault(key, []).append(c)
    adjacent = set()
    for c in cells:
        for off in itertools.product((-1, 0, 1), repeat=3):
            d = wrap(tuple(ci + o for ci, o in zip(c, off)))
            if d is not None:
                adjacent.add(frozenset((c, d)))
    assert set(owned) == adjacent
    assert all(len(v) == 1 for v in owned.values())
    # colours: each cell has exactly one; blocks of one colour are disjoint
    seen = []
    for colour in geom.colours:
        members = geom.colour_cells(colour)
        seen += members
        touched = set()
        for c in members:
            block = {wrap(tuple(ci + o for ci, o in zip(c, off)))
                     for off in itertools.product((0, 1), repeat=3)} - {None}
            assert not (block & touched), f"colour {colour}: cell {c} shares a block cell"
            touched |= block
    assert sorted(seen) == sorted(cells)


@pytest.mark.parametrize("periodic", [True, False])
def test_compiled_colour_loops_touch_each_sphere_once(arch, periodic):
    """On the compiled kernels: for every colour, each sphere lies in the block of at
    most one owner cell of that colour, and every sphere is in some block."""
    sim = ts.Simulation(gas(600, packing=0.3, periodic=periodic, gravity=(0, 0, 0)), arch=arch)
    sim.debug_view().grid.build()
    total = np.zeros(sim.n, dtype=np.int64)
    for k in range(len(sim.debug_view().contacts.colours)):
        touches = sim.debug_view().contacts.block_touches(k)
        assert touches.max() <= 1, f"colour {k}: a sphere is in two blocks"
        total += touches
    assert total.min() >= 1


@pytest.mark.parametrize("parallel", [False, True])
def test_grid_order_is_sorted_and_complete(arch, parallel):
    """Both ways of building (on the CPU below 200,000 spheres a serial scatter in id
    order that also copies the positions; else a parallel scatter, a sort of each cell
    and a copy) give cells sorted by id, each sphere's slot, and its position in xs."""
    tuning = DEFAULT.with_(serial_light_below=0) if parallel else DEFAULT
    sim = ts.Simulation(gas(500, periodic=False, gravity=(0, 0, 0)), arch=arch, tuning=tuning)
    assert sim.debug_view().grid.serial_light == (sim.runtime.is_cpu and not parallel)
    sim.debug_view().grid.build()
    n = sim.n      # (the fields may have room for more spheres and cells)
    start = sim.debug_view().grid.start.to_numpy()[:sim.debug_view().grid.m + 1]
    order = sim.debug_view().grid.order.to_numpy()[:n]
    cell_of = sim.debug_view().grid.cell_of.to_numpy()[:n]
    assert sorted(order.tolist()) == list(range(n))
    for c in range(sim.debug_view().grid.m):
        ids = order[start[c]:start[c + 1]]
        assert np.all(np.diff(ids) > 0), "ids inside a cell must be sorted"
        assert np.all(cell_of[ids] == c)
    np.testing.assert_array_equal(sim.debug_view().grid.slot.to_numpy()[order], np.arange(n))
    view = sim.debug_view()
    np.testing.assert_array_equal(view.grid.xs.to_numpy()[:n], view.state.x.to_numpy()[order])


def test_scan_over_many_blocks(arch):
    """More cells than one scan block: the multi-level scan still gives exact starts."""
    scene = gas(3000, packing=0.05, periodic=True, gravity=(0, 0, 0))
    sim = ts.Simulation(scene, arch=arch)
    assert sim.debug_view().grid.m > 1024 and len(sim.debug_view().grid.scan_sizes) >= 2
    sim.debug_view().grid.build()
    start = sim.debug_view().grid.start.to_numpy()[:sim.debug_view().grid.m + 1]
    counts = np.bincount(sim.debug_view().grid.cell_of.to_numpy()[:sim.n], minlength=sim.debug_view().grid.m)
    np.testing.assert_array_equal(start, np.concatenate([[0], np.cumsum(counts)]))


def test_row_stencils_cover_the_half_and_full_stencils():
    from taichi_spheres.grid import ALL_ROWS, FORWARD_ROWS

    def cells(rows):
        return sorted((dx, dy, dz) for dx, dy, lo, hi in rows for dz in range(lo, hi + 1))

    half = [(0, 0, 0)] + [o for o in itertools.product((-1, 0, 1), repeat=3) if o > (0, 0, 0)]
    assert cells(FORWARD_ROWS) == sorted(half)
    # every unordered neighbour pair is seen once: o or -o, never both
    assert all(tuple(-c for c in o) not in half for o in half if o != (0, 0, 0))
    assert cells(ALL_ROWS) == sorted(itertools.product((-1, 0, 1), repeat=3))


def test_cell_size_rules():
    """Cells: at least 2 r_max + 4 x (step_fraction r_min) where the box allows it (a
    collision carried forward can move a sphere by twice a step's largest move), down
    to 2 r_max + 2 x that on a short periodic axis; at most about max_cells_per_sphere
    cells per sphere in dilute scenes; with fewer, larger cells the margin (slack) is
    what the cells leave beyond a diameter."""
    MAX_CELLS_PER_SPHERE = DEFAULT.performance.max_cells_per_sphere
    r, f = 0.5, 0.1
    dense = GridGeometry.for_box((0, 0, 0), (60, 60, 60), (True,) * 3, r, r, 200_000, f)
    assert min(dense.cell) >= 2 * r + 4 * f * r
    assert dense.slack == pytest.approx(0.5 * (min(dense.cell) - 2 * r))
    # a pile-like box: 1e4 spheres of r = 0.015 in 3.2 x 3.2 x 1 m
    dilute = GridGeometry.for_box((0, 0, 0), (3.2, 3.2, 1.0), (False,) * 3, 0.015, 0.015,
                                  10_000, f)
    assert dilute.n_cells <= 1.5 * MAX_CELLS_PER_SPHERE * 10_000
    assert dilute.n_cells >= 0.5 * MAX_CELLS_PER_SPHERE * 10_000
    # 3.4 m periodic: 3 cells of 1.1 (2 r + 2 f r) fit, 3 of 1.2 would not
    short = GridGeometry.for_box((0, 0, 0), (3.4, 3.4, 3.4), (True,) * 3, r, r, 20, f)
    assert short.dims == (3, 3, 3)
    with pytest.raises(ValueError, match="periodic axis x"):
        GridGeometry.for_box((0, 0, 0), (3.2, 3.4, 3.4), (True,) * 3, r, r, 20, f)


def _runs_with_and_without_near_lists(scene, arch, duration, capacities=(None,)):
    """(state, stats) of ``scene`` advanced by ``duration`` [s] with near lists (one run
    per list capacity, None: the default), then without (every detection scans)."""
    runs = []
    for capacity in capacities + ("scan",):
        tuning = DEFAULT
        if capacity == "scan":
            tuning = DEFAULT.with_(near_lists_from=scene.n + 1)
        elif capacity is not None:
            tuning = DEFAULT.with_(near_capacity=capacity)
        sim = ts.Simulation(scene, arch=arch, tuning=tuning)
        sim.advance(duration)
        runs.append((sim.state(), sim.stats))
    return runs


def _assert_same_run(a, b):
    (sa, ta), (sb, tb) = a, b
    np.testing.assert_array_equal(sa.x, sb.x)
    np.testing.assert_array_equal(sa.v, sb.v)
    for key in ("steps", "pair_collisions", "wall_collisions", "sweeps", "unresolved",
                "grid_rebuilds", "projected_pairs"):
        assert ta[key] == tb[key], key


def test_near_lists_give_the_scan_bits_in_a_gas(arch):
    """Detections from near lists (Contacts.detect) find what the full grid scan finds:
    an elastic periodic gas runs to the same bits and counts with and without them.
    Lists serve most steps, longer than the two steps for which no sphere outruns
    their allowance, so the spheres that did are scanned around (the fast-mover
    path); lists that overflow their capacity are not used (and change nothing)."""
    scene = gas(3500, packing=0.3, seed=5)
    lists, overflowing, scan = _runs_with_and_without_near_lists(
        scene, arch, 1.0, capacities=(None, 1))
    steps = scan[1]["steps"]
    assert steps > 50 and scan[1]["pair_collisions"] > 5 * scene.n
    assert scan[1]["near_list_detections"] == 0
    assert overflowing[1]["near_list_detections"] == 0
    assert lists[1]["near_list_detections"] > 0.6 * steps
    _assert_same_run(lists, scan)
    _assert_same_run(overflowing, scan)


def test_near_lists_give_the_scan_bits_with_walls_and_gravity(arch):
    """The same with walls, gravity, inelastic pairs and walls and radii (and so masses)
    spread over a factor 2: the lists' reach is set by the largest sphere, and the
    orientation of a pair found from a list or around a fast mover is the scan's."""
    scene = gas(3500, packing=0.2, periodic=(False, True, False), gravity=(0, 0, -9.81),
                restitution=0.7, wall_restitution=0.8, polydispersity=0.5, seed=6)
    lists, scan = _runs_with_and_without_near_lists(scene, arch, 0.5)
    assert lists[1]["near_list_detections"] > 0
    assert scan[1]["wall_collisions"] > 0 and scan[1]["pair_collisions"] > scene.n
    _assert_same_run(lists, scan)


def test_recorded_pairs_resolve_as_the_block_search(arch, precision):
    """A cell that detection found two pairs for resolves them from its record
    (Contacts.earliest_recorded) as searching its block does (recorded_pairs = 1 sends
    every such cell to earliest_in_block): the same collisions, earliest first, in a
    dense elastic gas where such cells are common, to the bit (a recorded pair keeps
    the order the forward scan met its spheres in, which is the block's order)."""
    scene = gas(3500, packing=0.4, seed=7)
    probe = ts.Simulation(scene, arch=arch, precision=precision)
    probe.debug_view().params.h[None] = probe.max_step()
    probe.debug_view().motion.drift()
    probe.debug_view().grid.build()
    probe.debug_view().contacts.detect_all()
    assert np.count_nonzero(probe.debug_view().contacts.active.to_numpy() == 2) > 10
    runs = []
    for recorded in (2, 1):
        sim = ts.Simulation(scene, arch=arch, precision=precision,
                            tuning=DEFAULT.with_(recorded_pairs=recorded))
        for _ in range(10):
            sim.step(sim.max_step())
        runs.append((sim.state(), sim.stats))
    assert runs[0][1]["pair_collisions"] > scene.n
    _assert_same_run(*runs)
