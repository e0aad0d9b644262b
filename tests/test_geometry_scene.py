"""Scene layer of friction, spin, geometry and sinks beyond tests/test_geometry.py:
cone and tilted-plane gaps, every packed column, omega's checks, resolution of None
values through Scene.replace, and the scene-file tables and keys ([physics] friction
keys, [[sink]] recycle, [[cylinder]] keys, omega of every sphere table, random and
lattice spheres against geometry). Pure numpy: nothing here builds a Simulation."""
import math

import numpy as np
import pytest

import taichi_spheres as ts
from taichi_spheres.geometry import CONE, PACKED_WIDTH, PLANE
from taichi_spheres.scenefile import SceneFileError, random_positions

HALF = 1.0 / math.sqrt(2.0)


def _scene(x=((0.5, 0.5, 0.5), (0.2, 0.2, 0.2)), **kw):
    """Two spheres of radius 0.05 m at rest in the unit box, with the keywords given."""
    x = np.asarray(x, dtype=np.float64)
    return ts.Scene.from_arrays(x, np.zeros_like(x), 0.05, **kw)


# ------------------------------------------------------------------ gaps by hand

def test_tilted_plane_gap_and_orifice_wall():
    # normal (1, 0, 1)/sqrt 2 through the origin, an orifice of radius 1
    p = ts.Plane((0, 0, 0), (2, 0, 2), hole=1.0)
    assert p.normal.tolist() == pytest.approx([HALF, 0, HALF])
    x = np.array([[3.0, 0, 3.0],           # z = 3 sqrt 2, rho 0: over the hole, rim
                  [-1.0, 0, -1.0],         # z = -sqrt 2, rho 0: inside the orifice
                  [0.0, 5.0, 0.0]])        # z = 0, rho 5: beside the hole, on the plane
    r = np.array([0.1, 0.1, 0.1])
    assert p.gap(x, r) == pytest.approx([math.hypot(1.0, 3 * math.sqrt(2)) - 0.1,
                                         1.0 - 0.1, -0.1])


def test_cone_gap_inside_outside_and_far_rim():
    inner = ts.Cone((0, 0, 1), (0, 0, 1), 1.0, 2.0, 1.0)
    outer = ts.Cone((0, 0, 1), (0, 0, 1), 1.0, 2.0, 1.0, inside=False)
    x = np.array([[2.0, 0, 1.5],           # beyond the surface (rho 2 > 1.5 at t 0.5)
                  [1.5, 0, 1.5],           # on it
                  [2.0, 0, 3.0]])          # above the wide end: rim (t 1, rho 2) at 1
    r = np.full(3, 0.1)
    d = 0.5 * HALF                         # distance of (t 0.5, rho 2) from the surface
    assert inner.gap(x, r) == pytest.approx([-d - 0.1, -0.1, 1.0 - 0.1])
    assert outer.gap(x, r) == pytest.approx([d - 0.1, -0.1, 1.0 - 0.1])


def test_finite_cylinder_rim_at_its_start_and_tilted_axis():
    # axis along x from x = 1, radius 0.5, length 2
    c = ts.Cylinder((1, 0, 0), (3, 0, 0), 0.5, length=2.0)
    x = np.array([[0.0, 0.0, 0.5],         # before the start (t -1), at the rim's radius
                  [2.0, 0.2, 0.0],         # inside, 0.3 from the wall
                  [2.0, 0.0, 0.9]])        # outside the wall by 0.4
    r = np.full(3, 0.1)
    assert c.gap(x, r) == pytest.approx([1.0 - 0.1, 0.3 - 0.1, -0.4 - 0.1])
    assert c.radius == 0.5 and c.axis.tolist() == [1.0, 0.0, 0.0]


# ------------------------------------------------------------------ packed rows

def test_packed_columns_of_every_kind():
    plane = ts.Plane((1, 2, 3), (0, 3, 4), restitution=0.5, friction=0.25).packed()
    assert plane.dtype == np.float64 and plane.shape == (PACKED_WIDTH,) == (14,)
    assert plane.tolist() == pytest.approx([PLANE, 1, 2, 3, 0, 0.6, 0.8, 0, 0, 0, 1, 0,
                                            0.5, 0.25])
    cyl = ts.Cylinder((0, 0, 0), (0, 0, 2), 0.3, length=1.5, inside=False,
                      restitution=0.9, friction=0.1).packed()
    assert cyl.tolist() == pytest.approx([CONE, 0, 0, 0, 0, 0, 1, 0.3, 0.3, 1.5, 0, 0,
                                          0.9, 0.1])
    cone = ts.Cone((0, 0, 1), (0, 0, -1), 0.02, 0.2, 0.5, restitution=0.0,
                   friction=0.6).packed()
    assert cone.tolist() == pytest.approx([CONE, 0, 0, 1, 0, 0, -1, 0.02, 0.2, 0.5, 1, 0,
                                           0.0, 0.6])
    with pytest.raises(ValueError, match="Cone: restitution and friction must be resolved"):
        ts.Cone((0, 0, 0), (0, 0, 1), 1, 2, 1, friction=0.1).packed()


def test_scene_geometry_packs_resolved_values():
    s = _scene(wall_restitution=0.6, friction=0.3, wall_friction=0.2,
               geometry=[ts.Cylinder((0.5, 0.5, 0), (0, 0, 1), 0.49)])
    row = s.geometry[0].packed()
    assert row[12:].tolist() == [0.6, 0.2] and row[9] == -1.0


# ------------------------------------------------------------------ Scene checks

@pytest.mark.parametrize("kw, key", [
    (dict(friction=float("nan")), "friction must be"),
    (dict(friction=float("inf")), "friction must be"),
    (dict(friction="rough"), "friction must be a number"),
    (dict(wall_friction=-0.5), "wall_friction"),
    (dict(tangential_restitution=-1.5), "tangential_restitution"),
    (dict(omega=[[0, 0, 0], [np.nan, 0, 0]]), "omega of sphere 1 is not finite"),
    (dict(omega=[0, 0, 1]), "omega"),
    (dict(omega=[[0, 0, 0], [0, 0, 1e200]]), "omega: surface speed of sphere 1"),
    (dict(omega=[[0, 0, 0], [0, 0, 1.0]], friction=0.0),
     "omega of sphere 1 is not zero, but the scene has no friction"),
    (dict(geometry=[ts.Sink((0, 0, 0), (1, 1, 1))]), "geometry\\[0\\] must be a ts.Plane"),
    (dict(sinks=[ts.Plane((0, 0, 0), (0, 0, 1))]), "sinks\\[0\\] must be a ts.Sink"),
    (dict(wall_friction=0.1, restitution_model="smid"), "smid"),
    (dict(geometry=[ts.Plane((0, 0, 0), (0, 0, 1), friction=0.1)], restitution_model="smid"),
     "smid"),
    (dict(x=((0.69, 0.5, 0.5), (0.2, 0.2, 0.2)),      # across the cone's surface
          geometry=[ts.Cone((0.5, 0.5, 0.3), (0, 0, 1), 0.1, 0.4, 0.6, inside=False)]),
     "sphere 0 starts inside geometry\\[0\\] \\(Cone\\): gap"),
    (dict(geometry=[ts.Plane((0, 0, 0), (0, 0, 1)),
                    ts.Plane((0.5, 0.5, 0.6), (0, 0, 1), hole=0.04)]),
     "sphere 0 starts inside geometry\\[1\\] \\(Plane\\)"),
    (dict(geometry=[ts.Plane((0.5, 0.5, 0.01), (1, 0, 1), hole=0.6)]),
     "geometry\\[0\\] \\(Plane\\): hole 0.6 m reaches outside the box"),
])
def test_bad_scene_input_names_the_key(kw, key):
    with pytest.raises(ValueError, match=key):
        _scene(**kw)


def test_touching_geometry_is_accepted_and_periodic_axes_allowed():
    # sphere 0 rests on the plane z = 0.45 and touches the cylinder's wall from inside
    s = _scene(x=((0.5, 0.5, 0.5), (0.5, 0.2, 0.8)), periodic=(True, True, False),
               geometry=[ts.Plane((0.5, 0.5, 0.45), (0, 0, 1)),
                         ts.Cylinder((0.5, 0.5, 0.0), (0, 0, 1), 0.35)])
    gaps = [g.gap(s.x, s.radius) for g in s.geometry]
    assert gaps[0][0] == pytest.approx(0.0) and gaps[1][1] == pytest.approx(0.0, abs=1e-15)
    assert s.periodic == (True, True, False)


#: a platform cone 0.1 m tall (apex up, inside=False: spheres rest on its outside)
PLATFORM = ts.Cone((0.5, 0.5, 0.2), (0, 0, 1), 0.3, 0.0, 0.1, inside=False)


def test_a_start_behind_a_finite_shell_is_accepted_and_one_across_it_refused():
    """A finite cone or cylinder has two faces in the run (surfaces.py), so a start
    behind it (under the platform, outside a finite tube) is a start like any other;
    one whose sphere crosses either face is refused, naming the sphere."""
    under = (0.5, 0.5, 0.1)                      # below the platform: behind its shell
    s = _scene(x=((0.2, 0.2, 0.6), under), geometry=[PLATFORM])
    assert PLATFORM.gap(s.x, s.radius)[1] < -0.05                 # the front side: inside
    assert PLATFORM.gap(s.x, s.radius, both_faces=True)[1] > 0    # the run's face: clear
    tube = ts.Cylinder((0.5, 0.5, 0.3), (0, 0, 1), 0.2, length=0.4)
    assert _scene(x=((0.1, 0.1, 0.5), (0.5, 0.5, 0.5)), geometry=[tube]).n == 2
    with pytest.raises(ValueError, match="sphere 1 starts inside geometry\\[0\\] \\(Cone\\)"):
        _scene(x=((0.2, 0.2, 0.6), (0.65, 0.5, 0.22)), geometry=[PLATFORM])  # across the slope
    with pytest.raises(ValueError, match="sphere 0 starts inside geometry\\[0\\] \\(Cylinder\\)"):
        _scene(x=((0.72, 0.5, 0.5), (0.5, 0.5, 0.5)), geometry=[tube])       # across the tube


def test_an_infinite_cylinder_keeps_its_solid_back_at_the_start():
    pillar = ts.Cylinder((0.5, 0.5, 0.0), (0, 0, 1), 0.1, inside=False)
    with pytest.raises(ValueError, match="sphere 0 starts inside geometry\\[0\\]"):
        _scene(geometry=[pillar])


def test_omega_stored_as_float64_array():
    s = _scene(omega=[[1, 2, 3], [0, 0, -4]], friction=0.1)
    assert s.omega.dtype == np.float64 and s.omega.shape == (2, 3)
    assert s.omega.tolist() == [[1, 2, 3], [0, 0, -4]]
    assert s.replace(restitution=0.5).omega.tolist() == s.omega.tolist()


def test_wall_friction_given_and_resolved_on_replace():
    s = _scene(friction=0.5, wall_friction=0.1)
    assert (s.friction, s.wall_friction) == (0.5, 0.1)
    assert s.replace(friction=0.3).wall_friction == 0.1          # kept as given
    assert s.replace(friction=0.3, wall_friction=None).wall_friction == 0.3


def test_replace_keeps_spin_settings_geometry_and_sinks():
    sink = ts.Sink((0, 0, 0), (1, 1, 0.1), recycle=True)
    s = _scene(friction=0.2, tangential_restitution=0.4, rolling_friction=0.05,
               wall_restitution=0.8, geometry=[ts.Plane((0, 0, 0.12), (0, 0, 1))],
               sinks=[sink])
    t = s.replace(gravity=(0, 0, -1))
    assert (t.tangential_restitution, t.rolling_friction) == (0.4, 0.05)
    assert t.sinks == (sink,) and t.sinks[0].recycle
    assert t.geometry[0].restitution == 0.8
    # resolved values stay with the object; passing it anew with None resolves again
    assert s.replace(wall_restitution=0.3).geometry[0].restitution == 0.8
    fresh = s.replace(wall_restitution=0.3, geometry=[ts.Plane((0, 0, 0.12), (0, 0, 1))])
    assert fresh.geometry[0].restitution == 0.3
    assert s.replace(geometry=(), sinks=()).geometry == () and not t.replace(sinks=[]).sinks


@pytest.mark.parametrize("kw, frictional", [
    (dict(), False),
    (dict(wall_friction=0.2), True),
    (dict(friction=0.2, wall_friction=0.0), True),
    (dict(rolling_friction=0.01), True),
    (dict(tangential_restitution=0.5), False),
    (dict(geometry=[ts.Plane((0, 0, 0), (0, 0, 1), friction=0.0)]), False),
    (dict(geometry=[ts.Cone((0, 0, 0), (0, 0, 1), 0, 0.1, 0.1, friction=0.3)]), True),
])
def test_frictional(kw, frictional):
    assert _scene(**kw).frictional is frictional


# ------------------------------------------------------------------ scene files

BASE = """
name = "t"
[box]
lo = [0.0, 0.0, 0.0]
hi = [0.1, 0.1, 0.2]
wall_restitution = 0.7
[physics]
gravity = [0.0, 0.0, -9.81]
restitution = 0.5
"""
AXIS_Z = [0.0, 0.0, 1.0]
CENTRE = [0.05, 0.05, 0.0]
TOP_SPHERE = dict(x=[0.05, 0.05, 0.19], radius=0.005)


def _toml(value) -> str:
    """A Python value (bool, number, string or list of them) written as TOML."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml(c) for c in value) + "]"
    return repr(value)


def _keys(**keys) -> str:
    """'key = value' lines, one a key."""
    return "".join(f"{k} = {_toml(v)}\n" for k, v in keys.items())


def _table(kind, **keys) -> str:
    """One [[kind]] entry of a scene file."""
    return f"[[{kind}]]\n" + _keys(**keys)


def _load(tmp_path, *parts):
    """The Scene of BASE followed by ``parts`` (more [physics] keys first, then tables)."""
    f = tmp_path / "scene.toml"
    f.write_text(BASE + "".join(parts))
    return ts.load_scene(f)


def test_file_physics_keys_and_sink_recycle(tmp_path):
    s = _load(tmp_path,
              _keys(friction=0.3, wall_friction=0.6, tangential_restitution=0.2,
                    rolling_friction=0.05),
              _table("cone", point=[0.05, 0.05, 0.1], axis=AXIS_Z, radius_at_point=0.01,
                     radius_at_end=0.05, length=0.1),
              _table("cylinder", point=CENTRE, axis=AXIS_Z, radius=0.02, length=0.05,
                     inside=False, restitution=0.9),
              _table("sink", low=[0.0, 0.0, 0.0], high=[0.1, 0.1, 0.01], recycle=True),
              _table("spheres", x=[0.05, 0.05, 0.15], radius=0.005))
    assert (s.friction, s.wall_friction, s.tangential_restitution, s.rolling_friction) == \
        (0.3, 0.6, 0.2, 0.05)
    # cylinders before cones, whatever the file order
    assert [type(g).__name__ for g in s.geometry] == ["Cylinder", "Cone"]
    cyl, cone = s.geometry
    assert not cyl.inside and (cyl.restitution, cyl.friction) == (0.9, 0.6)
    assert (cone.restitution, cone.friction) == (0.7, 0.6) and cone.radius_at_end == 0.05
    assert s.sinks[0].recycle and s.sinks[0].high.tolist() == [0.1, 0.1, 0.01]


def test_file_cylinder_keys_checked_and_problems_reported_together(tmp_path):
    with pytest.raises(SceneFileError) as info:
        _load(tmp_path,
              _table("cylinder", point=CENTRE, axis=AXIS_Z, radius=0.04, heigth=0.1),
              _table("cylinder", point=CENTRE, axis=AXIS_Z, radius=0.04, inside="yes"),
              _table("cone", point=CENTRE, axis=AXIS_Z, radius_at_point=0.0,
                     radius_at_end=0.0, length=0.1),
              _table("spheres", **TOP_SPHERE))
    problems = "\n".join(info.value.problems)
    assert "unknown key 'cylinder[0].heigth'" in problems
    assert "cylinder[1].inside: must be a bool" in problems
    assert "cone[0]: Cone: radius_at_point and radius_at_end must not both be 0" in problems


def test_file_errors_name_the_geometry_and_sink_tables(tmp_path):
    """Scene errors about geometry or sinks name the file's tables (cylinder[0],
    sink[1]), not the Python API's geometry list."""
    plane = _table("plane", point=[0.05, 0.05, 0.02], normal=AXIS_Z)
    cylinder = _table("cylinder", point=CENTRE, axis=AXIS_Z, radius=0.02, length=0.05)
    with pytest.raises(SceneFileError, match=r"sphere 0 starts inside cylinder\[0\]: gap"):
        _load(tmp_path, plane, cylinder, _table("spheres", x=[0.069, 0.05, 0.05], radius=0.005))
    sinks = _table("sink", low=[0.0, 0.0, 0.0], high=[0.1, 0.1, 0.01]) + \
        _table("sink", low=[2.0, 2.0, 2.0], high=[3.0, 3.0, 3.0])
    with pytest.raises(SceneFileError, match=r"sink\[1\] \(\[2.0, 2.0, 2.0\]"):
        _load(tmp_path, sinks, _table("spheres", **TOP_SPHERE))


def test_file_omega_of_every_sphere_table(tmp_path):
    regions = {"lattice": dict(lo=[0.0, 0.0, 0.0], hi=[0.1, 0.02, 0.02]),
               "random": dict(count=3, lo=[0.0, 0.0, 0.05], hi=[0.1, 0.1, 0.1]),
               "pour": dict(count=4, lo=[0.0, 0.0, 0.12], hi=[0.1, 0.1, 0.18])}
    spins = [[0.0, 0.0, 1.0], [2.0, 0.0, 0.0], [0.0, 3.0, 0.0], [0.0, 0.0, 4.0]]
    tables = [_table("spheres", omega=spins[0], **TOP_SPHERE)]
    tables += [_table(kind, radius=0.005, omega=w, **keys)
               for (kind, keys), w in zip(regions.items(), spins[1:])]
    s = _load(tmp_path, _keys(friction=0.2), *tables)
    groups = s.meta["groups"]
    for g, w in enumerate(spins):
        assert (groups == g).any() and (s.omega[groups == g] == w).all()


def test_file_omega_must_be_a_vector(tmp_path):
    with pytest.raises(SceneFileError, match="pour\\[0\\].omega: must be 3 finite numbers"):
        _load(tmp_path, _table("pour", count=4, radius=0.005, omega=4.0))


SILO = (_table("plane", point=[0.05, 0.05, 0.05], normal=AXIS_Z, hole=0.01)
        + _table("cylinder", point=CENTRE, axis=AXIS_Z, radius=0.03))


def test_file_random_spheres_stay_clear_of_geometry(tmp_path):
    s = _load(tmp_path, SILO, _table("random", count=40, lo=[0.0, 0.0, 0.0],
                                     hi=[0.1, 0.1, 0.2], radius=0.004, radius_spread=0.3,
                                     seed=3))
    assert s.n == 40
    for g in s.geometry:
        assert (g.gap(s.x, s.radius) >= 0).all()


def test_random_draws_without_geometry_in_the_way_are_unchanged():
    # a plane below the region rejects no draw: the same places as without it
    lo, hi = np.zeros(3), np.ones(3)
    plain = random_positions(30, 0.05, lo, hi, np.random.default_rng(7))
    floor = ts.Plane((0, 0, -1), (0, 0, 1))
    beside = random_positions(30, 0.05, lo, hi, np.random.default_rng(7), shapes=(floor,))
    assert np.array_equal(plain, beside)
    wall = ts.Plane((0, 0, 0.5), (0, 0, 1))           # rejects the lower half
    upper = random_positions(30, 0.05, lo, hi, np.random.default_rng(7), shapes=(wall,))
    assert (upper[:, 2] >= 0.55).all() and not np.array_equal(plain, upper)


def test_random_region_inside_geometry_is_named(tmp_path):
    # a corner of the box outside the silo's wall
    with pytest.raises(SceneFileError, match="random\\[0\\]: could not place sphere 0 of 2 "
                                             "without overlap or entering geometry"):
        _load(tmp_path, SILO, _table("random", count=2, lo=[0.0, 0.0, 0.1],
                                     hi=[0.015, 0.015, 0.2], radius=0.004))


def test_file_lattice_inside_geometry_names_the_sphere(tmp_path):
    with pytest.raises(SceneFileError, match="starts inside cylinder\\[0\\]: gap"
                                             ".*lattice\\[0\\] #"):
        _load(tmp_path, SILO, _table("spheres", **TOP_SPHERE),
              _table("lattice", lo=[0.0, 0.0, 0.06], hi=[0.1, 0.1, 0.1], radius=0.005))
