"""Scene layer of friction, geometry and sinks (geometry.py, scene.py, scenegeometry.py):
gap formulas against hand-computed values, packed rows, resolution of None values,
and every bad input raising ValueError that names the key, sphere or table."""
import math

import numpy as np
import pytest

import taichi_spheres as ts
from taichi_spheres.geometry import CONE, PACKED_WIDTH, PLANE


def test_plane_gap_with_and_without_orifice():
    flat = ts.Plane((0, 0, 1), (0, 0, 2))
    holed = ts.Plane((0, 0, 1), (0, 0, 1), hole=0.3)
    x = np.array([[5, 5, 1.5], [0.1, 0, 1.4], [0.0, 0.0, 0.9], [0.4, 0, 1.2]])
    r = np.full(4, 0.1)
    assert flat.gap(x, r) == pytest.approx([0.4, 0.3, -0.2, 0.1])
    # far from the hole; over it (rim circle at rho 0.3, z 0); below it (orifice wall);
    # beside it (plane)
    assert holed.gap(x, r) == pytest.approx([0.4, math.hypot(0.2, 0.4) - 0.1, 0.3 - 0.1, 0.1])


def test_cylinder_and_cone_gaps():
    cyl = ts.Cylinder((0, 0, 0), (0, 0, 1), 1.0)
    out = ts.Cylinder((0, 0, 0), (0, 0, 1), 1.0, inside=False)
    short = ts.Cylinder((0, 0, 0), (0, 0, 1), 1.0, length=2.0)
    x = np.array([[0.5, 0, 5], [1.5, 0, 0.3], [0.9, 0, 3.0]])
    r = np.full(3, 0.1)
    assert cyl.gap(x, r) == pytest.approx([0.4, -0.6, 0.0])
    assert out.gap(x, r) == pytest.approx([-0.6, 0.4, -0.2])
    # above the finite cylinder's top rim (t = 3 > 2): distance to the rim circle
    assert short.gap(x[2:], r[2:]) == pytest.approx([math.hypot(0.1, 1.0) - 0.1])
    # a 45-degree cone from radius 1 at t = 0 to 2 at t = 1: inside at rho = 1, t = 0.5
    # the surface is at rho 1.5, distance 0.5 cos(45 deg)
    cone = ts.Cone((0, 0, 0), (0, 0, 1), 1.0, 2.0, 1.0)
    assert cone.gap(np.array([[1.0, 0, 0.5]]), [0.1]) == pytest.approx([0.5 / math.sqrt(2) - 0.1])
    # below its narrow end: distance to the rim (t = 0, rho = 1)
    assert cone.gap(np.array([[0.0, 0, -1.0]]), [0.1]) == pytest.approx([math.sqrt(2) - 0.1])


def test_packed_rows():
    p = ts.Plane((1, 2, 3), (0, 0, 5), hole=0.2, restitution=0.4, friction=0.3).packed()
    assert len(p) == PACKED_WIDTH and p[0] == PLANE
    assert p[1:7].tolist() == [1, 2, 3, 0, 0, 1] and p[11:].tolist() == [0.2, 0.4, 0.3]
    c = ts.Cylinder((0, 0, 0), (1, 0, 0), 0.5, restitution=1.0, friction=0.0).packed()
    assert c[0] == CONE and c[7] == c[8] == 0.5 and c[9] == -1.0 and c[10] == 1.0
    with pytest.raises(ValueError, match="resolved"):
        ts.Plane((0, 0, 0), (0, 0, 1)).packed()


def _scene(**kw):
    x = np.array([[0.5, 0.5, 0.5], [0.2, 0.2, 0.2]])
    return ts.Scene.from_arrays(x, np.zeros_like(x), 0.05, **kw)


def test_scene_resolves_wall_values_and_keeps_them_on_replace():
    s = _scene(friction=0.4, wall_restitution=0.7,
               geometry=[ts.Plane((0, 0, 0.1), (0, 0, 1)),
                         ts.Cylinder((0.5, 0.5, 0), (0, 0, 1), 0.49, friction=0.2)])
    assert s.wall_friction == 0.4 and s.frictional
    assert (s.geometry[0].restitution, s.geometry[0].friction) == (0.7, 0.4)
    assert (s.geometry[1].restitution, s.geometry[1].friction) == (0.7, 0.2)
    assert s.omega.shape == (2, 3) and not s.omega.any()
    t = s.replace(restitution=0.5)
    assert t.friction == 0.4 and len(t.geometry) == 2 and t.geometry[1].friction == 0.2
    assert not _scene().frictional
    assert _scene(geometry=[ts.Plane((0, 0, 0), (0, 0, 1), friction=0.1)]).frictional


@pytest.mark.parametrize("kw, key", [
    (dict(friction=-0.1), "friction"),
    (dict(wall_friction=float("nan")), "wall_friction"),
    (dict(rolling_friction=-1), "rolling_friction"),
    (dict(tangential_restitution=1.5), "tangential_restitution"),
    (dict(omega=np.zeros((3, 3))), "omega"),
    (dict(omega=[[0, 0, np.inf], [0, 0, 0]]), "omega of sphere 0"),
    (dict(geometry=["floor"]), "geometry\\[0\\]"),
    (dict(sinks=[(0, 1)]), "sinks\\[0\\]"),
    (dict(sinks=[ts.Sink((2, 2, 2), (3, 3, 3))]), "outside the box"),
    (dict(geometry=[ts.Plane((0, 0, 0.6), (0, 0, 1))]), "sphere 0 starts inside geometry\\[0\\]"),
    (dict(geometry=[ts.Cylinder((0.2, 0.2, 0), (0, 0, 1), 0.1, inside=False)]),
     "sphere 1 starts inside geometry\\[0\\] \\(Cylinder\\)"),
    (dict(geometry=[ts.Plane((0.5, 0.5, 0.01), (0, 0, 1), hole=0.7)]), "hole 0.7 m reaches"),
    (dict(friction=0.2, restitution_model="smid", restitution=0.5), "smid"),
])
def test_bad_friction_and_geometry_input_names_the_key(kw, key):
    with pytest.raises(ValueError, match=key):
        _scene(**kw)


@pytest.mark.parametrize("make, key", [
    (lambda: ts.Plane((0, 0, 0), (0, 0, 0)), "Plane.normal must not be zero"),
    (lambda: ts.Plane((0, 0, 0), (0, 0, 1), hole=-1), "Plane.hole"),
    (lambda: ts.Cylinder((0, 0, 0), (0, 0, 1), 0.0), "Cylinder.radius must be > 0"),
    (lambda: ts.Cylinder((0, 0, 0), (0, 0, 1), 1.0, length=-2), "Cylinder.length"),
    (lambda: ts.Cone((0, 0, 0), (0, 0, 1), 0, 0, 1), "both be 0"),
    (lambda: ts.Cone((0, 0, 0), (0, 0, 1), 1, 2, None), "Cone.length"),
    (lambda: ts.Cone((0, 0, 0), (0, 0, 1), 1, 2, 1, restitution=2), "Cone.restitution"),
    (lambda: ts.Plane((0, 0, 0), (0, 0, 1), friction=-1), "Plane.friction"),
    (lambda: ts.Sink((0, 0, 0), (1, 0, 1)), "Sink.low must be below Sink.high"),
])
def test_bad_geometry_objects(make, key):
    with pytest.raises(ValueError, match=key):
        make()


SILO = """
name = "silo"
[box]
lo = [0.0, 0.0, 0.0]
hi = [0.1, 0.1, 0.3]
[physics]
gravity = [0.0, 0.0, -9.81]
restitution = 0.5
friction = 0.4
tangential_restitution = 0.3
[[plane]]
point = [0.05, 0.05, 0.05]
normal = [0.0, 0.0, 1.0]
hole = 0.01
[[cylinder]]
point = [0.05, 0.05, 0.05]
axis = [0.0, 0.0, 1.0]
radius = 0.04
length = 0.25
[[cone]]
point = [0.05, 0.05, 0.2]
axis = [0.0, 0.0, 1.0]
radius_at_point = 0.03
radius_at_end = 0.04
length = 0.05
friction = 0.1
[[sink]]
low = [0.0, 0.0, 0.0]
high = [0.1, 0.1, 0.02]
[[spheres]]
x = [0.05, 0.05, 0.1]
v = [0.0, 0.0, 0.0]
omega = [1.0, 2.0, 3.0]
radius = 0.004
[[pour]]
count = 50
lo = [0.01, 0.01, 0.12]
hi = [0.09, 0.09, 0.19]
radius = 0.004
"""


def test_scene_file_geometry_tables(tmp_path):
    f = tmp_path / "silo.toml"
    f.write_text(SILO)
    s = ts.load_scene(f)
    assert [type(g).__name__ for g in s.geometry] == ["Plane", "Cylinder", "Cone"]
    assert s.geometry[0].hole == 0.01 and s.geometry[2].friction == 0.1
    assert s.geometry[1].friction == 0.4 and s.tangential_restitution == 0.3
    assert len(s.sinks) == 1 and not s.sinks[0].recycle
    assert s.omega[0].tolist() == [1.0, 2.0, 3.0] and not s.omega[1:].any()
    assert np.all(np.hypot(s.x[:, 0] - 0.05, s.x[:, 1] - 0.05) + s.radius <= 0.04)


@pytest.mark.parametrize("old, new, key", [
    ("radius = 0.04\n", "radius = -0.04\n", "cylinder\\[0\\]: Cylinder.radius must be > 0"),
    ("hole = 0.01", "hole = 0.01\nholes = 2", "unknown key 'plane\\[0\\].holes'"),
    ("normal = [0.0, 0.0, 1.0]", "normal = [0.0, 0.0, 0.0]", "plane\\[0\\]: Plane.normal"),
    ("friction = 0.4", "friction = -0.4", "friction"),
    ("high = [0.1, 0.1, 0.02]", "", "sink\\[0\\]: missing 'high'"),
])
def test_scene_file_geometry_errors_name_the_table(tmp_path, old, new, key):
    f = tmp_path / "bad.toml"
    f.write_text(SILO.replace(old, new, 1))
    with pytest.raises(ValueError, match=key):
        ts.load_scene(f)
