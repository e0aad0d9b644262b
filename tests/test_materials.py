"""Per-sphere materials (taichi_spheres/materials.py): the pair table, its checks, and
the engine using each pair's values against the exact reference and Walton's closed
form; one material (or several with equal values) compiles the lookups out and keeps
the bits of a scene without materials.
"""
import math

import numpy as np
import pytest

import taichi_spheres as ts
from taichi_spheres.builders import gas
from taichi_spheres.config import Tuning
from taichi_spheres.reference import EventDrivenReference, walton_impact
from taichi_spheres.state import Features

from test_friction import assert_impact, oblique_pair

G = 9.81
GLASS = ts.Material("glass", restitution=0.97, friction=0.092)
RUBBER = ts.Material("rubber", restitution=0.6, friction=0.8, rolling_friction=0.05)


def _two(**kw):
    x = np.array([[0.2, 0.5, 0.5], [0.5, 0.5, 0.5]])
    return ts.Scene.from_arrays(x, np.zeros((2, 3)), 0.05, **kw)


def test_pair_values_are_the_smaller_of_the_two_materials():
    sc = _two(restitution=0.9, friction=0.3, materials=[GLASS, ts.Material("soft")],
              material=[0, 1])
    table = sc.pair_values()
    assert table[0, 0].tolist() == [0.97, 0.092, 0.0]
    assert table[1, 1].tolist() == [0.9, 0.3, 0.0]          # None: the scene's values
    assert table[0, 1].tolist() == table[1, 0].tolist() == [0.9, 0.092, 0.0]
    assert sc.varied_materials and sc.frictional and not sc.elastic_pairs
    # replace keeps the materials and re-resolves the scene's values
    assert sc.replace(friction=0.5).pair_values()[1, 1].tolist() == [0.9, 0.5, 0.0]


def test_material_pairs_override_the_smaller_value():
    sc = _two(materials=[GLASS, RUBBER], material=[0, 1],
              material_pairs={(1, 0): ts.Material(restitution=0.8)})
    table = sc.pair_values()
    assert table[0, 1, 0] == table[1, 0, 0] == 0.8
    assert table[0, 1, 1] == 0.092                          # not overridden: the smaller


def test_equal_materials_compile_the_lookups_out():
    sc = _two(restitution=0.5, materials=[ts.Material("a"), ts.Material("b")],
              material=[0, 1])
    assert not sc.varied_materials
    assert not Features.from_scene(sc).materials
    unused = _two(materials=[GLASS, RUBBER], material=[1, 1])    # glass used by none
    assert not unused.varied_materials
    assert Features.from_scene(_two(materials=[GLASS, RUBBER], material=[0, 1])).materials


@pytest.mark.parametrize("kw, words", [
    (dict(materials=[GLASS, RUBBER], material=[0, 2]), "material of sphere 1 is 2"),
    (dict(materials=[1]), "materials[0] must be a ts.Material"),
    (dict(material=[0.5, 0]), "integer indices"),
    (dict(material=[0, 0, 0]), "shape (2,)"),
    (dict(material=1), "material of sphere 0 is 1"),
    (dict(material_pairs={(0, 3): GLASS}), "material_pairs[(0, 3)]"),
    (dict(materials=[GLASS, RUBBER], material=[0, 1],
          material_pairs={(0, 1): GLASS, (1, 0): RUBBER}), "the pair (0, 1) is given twice"),
    (dict(materials=[GLASS, GLASS]), "names must differ"),
    (dict(materials=[ts.Material()] * 17), "at most 16"),
])
def test_bad_materials_name_the_key(kw, words):
    with pytest.raises(ValueError) as err:
        _two(**kw)
    assert words in str(err.value)


@pytest.mark.parametrize("key, value", [("restitution", 1.5), ("friction", -0.1),
                                        ("rolling_friction", math.inf),
                                        ("restitution", "hard")])
def test_bad_material_coefficients_name_the_key(key, value):
    with pytest.raises(ValueError, match=f"Material 'x'.{key}"):
        ts.Material("x", **{key: value})


def test_two_material_gas_follows_the_exact_reference(arch):
    """A walled gas of two materials (e 0.9 and 0.5: pairs 0.9, 0.5, 0.5) under gravity,
    nothing resting in [0, 0.4] s: every collision uses its pair's restitution, as in the
    reference."""
    if arch == "metal":
        pytest.skip("needs f64")
    base = gas(30, packing=0.05, radius=0.05, periodic=False, speed=3.0, seed=7)
    scene = ts.Scene.from_arrays(
        base.x, base.v, base.radius, box=(base.box_lo, base.box_hi), gravity=(0, 0, -G),
        wall_restitution=0.8, materials=[ts.Material(restitution=0.9),
                                         ts.Material(restitution=0.5)],
        material=np.arange(30) % 2)
    sim = ts.Simulation(scene, arch=arch, precision="f64", step_fraction=0.01)
    assert sim.features.materials
    ref = EventDrivenReference(scene)
    sim.advance_to(0.4)
    ref.advance_to(0.4)
    a, b = sim.state(), ref.state()
    assert sim.stats["pair_collisions"] == ref.stats["pair_collisions"] > 90
    assert sim.stats["energy_contacts"] == 0
    assert np.abs(a.x - b.x).max() < 1e-6 * float(base.box_size[0])
    assert np.abs(a.v - b.v).max() < 1e-5
    # the same gas with one material of e 0.9 loses less energy
    one = ts.Simulation(scene.replace(materials=(), material=None, restitution=0.9),
                        arch=arch, precision="f64", step_fraction=0.01)
    one.advance_to(0.4)
    assert one.stats["energy_pair_restitution"] < sim.stats["energy_pair_restitution"]


def test_one_material_keeps_the_bits_of_a_scene_without_materials(arch, precision):
    base = gas(40, packing=0.1, radius=0.05, periodic=False, speed=2.0, seed=3)
    plain = ts.Scene.from_arrays(base.x, base.v, base.radius, box=(base.box_lo, base.box_hi),
                                 gravity=(0, 0, -G), restitution=0.7, friction=0.3)
    named = plain.replace(materials=[ts.Material("sand")], material=0)
    runs = []
    for sc in (plain, named):
        sim = ts.Simulation(sc, arch=arch, precision=precision)
        sim.advance_to(0.2)
        runs.append(sim.state())
    assert np.array_equal(runs[0].x, runs[1].x) and np.array_equal(runs[0].omega, runs[1].omega)


def test_oblique_impact_of_two_materials_follows_walton(arch):
    """Glass meeting rubber: Walton's impact with the pair's e 0.6 and mu 0.092."""
    sim, (v, w, r, m, n) = oblique_pair((0.0, 400.0, -100.0), arch, tangential_restitution=0.35,
                                        materials=[GLASS, RUBBER], material=[0, 1])
    sim.advance(1e-3)
    assert sim.stats["pair_collisions"] == 1
    want = walton_impact(v[0], v[1], w[0], w[1], r[0], r[1], m[0], m[1], n, 0.6, 0.092, 0.35)
    assert_impact(sim.state(), v, r, want[:2], want[2:])


def test_rolling_friction_of_each_material_on_the_floor(arch):
    """Two spheres rolling on the floor, one of a material with rolling friction mu_r:
    it decelerates at 5/7 mu_r g (rolling torque mu_r r m g, no slip), the other keeps
    rolling at its speed."""
    r, v0, mu_r = 0.02, 0.5, 0.05
    x = np.array([[0.2, 0.3, r], [0.2, 0.7, r]])
    v = np.array([[v0, 0, 0], [v0, 0, 0]])
    w = np.array([[0, v0 / r, 0], [0, v0 / r, 0]])
    sc = ts.Scene.from_arrays(x, v, r, box=((0, 0, 0), (2, 1, 1)), restitution=0.5,
                              wall_restitution=0.5, wall_friction=0.5, omega=w,
                              materials=[ts.Material(friction=0.5, rolling_friction=mu_r),
                                         ts.Material(friction=0.5)], material=[0, 1])
    sim = ts.Simulation(sc, arch=arch, precision="f64")
    t = 0.5
    sim.advance_to(t)
    st = sim.state()
    assert st.v[0, 0] == pytest.approx(v0 - 5 / 7 * mu_r * G * t, rel=1e-3)
    assert st.v[1, 0] == pytest.approx(v0, rel=1e-9)


def _two_material_pile():
    """36 spheres in two materials (glass-like and rubbery), dropped into a box."""
    rng = np.random.default_rng(5)
    r = 0.01
    g = np.arange(4) * 0.025 + 0.015
    x = np.array([(a, b, c) for a in g for b in g for c in (0.02, 0.05, 0.08)], float)[:36]
    x[:, :2] += rng.uniform(-2e-3, 2e-3, (len(x), 2))
    v = rng.uniform(-0.2, 0.2, x.shape)
    return ts.Scene.from_arrays(x, v, r, box=((0, 0, 0), (0.105, 0.105, 0.3)),
                                wall_restitution=0.5, wall_friction=0.3,
                                materials=[GLASS, RUBBER], material=np.arange(len(x)) % 2)


def test_two_material_pile_settles_with_its_energy_booked(arch):
    """Glass and rubber spheres settle in a pile: energy never above the start, every
    joule booked; overlaps below 2.5e-3 of a diameter after any step (1.2e-3 measured,
    in the landing) and below 1e-5 after the last."""
    sim = ts.Simulation(_two_material_pile(), arch=arch, precision="f64")
    assert sim.features.materials and sim.features.rolling
    energy = [sim.energy_budget()["current"]]
    for _ in range(1500):
        sim.advance(sim.max_step())
        energy.append(sim.energy_budget()["current"])
    assert max(energy) <= energy[0] * (1 + 1e-12)
    budget = sim.energy_budget()
    assert abs(budget["unaccounted"]) <= 1e-9 * abs(budget["initial"])
    assert sim.stats["max_overlap"] < 2.5e-3
    assert sim.last_step["max_overlap"] < 1e-5


def test_two_material_pile_same_bits_on_both_paths(arch):
    """Two materials give the same bits on the serial path (every loop on one thread)
    and on the parallel one (forced with the HOST_ONLY sphere counts at 0: its loops
    spread over the runtime's threads) (CPU properties)."""
    if arch != "cpu":
        pytest.skip("the serial path is a CPU setting")
    parallel = Tuning().with_(serial_light_below=0, serial_heavy_below=0,
                              serial_solver_below=0, few_pairs=0, serial_resolve_pairs=0)
    digests = []
    for tuning in (Tuning(), parallel):
        sim = ts.Simulation(_two_material_pile(), arch=arch, precision="f64", tuning=tuning)
        sim.advance(0.2)
        st = sim.state()
        digests.append((st.x.tobytes(), st.v.tobytes(), st.omega.tobytes()))
    assert digests[0] == digests[1]
    assert sim.debug_view().solver._sweeps, "the parallel sweeps did not run"


def test_discharged_spheres_take_their_material_with_them(arch):
    """A sink removes spheres of both materials; the rest keep theirs."""
    r = 0.005
    x = np.array([(0.02 + 0.012 * k, 0.05, 0.05) for k in range(6)], float)
    v = np.zeros_like(x)
    v[:3, 2] = -2.0                         # the first three fall into the sink
    sc = ts.Scene.from_arrays(x, v, r, box=((0, 0, 0), (0.1, 0.1, 0.1)), gravity=(0, 0, 0),
                              materials=[GLASS, RUBBER], material=[0, 1, 0, 1, 0, 1],
                              sinks=[ts.Sink((0, 0, 0), (0.1, 0.1, 0.02))])
    sim = ts.Simulation(sc, arch=arch, precision="f64")
    sim.advance(0.05)
    assert sim.stats["discharged"] == 3
    assert sim.sphere_ids.tolist() == [3, 4, 5]
    assert sim.scene.material.tolist() == [1, 0, 1]


SCENE = """
name = "two"
[box]
hi = [0.2, 0.2, 0.4]
wall_restitution = 0.5
[physics]
gravity = [0, 0, -9.81]
restitution = 0.5
friction = 0.4
[[material]]
name = "glass"
restitution = 0.97
friction = 0.092
[[material]]
name = "rubber"
friction = 0.9
rolling_friction = 0.05
[[material_pair]]
materials = ["glass", "rubber"]
restitution = 0.7
[[pour]]
count = 20
lo = [0.02, 0.02, 0.2]
hi = [0.18, 0.18, 0.38]
radius = 0.01
material = "glass"
[[pour]]
count = 20
lo = [0.02, 0.02, 0.02]
hi = [0.18, 0.18, 0.09]
radius = 0.01
material = "rubber"
[[spheres]]
x = [0.1, 0.1, 0.15]
radius = 0.01
"""


def test_scene_file_materials(tmp_path):
    path = tmp_path / "two.toml"
    path.write_text(SCENE)
    sc = ts.load_scene(path)
    assert [m.name for m in sc.materials] == ["default", "glass", "rubber"]
    assert np.bincount(sc.material).tolist() == [1, 20, 20]     # [[spheres]] first
    table = sc.pair_values()
    assert table[1, 2].tolist() == [0.7, 0.092, 0.0]
    assert table[0, 0].tolist() == [0.5, 0.4, 0.0]
    assert table[2, 2].tolist() == [0.5, 0.9, 0.05]


@pytest.mark.parametrize("change, words", [
    (('material = "rubber"', 'material = "rubbr"'), "pour[1].material: unknown material "
                                                    "'rubbr' (did you mean 'rubber'?)"),
    (('name = "glass"', 'name = "rubber"'), "material[1].name: 'rubber' is taken"),
    (('rolling_friction = 0.05', 'rolling_friction = -1'),
     "material[1]: Material 'rubber'.rolling_friction must be >= 0"),
    (('materials = ["glass", "rubber"]', 'materials = ["glass"]'),
     "material_pair[0].materials: must be a list of two material names"),
    (('friction = 0.092', 'frict = 0.092'), "unknown key 'material[0].frict'"),
    (('[[material_pair]]', '[[material_pair]]\nmaterials = ["rubber", "glass"]\n'
                           'restitution = 0.2\n[[material_pair]]'),
     "material_pair[1]: the pair glass/rubber is given by an earlier [[material_pair]]"),
])
def test_scene_file_material_problems_are_named(tmp_path, change, words):
    path = tmp_path / "bad.toml"
    path.write_text(SCENE.replace(*change))
    with pytest.raises(ValueError) as err:
        ts.load_scene(path)
    assert words in str(err.value)


def test_checkpoint_after_a_discharge_keeps_the_materials(arch, tmp_path):
    r = 0.005
    x = np.array([(0.02 + 0.012 * k, 0.05, 0.05) for k in range(6)], float)
    v = np.zeros_like(x)
    v[:3, 2] = -2.0
    sc = ts.Scene.from_arrays(x, v, r, box=((0, 0, 0), (0.1, 0.1, 0.1)), gravity=(0, 0, 0),
                              materials=[GLASS, RUBBER], material=[0, 1, 0, 1, 0, 1],
                              sinks=[ts.Sink((0, 0, 0), (0.1, 0.1, 0.02))])
    sim = ts.Simulation(sc, arch=arch, precision="f64")
    sim.advance(0.05)
    ck = sim.checkpoint()
    again = ts.Simulation(sc, arch=arch, precision="f64")
    again.restore(ck)
    assert again.scene.material.tolist() == [1, 0, 1]
