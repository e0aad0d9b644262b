"""Shipped scenes: each loads, simulates and renders; physics checked where a check exists;
the rendered image has the orientation a user expects."""
import glob
import os

import numpy as np
import pytest

import taichi_spheres as ts
from taichi_spheres.render import Renderer, RenderUnavailable

SCENES = sorted(glob.glob(os.path.join(os.path.dirname(__file__), "..", "scenes", "*.toml")))


def _renderer(scene, **kw):
    try:
        return Renderer(scene, size=(160, 128), **kw)
    except RenderUnavailable as exc:
        pytest.skip(str(exc))


def test_scene_library_is_complete():
    names = {os.path.basename(p) for p in SCENES}
    assert {"seed_five.toml", "newton_cradle.toml", "gas.toml", "pour.toml", "cooling.toml",
            "heavy_intruder.toml", "polydisperse.toml"} <= names


@pytest.mark.parametrize("path", SCENES, ids=lambda p: os.path.basename(p))
def test_every_scene_simulates_and_renders(arch, path):
    scene = ts.load_scene(path)
    sim = ts.Simulation(scene, arch=arch)
    r = _renderer(scene)
    try:
        first = r.frame(sim.state())
        sim.advance(0.05)
        second = r.frame(sim.state())
    finally:
        r.close()
    assert first.shape == (128, 160, 3) and first.dtype == np.uint8
    assert first.std() > 1.0 and second.std() > 1.0
    assert sim.stats["unresolved"] == 0
    st = sim.state()
    assert np.isfinite(st.x).all() and np.isfinite(st.v).all()


def test_image_orientation(arch):
    """A sphere near the top-left-front corner (low x, high z, front = low y, seen from
    the default camera in front of the box) appears in the top-left of the frame."""
    scene = ts.Scene.from_arrays([[0.15, 0.2, 0.85]], [[0, 0, 0]], 0.12, gravity=(0, 0, 0))
    ts.Simulation(scene, arch=arch)     # initialises Taichi on the arch under test
    r = _renderer(scene, colour_table=np.array([[1.0, 0.0, 0.0]], dtype=np.float32),
                  background=(0, 0, 0))
    try:
        img = r.frame(ts.State(x=scene.x, v=scene.v, radius=scene.radius, mass=scene.mass,
                               time=0.0)).astype(int)
    finally:
        r.close()
    red = (img[..., 0] > 120) & (img[..., 1] < 80) & (img[..., 2] < 80)
    assert red.sum() > 20
    rows, cols = np.nonzero(red)
    assert rows.mean() < img.shape[0] / 2, "sphere at the top of the box must be at the top"
    assert cols.mean() < img.shape[1] / 2, "sphere at low x must be on the left"


def test_seed_five_energy_falls_and_spheres_end_on_the_floor(arch):
    scene = ts.load_scene(os.path.join(os.path.dirname(__file__), "..", "scenes",
                                       "seed_five.toml"))
    sim = ts.Simulation(scene, arch=arch)
    energies = []
    for k in range(1, 121):
        sim.advance_to(0.1 * k)
        energies.append(ts.observe.total_energy(sim.state(), scene.gravity))
    e = np.array(energies)
    assert np.all(np.diff(e) <= 1e-9 * abs(e[0])), "energy must never grow"
    assert e[-1] < 0.2 * e[0]
    st = sim.state()
    height = st.x[:, 2] - st.radius - scene.box_lo[2]
    assert np.all(height < 1e-3), f"spheres must end on the floor, heights {height}"
    assert np.all(st.x - st.radius[:, None] >= scene.box_lo - 1e-12)
    assert np.all(st.x + st.radius[:, None] <= scene.box_hi + 1e-12)
    assert sim.stats["pair_collisions"] > 0 and sim.stats["wall_collisions"] > 0
