"""Input validation: Scene.from_arrays, the cell-list overlap check and TOML scene files.

Pure numpy: nothing here calls ti.init or builds a Simulation.
"""
import math
import re
import textwrap

import numpy as np
import pytest

import taichi_spheres as ts
from taichi_spheres.scene import TOUCH_TOLERANCE, find_first_overlap
from taichi_spheres.scenefile import SceneFileError, scene_from_dict

UNIT = ((0.0, 0.0, 0.0), (1.0, 1.0, 1.0))


def grid_positions(n, r=0.05):
    """n well separated centres inside the unit box (spacing 0.2, radius r)."""
    pts = [(0.1 + 0.2 * i, 0.1 + 0.2 * j, 0.1 + 0.2 * k)
           for i in range(5) for j in range(5) for k in range(5)]
    assert n <= len(pts)
    return np.array(pts[:n]), np.full(n, r)


def make(x=None, v=None, radius=None, n=10, **kw):
    gx, gr = grid_positions(n)
    x = gx if x is None else x
    v = np.zeros((len(x), 3)) if v is None else v
    radius = gr if radius is None else radius
    return ts.Scene.from_arrays(x, v, radius, **kw)


def brute_first_overlap(x, radius, lo, hi, periodic, tolerance=TOUCH_TOLERANCE):
    """O(N^2) reference for find_first_overlap: lowest (i, j), i < j, or (-1, -1, nan)."""
    size = np.asarray(hi, float) - np.asarray(lo, float)
    d = x[:, None, :] - x[None, :, :]
    for a in range(3):
        if periodic[a]:
            d[..., a] -= size[a] * np.round(d[..., a] / size[a])
    dist = np.sqrt((d * d).sum(axis=-1))
    sigma = (radius[:, None] + radius[None, :]) * (1.0 - tolerance)
    hit = (dist < sigma) & np.triu(np.ones(dist.shape, dtype=bool), k=1)
    ii, jj = np.nonzero(hit)  # row-major: already sorted by (i, j)
    if ii.size == 0:
        return -1, -1, float("nan")
    return int(ii[0]), int(jj[0]), float(dist[ii[0], jj[0]])


def min_image_overlaps(scene):
    return brute_first_overlap(scene.x, scene.radius, scene.box_lo, scene.box_hi,
                               scene.periodic)


# --------------------------------------------------------------------------- valid input

def test_valid_scene_fields_and_default_density():
    s = make(n=5, gravity=(0.0, 0.0, -1.0), restitution=0.5, wall_restitution=0.25)
    assert s.n == 5
    assert s.x.shape == (5, 3) and s.v.shape == (5, 3) and s.radius.shape == (5,)
    np.testing.assert_allclose(s.mass, 1000.0 * 4.0 / 3.0 * math.pi * 0.05 ** 3, rtol=1e-15)
    np.testing.assert_array_equal(s.box_size, [1.0, 1.0, 1.0])
    assert s.periodic == (False, False, False)
    assert s.restitution == 0.5 and s.wall_restitution == 0.25
    np.testing.assert_array_equal(s.gravity, [0.0, 0.0, -1.0])


def test_scalar_mass_density_and_periodic_bool_are_broadcast():
    s = make(n=4, mass=2.0, periodic=True)
    np.testing.assert_array_equal(s.mass, [2.0] * 4)
    assert s.periodic == (True, True, True)
    s = make(n=4, density=[1.0, 2.0, 3.0, 4.0])
    np.testing.assert_allclose(s.mass / (4.0 / 3.0 * math.pi * 0.05 ** 3), [1, 2, 3, 4])


def test_inputs_are_copied():
    x, r = grid_positions(3)
    s = ts.Scene.from_arrays(x, np.zeros((3, 3)), r)
    x[0] = 99.0
    assert s.x[0, 0] == pytest.approx(0.1)


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_exactly_touching_spheres_are_accepted(axis):
    x = np.full((2, 3), 0.5)
    x[0, axis], x[1, axis] = 0.3, 0.5          # 0.5 - 0.3 = 0.19999999999999998 in binary
    s = ts.Scene.from_arrays(x, np.zeros((2, 3)), 0.1)
    assert s.n == 2


def test_touching_polydisperse_pair_is_accepted():
    x = [[0.5, 0.5, 0.2], [0.5, 0.5, 0.5]]     # 0.3 apart, radii 0.1 + 0.2
    assert ts.Scene.from_arrays(x, np.zeros((2, 3)), [0.1, 0.2]).n == 2


def test_spheres_touching_the_walls_are_accepted():
    # 0.2 + 0.1 = 0.30000000000000004 > 0.3 in binary: still a touching sphere
    s = ts.Scene.from_arrays([[0.2, 0.1, 0.2]], [[0, 0, 0]], 0.1,
                             box=((0, 0, 0), (0.3, 0.3, 0.3)))
    assert s.n == 1
    s = ts.Scene.from_arrays([[0.1, 0.1, 0.9]], [[0, 0, 0]], 0.1)
    assert s.n == 1


def test_touching_across_periodic_boundary_is_accepted():
    x = [[0.05, 0.5, 0.5], [0.85, 0.5, 0.5]]     # image distance 0.2 == 2 r
    s = ts.Scene.from_arrays(x, np.zeros((2, 3)), 0.1, periodic=(True, False, False))
    assert s.n == 2


def test_periodic_axis_allows_sphere_to_straddle_the_face():
    s = ts.Scene.from_arrays([[0.0, 0.5, 0.5]], [[0, 0, 0]], 0.1, periodic=(True, False, False))
    assert s.n == 1


@pytest.mark.parametrize("e", [0.0, 1.0, 0.5])
def test_restitution_bounds_are_inclusive(e):
    s = make(n=2, restitution=e, wall_restitution=e)
    assert s.restitution == e and s.wall_restitution == e


# --------------------------------------------------------------------------- non-finite values

@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize("name", ["x", "v"])
def test_non_finite_positions_and_velocities_name_the_sphere(name, bad):
    x, r = grid_positions(6)
    v = np.zeros((6, 3))
    arr = x if name == "x" else v
    arr[4, 1] = bad
    with pytest.raises(ValueError, match=rf"^{name} of sphere 4 is not finite"):
        ts.Scene.from_arrays(x, v, r)


@pytest.mark.parametrize("bad", [np.nan, np.inf])
@pytest.mark.parametrize("name", ["radius", "mass", "density"])
def test_non_finite_per_sphere_values_name_the_sphere(name, bad):
    values = np.full(6, 0.05 if name == "radius" else 1.0)
    values[3] = bad
    values[5] = bad
    with pytest.raises(ValueError, match=rf"^{name} of sphere 3 is not finite.*and 1 more"):
        make(n=6, **{name: values})


def test_mass_overflowing_from_density_is_rejected():
    with pytest.raises(ValueError, match=r"mass \(from density\) of sphere 0 is not finite"):
        make(n=2, density=1e308, radius=[1.0, 1.0],
             x=[[2.0, 2.0, 2.0], [5.0, 5.0, 5.0]], box=((0, 0, 0), (10, 10, 10)))


# --------------------------------------------------------------------------- sign checks

@pytest.mark.parametrize("value", [0.0, -0.05])
def test_non_positive_radius_names_the_sphere(value):
    r = np.full(8, 0.05)
    r[6] = value
    with pytest.raises(ValueError, match=r"^radius of sphere 6 must be > 0"):
        make(n=8, radius=r)


@pytest.mark.parametrize("name", ["mass", "density"])
@pytest.mark.parametrize("value", [0.0, -1.0])
def test_non_positive_mass_or_density_names_the_sphere(name, value):
    m = np.ones(8)
    m[2] = value
    with pytest.raises(ValueError, match=rf"^{name} of sphere 2 must be > 0"):
        make(n=8, **{name: m})


def test_mass_and_density_together_are_rejected():
    with pytest.raises(ValueError, match="mass or density, not both"):
        make(n=2, mass=1.0, density=1.0)


def test_density_so_small_that_mass_is_zero_is_rejected():
    with pytest.raises(ValueError, match=r"mass \(from density\) of sphere 0 must be > 0"):
        make(n=2, density=5e-324)


# --------------------------------------------------------------------------- overlaps

def test_overlap_names_both_indices():
    x, r = grid_positions(10)
    x[7] = x[3] + [0.05, 0.0, 0.0]
    with pytest.raises(ValueError, match=r"^spheres 3 and 7 overlap: distance"):
        ts.Scene.from_arrays(x, np.zeros((10, 3)), r)


def test_overlap_reports_the_lowest_index_pair():
    x, r = grid_positions(12)
    x[9] = x[8] + [0.01, 0.0, 0.0]
    x[11] = x[2] + [0.0, 0.05, 0.0]
    x[10] = x[2] + [0.0, 0.0, 0.07]
    with pytest.raises(ValueError, match=r"^spheres 2 and 10 overlap"):
        ts.Scene.from_arrays(x, np.zeros((12, 3)), r)


def test_coincident_centres_are_named():
    x, r = grid_positions(6)
    x[4] = x[1]
    with pytest.raises(ValueError, match=r"^spheres 1 and 4 have coincident centres"):
        ts.Scene.from_arrays(x, np.zeros((6, 3)), r)


def test_barely_overlapping_pair_is_rejected():
    x = [[0.5, 0.5, 0.3], [0.5, 0.5, 0.5 - 1e-6]]
    with pytest.raises(ValueError, match=r"spheres 0 and 1 overlap"):
        ts.Scene.from_arrays(x, np.zeros((2, 3)), 0.1)


def test_polydisperse_overlap_is_detected():
    # small sphere far from the big one's cell-mate neighbours still reaches it
    x = [[0.5, 0.5, 0.5], [0.5, 0.5, 0.5 + 0.3 + 0.045], [0.1, 0.1, 0.1]]
    with pytest.raises(ValueError, match=r"spheres 0 and 1 overlap"):
        ts.Scene.from_arrays(x, np.zeros((3, 3)), [0.3, 0.05, 0.05])


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_periodic_overlap_across_the_boundary_is_detected(axis):
    x = np.full((3, 3), 0.5)
    x[2, axis] = 0.25
    x[0, axis], x[1, axis] = 0.98, 0.01            # image distance 0.03 < 0.06
    periodic = [False] * 3
    periodic[axis] = True
    with pytest.raises(ValueError, match=r"^spheres 0 and 1 overlap"):
        ts.Scene.from_arrays(x, np.zeros((3, 3)), 0.03, periodic=periodic)
    # on a wall axis the same pair is 0.97 apart: it is the walls that complain, not overlap
    with pytest.raises(ValueError, match=r"^sphere 0 .* outside the walls"):
        ts.Scene.from_arrays(x, np.zeros((3, 3)), 0.03)


def test_periodic_corner_overlap_is_detected():
    x = [[0.99, 0.99, 0.99], [0.5, 0.5, 0.5], [0.01, 0.01, 0.01]]
    with pytest.raises(ValueError, match=r"^spheres 0 and 2 overlap"):
        ts.Scene.from_arrays(x, np.zeros((3, 3)), 0.03, periodic=True)


# --------------------------------------------------------------------------- box containment

@pytest.mark.parametrize("axis", [0, 1, 2])
@pytest.mark.parametrize("side", ["lo", "hi"])
def test_sphere_through_a_wall_names_sphere_and_axis(axis, side):
    x, r = grid_positions(6)
    x[5, axis] = 0.04 if side == "lo" else 0.96     # radius 0.05
    with pytest.raises(ValueError, match=rf"^sphere 5 .*outside the walls .* on axis {'xyz'[axis]}"):
        ts.Scene.from_arrays(x, np.zeros((6, 3)), r)


def test_sphere_entirely_outside_is_rejected_with_count_of_others():
    x, r = grid_positions(6)
    x[2] = [2.0, 2.0, 2.0]
    x[4] = [-1.0, 0.5, 0.5]
    with pytest.raises(ValueError, match=r"^sphere 2 .*outside.*and 1 more"):
        ts.Scene.from_arrays(x, np.zeros((6, 3)), r)


@pytest.mark.parametrize("coord, ok", [(0.0, True), (0.999999, True), (1.0, False),
                                       (-1e-9, False), (1.5, False)])
def test_periodic_axis_needs_centre_in_half_open_box(coord, ok):
    x = [[0.5, 0.5, 0.5], [coord, 0.5, 0.2]]
    args = (x, np.zeros((2, 3)), 0.05)
    if ok:
        assert ts.Scene.from_arrays(*args, periodic=(True, False, False)).n == 2
    else:
        with pytest.raises(ValueError, match=r"^sphere 1 .*outside \[0.0, 1.0\) on periodic axis x"):
            ts.Scene.from_arrays(*args, periodic=(True, False, False))


def test_shifted_box_is_respected():
    box = ((-2.0, 10.0, 0.0), (-1.0, 11.0, 1.0))
    s = ts.Scene.from_arrays([[-1.5, 10.5, 0.5]], [[0, 0, 0]], 0.1, box=box)
    np.testing.assert_array_equal(s.box_lo, [-2.0, 10.0, 0.0])
    with pytest.raises(ValueError, match=r"^sphere 0 .*outside the walls -2.0 .. -1.0 on axis x"):
        ts.Scene.from_arrays([[0.5, 10.5, 0.5]], [[0, 0, 0]], 0.1, box=box)


# --------------------------------------------------------------------------- scalar arguments

@pytest.mark.parametrize("name", ["restitution", "wall_restitution"])
@pytest.mark.parametrize("value", [-0.01, 1.01, float("nan"), float("inf")])
def test_restitution_out_of_range(name, value):
    with pytest.raises(ValueError, match=rf"^{name} must be in \[0, 1\]"):
        make(n=2, **{name: value})


@pytest.mark.parametrize("name", ["restitution", "wall_restitution"])
def test_restitution_not_a_number(name):
    with pytest.raises(ValueError, match=rf"^{name} must be a number"):
        make(n=2, **{name: None})


@pytest.mark.parametrize("gravity", [(0, 0), (0, 0, float("nan")), None, "down"])
def test_bad_gravity(gravity):
    with pytest.raises(ValueError, match=r"^gravity must be three"):
        make(n=2, gravity=gravity)


# --------------------------------------------------------------------------- shapes

@pytest.mark.parametrize("x, pattern", [
    (np.zeros((3, 2)), r"x must have shape \(N, 3\)"),
    (np.zeros((3, 4)), r"x must have shape \(N, 3\)"),
    (np.zeros(3), r"x must be a 2-d array"),
    (np.zeros((2, 3, 1)), r"x must be a 2-d array"),
    (np.zeros((0, 3)), r"x: a scene needs at least one sphere"),
    ([[0.5, 0.5, "a"]], r"x: not numeric"),
    ([[0.5, 0.5], [0.5, 0.5, 0.5]], r"x: not numeric"),
])
def test_bad_x_shape(x, pattern):
    with pytest.raises(ValueError, match=pattern):
        ts.Scene.from_arrays(x, np.zeros((3, 3)), 0.05)


@pytest.mark.parametrize("v", [np.zeros((2, 3)), np.zeros((3, 2)), np.zeros(9), np.zeros((3, 3, 1))])
def test_bad_v_shape(v):
    x, r = grid_positions(3)
    with pytest.raises(ValueError, match=r"^v must (have shape \(3, 3\)|be a 2-d array)"):
        ts.Scene.from_arrays(x, v, r)


@pytest.mark.parametrize("name", ["radius", "mass", "density"])
@pytest.mark.parametrize("shape", [(2,), (4,), (3, 1), (1, 3)])
def test_bad_per_sphere_shape(name, shape):
    x, _ = grid_positions(3)
    kw = {"radius": 0.05, name: np.full(shape, 0.05)}
    with pytest.raises(ValueError, match=rf"^{name} must be a scalar or have shape \(3,\)"):
        ts.Scene.from_arrays(x, np.zeros((3, 3)), **kw)


# --------------------------------------------------------------------------- box and periodic

@pytest.mark.parametrize("axis", [0, 1, 2])
@pytest.mark.parametrize("hi_value", [0.0, -1.0])
def test_box_hi_must_exceed_lo(axis, hi_value):
    hi = [1.0, 1.0, 1.0]
    hi[axis] = hi_value
    with pytest.raises(ValueError, match=rf"^box: upper corner must exceed lower corner on axis {'xyz'[axis]}"):
        make(n=1, box=((0, 0, 0), hi))


@pytest.mark.parametrize("box, pattern", [
    (None, r"^box must be \(\(xlo"),
    (((0, 0, 0),), r"^box must be \(\(xlo"),
    (((0, 0, 0), (1, 1, 1), (2, 2, 2)), r"^box must be \(\(xlo"),
    (((0, 0), (1, 1)), r"^box lower corner must be three"),
    (((0, 0, 0), (1, 1, float("nan"))), r"^box upper corner must be three finite"),
    (((0, 0, 0), (1, 1, float("inf"))), r"^box upper corner must be three finite"),
    (((-1e308, 0, 0), (1e308, 1, 1)), r"^box: size .* is not finite"),
])
def test_bad_box(box, pattern):
    with pytest.raises(ValueError, match=pattern):
        make(n=1, box=box)


@pytest.mark.parametrize("periodic", [None, (True, False), (True, False, False, True),
                                      (1, 0, 0), "abc", ("yes", "no", "no"), 1])
def test_bad_periodic(periodic):
    with pytest.raises(ValueError, match=r"^periodic must be a bool or three bools"):
        make(n=1, periodic=periodic)


def test_replace_revalidates():
    s = make(n=3)
    with pytest.raises(ValueError, match=r"^restitution must be in"):
        s.replace(restitution=2.0)
    x = s.x.copy()
    x[2] = x[0]
    with pytest.raises(ValueError, match=r"spheres 0 and 2 have coincident centres"):
        s.replace(x=x)
    assert s.replace(density=2000.0).mass[0] == pytest.approx(2 * s.mass[0])


# --------------------------------------------------------------------------- cell list vs brute force

def _random_config(seed, periodic, n_target, mode):
    """Polydisperse (radius ratio 10) non-overlapping spheres by random sequential
    addition; mode 'one' then moves one sphere onto another (possibly across a
    periodic face), mode 'many' adds loose random spheres on top."""
    rng = np.random.default_rng(seed)
    rmax = 0.08
    lo = rng.uniform(-1.0, 1.0, 3)
    size = 2 * rmax * rng.uniform(1.5, 8.0, 3)     # 1 .. 8 cells per axis
    hi = lo + size
    xs, rs = [], []
    for k in range(6 * n_target):
        if len(xs) >= n_target:
            break
        r = rmax if k == 0 else rng.uniform(rmax / 10, rmax)
        p = lo + rng.random(3) * size
        for a in range(3):
            if not periodic[a]:
                p[a] = lo[a] + r + rng.random() * (size[a] - 2 * r)
        if xs:
            d = np.array(xs) - p
            for a in range(3):
                if periodic[a]:
                    d[:, a] -= size[a] * np.round(d[:, a] / size[a])
            if (np.sqrt((d * d).sum(1)) < np.array(rs) + r).any():
                continue
        xs.append(p)
        rs.append(r)
    x, r = np.array(xs), np.array(rs)
    n = len(x)
    if mode == "one":
        i, j = rng.choice(n, 2, replace=False)
        u = rng.normal(size=3)
        x[j] = x[i] + u / np.linalg.norm(u) * (r[i] + r[j]) * rng.uniform(0.3, 0.99)
        for a in range(3):
            if periodic[a]:
                x[j, a] = lo[a] + (x[j, a] - lo[a]) % size[a]
            else:
                x[j, a] = np.clip(x[j, a], lo[a] + r[j], hi[a] - r[j])
    elif mode == "many":
        extra = 5
        r = np.concatenate([r, rng.uniform(rmax / 10, rmax, extra)])
        new = lo + rng.random((extra, 3)) * size
        for a in range(3):
            if not periodic[a]:
                new[:, a] = np.clip(new[:, a], lo[a] + r[n:], hi[a] - r[n:])
        x = np.concatenate([x, new])
        perm = rng.permutation(len(x))
        x, r = x[perm], r[perm]
    return x, r, lo, hi


PERIODICITIES = [(False, False, False), (True, True, True), (True, False, False),
                 (False, True, True)]


@pytest.mark.parametrize("periodic", PERIODICITIES)
@pytest.mark.parametrize("mode", ["none", "one", "many"])
def test_cell_list_matches_brute_force(periodic, mode):
    found = 0
    for seed in range(8):
        x, r, lo, hi = _random_config(1000 * seed + 7, periodic, 60, mode)
        got = find_first_overlap(x, r, lo, hi, periodic)
        want = brute_first_overlap(x, r, lo, hi, periodic)
        assert got[:2] == want[:2], (seed, got, want)
        if want[0] < 0:
            assert math.isnan(got[2])
            assert mode != "one"
        else:
            assert got[0] < got[1]
            assert got[2] == pytest.approx(want[2], rel=1e-12)
            found += 1
    if mode == "none":
        assert found == 0
    else:
        assert found >= 6     # the configurations really exercise the overlap path


def test_cell_list_many_spheres_in_one_cell():
    # a cluster of many overlapping small spheres plus one large: every cell pair visited
    rng = np.random.default_rng(3)
    x = np.concatenate([rng.uniform(0.4, 0.6, (40, 3)), [[0.1, 0.1, 0.1]]])
    r = np.concatenate([np.full(40, 0.01), [0.1]])
    for periodic in PERIODICITIES:
        got = find_first_overlap(x, r, np.zeros(3), np.ones(3), periodic)
        want = brute_first_overlap(x, r, np.zeros(3), np.ones(3), periodic)
        assert got[:2] == want[:2]


def test_cell_list_single_sphere_and_no_overlap():
    i, j, d = find_first_overlap(np.array([[0.5, 0.5, 0.5]]), np.array([0.1]),
                                 np.zeros(3), np.ones(3), (False,) * 3)
    assert (i, j) == (-1, -1) and math.isnan(d)
    x, r = grid_positions(125, r=0.1)             # a touching simple-cubic lattice
    for periodic in PERIODICITIES:
        i, j, d = find_first_overlap(x, r, np.zeros(3), np.ones(3), periodic)
        assert (i, j) == (-1, -1) and math.isnan(d)


# =========================================================================== scene files

GOOD = """
name = "demo"

[box]
lo = [0.0, 0.0, 0.0]
hi = [1.0, 1.0, 2.0]
periodic = [true, true, false]
wall_restitution = 0.9

[physics]
gravity = [0.0, 0.0, -9.81]
restitution = 0.8
precision = "f64"

[run]
duration = 2.5
fps = 30

[[spheres]]
x = [0.5, 0.5, 1.5]
v = [1.0, 0.0, 0.0]
radius = 0.1
mass = 2.0

[[spheres]]
x = [0.5, 0.5, 1.2]
radius = 0.05
density = 500.0
"""


def write(tmp_path, text, name="scene.toml"):
    p = tmp_path / name
    p.write_text(textwrap.dedent(text))
    return p


def load_problems(tmp_path, text):
    with pytest.raises(SceneFileError) as info:
        ts.load_scene(write(tmp_path, text))
    assert isinstance(info.value, ValueError)
    return info.value.problems, str(info.value)


def test_good_scene_file(tmp_path):
    s = ts.load_scene(write(tmp_path, GOOD))
    assert s.n == 2 and s.name == "demo"
    np.testing.assert_array_equal(s.box_hi, [1.0, 1.0, 2.0])
    assert s.periodic == (True, True, False)
    assert s.restitution == 0.8 and s.wall_restitution == 0.9
    np.testing.assert_array_equal(s.v[0], [1.0, 0.0, 0.0])
    np.testing.assert_array_equal(s.v[1], [0.0, 0.0, 0.0])
    assert s.mass[0] == 2.0
    assert s.mass[1] == pytest.approx(500.0 * 4.0 / 3.0 * math.pi * 0.05 ** 3)
    assert s.meta["run"] == {"duration": 2.5, "fps": 30}
    assert s.meta["physics"]["precision"] == "f64"
    assert s.meta["source"].endswith("scene.toml")


def test_unknown_top_level_key(tmp_path):
    problems, msg = load_problems(tmp_path, 'bogus = 1\n' + GOOD)
    assert problems == ["unknown key 'bogus' (valid: box, cone, cylinder, initial, lattice, "
                        "material, material_pair, name, output, physics, plane, pour, "
                        "random, render, run, sink, spheres, tuning)"]


def test_tuning_table_sets_the_simulations_options(tmp_path, arch):
    """[tuning] names Rules and Performance fields; a Simulation of the scene takes
    them unless it is given tuning=."""
    from taichi_spheres.config import DEFAULT
    scene = ts.load_scene(write(tmp_path, GOOD + "\n[tuning]\nrelaxation = 1.8\n"
                                "contact_iterations = 40\nshock_propagation = \"on\"\n"
                                "warm_start = true\n"))
    assert scene.meta["tuning"] == dict(relaxation=1.8, contact_iterations=40,
                                        shock_propagation="on", warm_start=True)
    from taichi_spheres.runtime import default_precision
    precision = default_precision(arch)     # (the scene asks for f64: not on every arch)
    sim = ts.Simulation(scene, arch=arch, precision=precision)
    assert sim.tuning == DEFAULT.with_(relaxation=1.8, contact_iterations=40,
                                       shock_propagation="on")
    assert ts.Simulation(scene, arch=arch, precision=precision,
                         tuning=DEFAULT).tuning == DEFAULT
    assert "tuning" not in ts.load_scene(write(tmp_path, GOOD)).meta


def test_physics_table_sets_the_simulations_run_settings(tmp_path, arch):
    """[physics] step_fraction, max_sweeps and precision reach a Simulation of the scene
    left without them, as they reach `taichi-spheres run`; arguments given win."""
    from taichi_spheres.simulation import (DEFAULT_MAX_SWEEPS, DEFAULT_STEP_FRACTION,
                                           scene_simulation_settings as settings)
    scene = ts.load_scene(write(tmp_path, GOOD.replace(
        'precision = "f64"', 'precision = "f64"\nstep_fraction = 0.15\nmax_sweeps = 8')))
    assert settings(scene) == (0.15, 8, "f64")
    assert settings(scene, 0.05, 4, "f32") == (0.05, 4, "f32")
    plain = ts.load_scene(write(tmp_path, GOOD.replace('precision = "f64"\n', "")))
    assert settings(plain) == (DEFAULT_STEP_FRACTION, DEFAULT_MAX_SWEEPS, None)
    chosen = ts.load_scene(write(tmp_path, GOOD.replace(
        'precision = "f64"', "step_fraction = 0.15\nmax_sweeps = 8")))
    sim = ts.Simulation(chosen, arch=arch)
    assert (sim.step_fraction, sim.max_sweeps) == (0.15, 8)
    sim = ts.Simulation(chosen, arch=arch, step_fraction=0.05, max_sweeps=4)
    assert (sim.step_fraction, sim.max_sweeps) == (0.05, 4)
    for bad in ("fast", "0.15", True, np.True_, b"0.1", 0.0, 1.5, float("nan")):
        with pytest.raises(ValueError, match=r"step_fraction must be a number in \(0, 1\]"):
            ts.Simulation(chosen, arch=arch, step_fraction=bad)


@pytest.mark.parametrize("line, problem", [
    ("relaxaton = 1.8", "unknown key 'tuning.relaxaton' (did you mean 'tuning.relaxation'?)"),
    ("contact_iterations = 4.5", "tuning.contact_iterations: must be an integer, got 4.5"),
    ("relaxation = 2.5", "tuning.relaxation must be in (0, 2), got 2.5"),
    ('shock_propagation = "always"', "tuning.shock_propagation must be one of auto, on, off, "
                                     "got 'always'"),
])
def test_bad_tuning_key_is_named(tmp_path, line, problem):
    problems, _ = load_problems(tmp_path, GOOD + "\n[tuning]\n" + line + "\n")
    assert problems == [problem]


def test_misspelt_top_level_key_gets_suggestion(tmp_path):
    problems, _ = load_problems(tmp_path, 'nmae = "x"\n' + GOOD.replace('name = "demo"', ""))
    assert problems == ["unknown key 'nmae' (did you mean 'name'?)"]


def test_top_level_key_that_belongs_in_a_table(tmp_path):
    problems, _ = load_problems(tmp_path, 'periodic = true\n' + GOOD)
    assert len(problems) == 1
    assert "unknown key 'periodic'" in problems[0]
    assert "did you mean 'box.periodic'?" in problems[0]


@pytest.mark.parametrize("old, new, key, hint", [
    ("periodic = [", "periodc = [", "box.periodc", "box.periodic"),
    ("wall_restitution", "wall_restituion", "box.wall_restituion", "box.wall_restitution"),
    ("gravity", "gravty", "physics.gravty", "physics.gravity"),
    ("fps", "fsp", "run.fsp", "run.fps"),
    ("density = 500.0", "densty = 500.0", "spheres[1].densty", "spheres[1].density"),
])
def test_unknown_nested_key_gets_nearest_name(tmp_path, old, new, key, hint):
    problems, msg = load_problems(tmp_path, GOOD.replace(old, new, 1))
    assert problems == [f"unknown key '{key}' (did you mean '{hint}'?)"]
    assert f"did you mean '{hint}'?" in msg


def test_unknown_key_without_near_match_lists_valid_keys(tmp_path):
    problems, _ = load_problems(tmp_path, GOOD.replace("mass = 2.0", "weight = 2.0"))
    assert problems == ["unknown key 'spheres[0].weight' (valid: colour, density, mass, "
                        "material, omega, radius, v, x)"]


def test_all_problems_reported_at_once(tmp_path):
    text = (GOOD.replace("periodic = [", "periodc = [")
            .replace("restitution = 0.8", "restitution = \"high\"")
            .replace("radius = 0.05\n", ""))
    problems, msg = load_problems(tmp_path, text)
    assert len(problems) == 3, problems
    assert "unknown key 'box.periodc' (did you mean 'box.periodic'?)" in problems
    assert "physics.restitution: must be a number, got 'high'" in problems
    assert "spheres[1]: missing 'radius'" in problems
    assert msg.count("\n  - ") == 3 and "3 problem(s)" in msg


def test_two_problems_reported_together(tmp_path):
    text = "colour = 1\n" + GOOD.replace("radius = 0.1", "radius = -0.1")
    problems, msg = load_problems(tmp_path, text)
    assert len(problems) == 2
    assert problems[0].startswith("unknown key 'colour'")
    assert problems[1] == "spheres[0].radius: must be > 0, got -0.1"
    assert "2 problem(s)" in msg


@pytest.mark.parametrize("old, new, expected", [
    ("radius = 0.1", 'radius = "big"', r"spheres\[0\]\.radius: must be a number, got 'big'"),
    ("lo = [0.0, 0.0, 0.0]", "lo = [0.0, 0.0]", r"box\.lo: must be 3 finite numbers"),
    ("hi = [1.0, 1.0, 2.0]", "hi = [1.0, 1.0, nan]", r"box\.hi: must be 3 finite numbers"),
    ("periodic = [true, true, false]", 'periodic = "yes"', r"box\.periodic: must be a bool or 3 bools"),
    ("periodic = [true, true, false]", "periodic = [1, 1, 0]", r"box\.periodic: must be a bool or 3 bools"),
    ('name = "demo"', "name = 3", r"name: must be a str, got 3"),
    ("radius = 0.1", "radius = true", r"spheres\[0\]\.radius: must be a number, got True"),
    ("fps = 30", 'fps = "30"', r"run\.fps: must be a number"),
    ('precision = "f64"', 'precision = "f16"', r"physics\.precision: must be \"f32\" or \"f64\""),
])
def test_wrong_type_is_named(tmp_path, old, new, expected):
    problems, msg = load_problems(tmp_path, GOOD.replace(old, new, 1))
    assert len(problems) == 1, problems
    assert re.search(expected, problems[0]), problems[0]


def test_table_given_as_wrong_kind(tmp_path):
    problems, _ = load_problems(tmp_path, 'box = 3\nspheres = [1]\n[[lattice]]\nradius = 0.1\n')
    assert "box: must be a dict, got 3" in problems
    assert "spheres[0]: must be a table ([[spheres]])" in problems


def test_missing_radius_and_x(tmp_path):
    problems, _ = load_problems(tmp_path, """
        [[spheres]]
        x = [0.5, 0.5, 0.5]
        [[spheres]]
        radius = 0.1
        [[random]]
        seed = 1
    """)
    assert problems == ["spheres[0]: missing 'radius'", "spheres[1]: missing 'x'",
                        "random[0]: missing 'count', 'radius'"]


def test_mass_and_density_or_v_and_speed_together(tmp_path):
    problems, _ = load_problems(tmp_path, """
        [[spheres]]
        x = [0.5, 0.5, 0.5]
        radius = 0.1
        mass = 1.0
        density = 2.0
        [[lattice]]
        radius = 0.01
        v = [1.0, 0.0, 0.0]
        speed = 1.0
    """)
    assert problems == ["spheres[0]: give mass or density, not both",
                        "lattice[0]: give v or speed, not both"]


def test_value_ranges_reported_together(tmp_path):
    problems, _ = load_problems(tmp_path, """
        [box]
        hi = [1.0, 0.0, 1.0]
        wall_restitution = 1.5
        [physics]
        restitution = -0.1
        step_fraction = 0.0
        max_sweeps = 0
        [[random]]
        count = 0
        radius = 0.1
        seed = -3
        density = 0.0
    """)
    assert problems == [
        "random[0].density: must be > 0, got 0.0",
        "random[0].seed: must be >= 0, got -3",
        "random[0].count: must be >= 1, got 0",
        "box: hi must exceed lo on axis y (0.0 .. 0.0)",
        "box.wall_restitution: must be in [0, 1], got 1.5",
        "physics.restitution: must be in [0, 1], got -0.1",
        "physics.step_fraction: must be in (0, 1], got 0.0",
        "physics.max_sweeps: must be >= 1, got 0",
    ]


def test_friction_ranges_name_their_keys(tmp_path):
    problems, _ = load_problems(tmp_path, """
        [physics]
        friction = -0.3
        wall_friction = -2.0
        rolling_friction = -1.0
        tangential_restitution = 1.5
        [[spheres]]
        x = [0.5, 0.5, 0.5]
        radius = 0.1
    """)
    assert problems == [
        "physics.friction: must be >= 0 and finite, got -0.3",
        "physics.wall_friction: must be >= 0 and finite, got -2.0",
        "physics.tangential_restitution: must be in [-1, 1], got 1.5",
        "physics.rolling_friction: must be >= 0 and finite, got -1.0",
    ]


def test_no_spheres(tmp_path):
    problems, _ = load_problems(tmp_path, "[box]\nhi = [1.0, 1.0, 1.0]\n")
    assert problems == ["no spheres: add [[spheres]], [[lattice]], [[random]] or [[pour]] "
                        "tables, or [initial] gsd"]


def test_overlapping_explicit_spheres_name_both_indices(tmp_path):
    problems, msg = load_problems(tmp_path, """
        [[spheres]]
        x = [0.2, 0.2, 0.2]
        radius = 0.1
        [[spheres]]
        x = [0.5, 0.5, 0.5]
        radius = 0.1
        [[spheres]]
        x = [0.5, 0.5, 0.65]
        radius = 0.1
    """)
    assert len(problems) == 1
    assert re.match(r"spheres 1 and 2 overlap", problems[0])
    assert "sphere 1 is spheres[1]; sphere 2 is spheres[2]" in problems[0]


def test_overlap_between_tables_names_the_generator(tmp_path):
    problems, _ = load_problems(tmp_path, """
        [[spheres]]
        x = [0.1, 0.1, 0.62]
        radius = 0.1
        [[lattice]]
        radius = 0.1
        spacing = 0.4
    """)
    assert len(problems) == 1
    assert re.match(r"spheres 0 and 2 overlap", problems[0])
    assert "sphere 2 is lattice[0] #1" in problems[0]


def test_explicit_sphere_outside_box(tmp_path):
    problems, _ = load_problems(tmp_path, """
        [box]
        hi = [2.0, 1.0, 1.0]
        [[spheres]]
        x = [0.5, 0.5, 0.5]
        radius = 0.1
        [[spheres]]
        x = [1.95, 0.5, 0.5]
        radius = 0.1
    """)
    assert len(problems) == 1
    assert re.match(r"sphere 1 .*outside the walls 0.0 .. 2.0 on axis x", problems[0])


def test_invalid_toml(tmp_path):
    problems, msg = load_problems(tmp_path, "[box\nlo = 1\n")
    assert len(problems) == 1 and problems[0].startswith("not valid TOML")
    (tmp_path / "bin.toml").write_bytes(b"\xff\xfe name = 1")
    with pytest.raises(SceneFileError, match="not valid TOML"):
        ts.load_scene(tmp_path / "bin.toml")


def test_nonexistent_file_and_directory(tmp_path):
    missing = tmp_path / "nope.toml"
    with pytest.raises(ValueError, match=r"scene file not found: .*nope\.toml"):
        ts.load_scene(missing)
    with pytest.raises(ValueError, match=r"cannot read scene file"):
        ts.load_scene(tmp_path)


# --------------------------------------------------------------------------- generators

def test_lattice_fills_box_with_expected_count(tmp_path):
    s = ts.load_scene(write(tmp_path, """
        [[lattice]]
        radius = 0.1
        spacing = 0.2
        mass = 1.5
    """))
    assert s.n == 125                         # 5 touching layers per axis, on the walls
    assert (s.x - s.radius[:, None] >= -1e-12).all() and (s.x + s.radius[:, None] <= 1 + 1e-12).all()
    np.testing.assert_allclose(np.unique(np.round(s.x[:, 0], 12)), [0.1, 0.3, 0.5, 0.7, 0.9])
    assert (s.mass == 1.5).all() and (s.v == 0).all()


@pytest.mark.parametrize("text, expected", [
    ("radius = 0.05\nspacing = 0.1", 1000),
    ("radius = 0.1", 64),                     # default spacing 2.2 r: 0.1, 0.32, 0.54, 0.76
    ("radius = 0.05\nspacing = 0.1\nlo = [0.0, 0.0, 0.0]\nhi = [0.3, 0.3, 0.3]", 27),
    ("radius = 0.1\nlo = [0.0, 0.0, 0.0]\nhi = [1.0, 1.0, 0.2]", 16),
])
def test_lattice_count(tmp_path, text, expected):
    s = ts.load_scene(write(tmp_path, "[[lattice]]\n" + text + "\n"))
    assert s.n == expected
    assert min_image_overlaps(s)[0] == -1


def test_lattice_with_speed_has_random_directions(tmp_path):
    text = "[[lattice]]\nradius = 0.1\nspeed = 2.0\nseed = 4\n"
    a = ts.load_scene(write(tmp_path, text))
    b = ts.load_scene(write(tmp_path, text, "b.toml"))
    np.testing.assert_allclose(np.linalg.norm(a.v, axis=1), 2.0)
    np.testing.assert_array_equal(a.v, b.v)
    assert np.abs(a.v.mean(axis=0)).max() < 1.0


def test_lattice_spacing_below_diameter(tmp_path):
    problems, _ = load_problems(tmp_path, "[[lattice]]\nradius = 0.1\nspacing = 0.15\n")
    assert problems == ["lattice[0]: spacing 0.15 is less than the diameter 0.2"]


def test_lattice_region_too_small(tmp_path):
    problems, _ = load_problems(tmp_path, """
        [[lattice]]
        radius = 0.1
        lo = [0.0, 0.0, 0.0]
        hi = [0.1, 1.0, 1.0]
    """)
    assert problems == ["lattice[0]: region too small for one sphere"]


RANDOM = """
[box]
periodic = [true, false, false]
[[spheres]]
x = [0.0, 0.5, 0.5]
radius = 0.15
[[random]]
count = 300
radius = 0.03
speed = 1.0
seed = {seed}
"""


def test_random_is_reproducible_and_non_overlapping(tmp_path):
    a = ts.load_scene(write(tmp_path, RANDOM.format(seed=11), "a.toml"))
    b = ts.load_scene(write(tmp_path, RANDOM.format(seed=11), "b.toml"))
    c = ts.load_scene(write(tmp_path, RANDOM.format(seed=12), "c.toml"))
    assert a.n == b.n == c.n == 301
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.v, b.v)
    assert not np.array_equal(a.x, c.x)
    for s in (a, c):
        # including across the periodic x faces, next to the big sphere at x = 0
        assert min_image_overlaps(s)[0] == -1
        xr = s.x[1:]
        assert (xr - 0.03 >= 0).all() and (xr + 0.03 <= 1).all()
        np.testing.assert_allclose(np.linalg.norm(s.v, axis=1)[1:], 1.0)


def test_random_respects_region_and_earlier_spheres(tmp_path):
    s = ts.load_scene(write(tmp_path, """
        [[lattice]]
        radius = 0.05
        spacing = 0.2
        lo = [0.0, 0.0, 0.0]
        hi = [1.0, 1.0, 0.5]
        [[random]]
        count = 50
        radius = 0.04
        lo = [0.0, 0.0, 0.0]
        hi = [1.0, 1.0, 0.5]
        v = [0.0, 0.0, 1.0]
        seed = 2
    """))
    n_lattice = 5 * 5 * 3
    assert s.n == n_lattice + 50
    assert min_image_overlaps(s)[0] == -1
    assert (s.x[n_lattice:, 2] + 0.04 <= 0.5).all()
    np.testing.assert_array_equal(s.v[n_lattice:], np.tile([0.0, 0.0, 1.0], (50, 1)))


def test_random_region_too_full(tmp_path):
    problems, _ = load_problems(tmp_path, "[[random]]\ncount = 2000\nradius = 0.1\n")
    assert len(problems) == 1
    assert re.match(r"random\[0\]: could not place sphere \d+ of 2000 .*too full", problems[0])


def test_scene_from_dict_matches_file(tmp_path):
    try:
        import tomllib
    except ImportError:  # Python 3.10
        import tomli as tomllib
    s1 = ts.load_scene(write(tmp_path, GOOD))
    s2 = scene_from_dict(tomllib.loads(GOOD))
    np.testing.assert_array_equal(s1.x, s2.x)
    np.testing.assert_array_equal(s1.mass, s2.mass)


def test_pour_generator_fills_from_the_top(tmp_path):
    text = ('[physics]\ngravity = [0.0, 0.0, -9.81]\n[[pour]]\ncount = 50\nradius = 0.02\n'
            'lo = [0.1, 0.1, 0.5]\nhi = [0.9, 0.9, 1.0]\nv = [0.0, 0.0, -1.0]\nv_spread = 0.1\n'
            'seed = 1\n')
    p = tmp_path / "pour.toml"
    p.write_text(text)
    scene = ts.load_scene(str(p))
    assert scene.n == 50
    assert scene.x[:, 2].min() > 0.5 + 0.02 - 1e-12 and scene.x[:, 2].max() <= 1.0 - 0.02
    # the top layer is filled first: every sphere is within two layers of the top
    assert scene.x[:, 2].min() > 1.0 - 0.02 - 2 * 2.5 * 0.02 - 0.02
    assert abs(scene.v[:, 2].mean() + 1.0) < 0.1 and scene.v[:, 0].std() > 0
    again = ts.load_scene(str(p))
    np.testing.assert_array_equal(scene.x, again.x)


def test_pour_too_many_for_the_region(tmp_path):
    p = tmp_path / "pour.toml"
    p.write_text('[[pour]]\ncount = 100000\nradius = 0.05\nlo = [0, 0, 0.8]\nhi = [1, 1, 1]\n')
    with pytest.raises(ValueError, match="make it taller"):
        ts.load_scene(str(p))


def test_radius_spread_gives_polydisperse_random_group(tmp_path):
    p = tmp_path / "poly.toml"
    p.write_text('[[random]]\ncount = 200\nradius = 0.03\nradius_spread = 0.5\nseed = 2\n')
    scene = ts.load_scene(str(p))
    assert scene.radius.min() >= 0.015 and scene.radius.max() <= 0.03
    assert scene.radius.max() / scene.radius.min() > 1.5
    # masses follow the radii through the (default) density
    np.testing.assert_allclose(scene.mass, 1000.0 * 4 / 3 * np.pi * scene.radius ** 3)


# --------------------------------------------------------------------------- what f64 can hold

def test_misspelt_required_key_is_reported_as_unknown_not_missing(tmp_path):
    problems, _ = load_problems(tmp_path, GOOD.replace("radius = 0.1", "radious = 0.1"))
    assert problems == ["unknown key 'spheres[0].radious' (did you mean 'spheres[0].radius'?)"]


@pytest.mark.parametrize("where, text", [
    ("spheres[0].colour", "mass = 2.0\ncolour = [2.0, 0.3, 0.25]"),
    ("spheres[0].colour", "mass = 2.0\ncolour = [0.5, -0.1, 0.25]"),
    ("render.background", "mass = 2.0\n[render]\nbackground = [0.1, 0.1, 1.5]"),
])
def test_colour_outside_zero_to_one_is_an_error(tmp_path, where, text):
    problems, _ = load_problems(tmp_path, GOOD.replace("mass = 2.0", text, 1))
    assert len(problems) == 1 and problems[0].startswith(f"{where}: red, green and blue must "
                                                         f"each be in [0, 1]")


def test_colour_inside_zero_to_one_is_kept(tmp_path):
    text = GOOD.replace("mass = 2.0", "mass = 2.0\ncolour = [1, 0, 0.5]")
    s = ts.load_scene(write(tmp_path, text))
    np.testing.assert_array_equal(s.meta["group_colours"][0], [1.0, 0.0, 0.5])


def test_radius_below_what_f64_resolves_names_the_radius_not_the_mass(tmp_path):
    problems, _ = load_problems(tmp_path, GOOD.replace("radius = 0.05", "radius = 1e-300"))
    assert len(problems) == 1
    assert problems[0].startswith("radius of sphere 1 (1e-300 m) is below what f64 can simulate")
    assert "mass" not in problems[0]


def test_speed_overflowing_f64_names_the_sphere():
    v = np.zeros((6, 3))
    v[4] = [1e300, 0.8, 1.0]
    with pytest.raises(ValueError, match=r"^speed of sphere 4 \(1e\+300 m/s\) overflows f64"):
        make(n=6, v=v)


def test_gravity_overflowing_f64_is_named():
    with pytest.raises(ValueError, match=r"^gravity \[0, 0, -1e\+307\] m/s\^2 overflows f64"):
        make(n=2, gravity=(0.0, 0.0, -1e307))


# ---- [initial] gsd: the spheres of a frame of a GSD trajectory ----

def gsd_file(path, frames=2):
    """A HOOMD-schema file of ``frames`` frames of two spheres (the last one moved)."""
    gsd_hoomd = pytest.importorskip("gsd.hoomd")
    with gsd_hoomd.open(str(path), "w") as traj:
        for k in range(frames):
            frame = gsd_hoomd.Frame()
            frame.configuration.box = [2.0, 2.0, 2.0, 0, 0, 0]
            frame.configuration.step = k
            frame.particles.N = 2
            frame.particles.position = [[-0.5 + 0.25 * k, 0, 0], [0.5, 0, 0]]
            frame.particles.velocity = [[1.0, 0, 0], [0, 0, float(k)]]
            frame.particles.diameter = [0.5, 0.25]
            frame.particles.mass = [2.0, 1.0]
            traj.append(frame)
    return path


INITIAL = """
name = "continued"
[physics]
restitution = 0.7
[initial]
gsd = "start.gsd"
"""


def test_initial_gsd_takes_the_last_frame_relative_to_the_scene_file(tmp_path):
    gsd_file(tmp_path / "start.gsd")
    s = ts.load_scene(write(tmp_path, INITIAL))
    assert s.n == 2 and s.restitution == 0.7 and s.name == "continued"
    np.testing.assert_array_equal(s.x[0], [-0.25, 0, 0])           # HOOMD box, centred
    np.testing.assert_array_equal(s.v[1], [0, 0, 1.0])
    np.testing.assert_array_equal(s.radius, [0.25, 0.125])
    np.testing.assert_array_equal(s.mass, [2.0, 1.0])
    np.testing.assert_array_equal(s.box_lo, [-1, -1, -1])
    assert s.periodic == (True, True, True)
    assert s.meta["initial"]["frame"] == 1 and s.meta["group_names"] == ["A"]


def test_initial_frame_and_box_from_the_scene_file(tmp_path):
    gsd_file(tmp_path / "start.gsd")
    text = INITIAL + "frame = 0\n[box]\nlo = [0.0, 0.0, 0.0]\nhi = [2.0, 2.0, 2.0]\n" \
        "periodic = false\n"
    s = ts.load_scene(write(tmp_path, text))
    np.testing.assert_array_equal(s.x[0], [0.5, 1, 1])       # about the box centre
    np.testing.assert_array_equal(s.v[1], [0, 0, 0])
    assert s.periodic == (False, False, False)


@pytest.mark.parametrize("extra, words", [
    ("frame = 5\n", ["initial.frame:", "has 2 frame(s)", "frame 5 does not exist"]),
    ("frame = -3\n", ["initial.frame:", "frame -3 does not exist"]),
    ("frame = 1.5\n", ["initial.frame: must be an integer"]),
    ("[[spheres]]\nx = [0.5, 0.5, 0.5]\nradius = 0.1\n",
     ["initial.gsd: the spheres come from the GSD frame; remove the [[spheres]]"]),
])
def test_initial_mistakes_name_the_key(tmp_path, extra, words):
    gsd_file(tmp_path / "start.gsd")
    problems, msg = load_problems(tmp_path, INITIAL + extra)
    assert len(problems) == 1 and all(w in msg for w in words), msg


def test_initial_gsd_file_missing_or_unreadable(tmp_path):
    problems, _ = load_problems(tmp_path, INITIAL)
    assert problems == [f"initial.gsd: GSD file not found: {tmp_path / 'start.gsd'}"]
    (tmp_path / "start.gsd").write_text("not gsd")
    problems, _ = load_problems(tmp_path, INITIAL)
    assert problems[0].startswith("initial.gsd: cannot read GSD file")


def test_initial_frame_needs_a_file_and_gsd_must_be_a_path(tmp_path):
    problems, _ = load_problems(tmp_path, GOOD + "[initial]\nframe = 0\n")
    assert problems == ["initial.frame: needs initial.gsd (the file to read the frame from)"]
    problems, _ = load_problems(tmp_path, "[initial]\ngsd = 3\n")
    assert problems == ["initial.gsd: must be a str, got 3"]


def test_output_trajectory_keys_are_checked(tmp_path):
    text = GOOD + '[output]\ntrajectory = "t.xyz"\ntrajectory_every = 0\n'
    problems, _ = load_problems(tmp_path, text)
    assert problems == ["output.trajectory: must end in .gsd, got 't.xyz'",
                        "output.trajectory_every: must be >= 1 step, got 0"]


def test_tables_name_the_types_of_their_spheres(tmp_path):
    s = ts.load_scene(write(tmp_path, GOOD))
    assert s.meta["group_names"] == ["spheres[0]", "spheres[1]"]
