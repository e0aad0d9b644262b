"""Stiff cases (issue 4, started): a bouncing ball comes to rest at the analytic time
and stays there; a stacked column is the known open failure (strict xfail)."""
import numpy as np
import pytest

import taichi_spheres as ts
from conftest import tol


@pytest.mark.parametrize("e", [0.5, 0.8])
def test_bouncing_ball_comes_to_rest_at_the_analytic_time(arch, precision, e):
    """Apex heights e^(2n) h0 and rest at t0 (1+e)/(1-e), t0 = sqrt(2 h0/g); after that
    the ball stays on the floor, and its energy never grows."""
    r, h0, g = 0.05, 0.5, 9.81
    scene = ts.Scene.from_arrays([[0.5, 0.5, r + h0]], [[0, 0, 0]], r, gravity=(0, 0, -g),
                                 wall_restitution=e)
    sim = ts.Simulation(scene, arch=arch, precision=precision)
    t0 = np.sqrt(2 * h0 / g)
    t_rest = t0 * (1 + e) / (1 - e)
    energy = [ts.observe.total_energy(sim.state(), scene.gravity)]
    # apexes: bounce k at t0 (1 + 2 e + ... + 2 e^(k-1)), apex e^k t0 later
    t_bounce = t0
    for k in range(1, 4):
        sim.advance_to(t_bounce + e ** k * t0)
        st = sim.state()
        assert st.x[0, 2] - r == pytest.approx(e ** (2 * k) * h0, rel=tol(precision, 1e3))
        energy.append(ts.observe.total_energy(st, scene.gravity))
        t_bounce += 2 * e ** k * t0
    sim.advance_to(0.999 * t_rest)
    before = sim.state()
    assert before.x[0, 2] - r > 0 or abs(before.v[0, 2]) > 0, "still bouncing just before"
    sim.advance_to(1.001 * t_rest)
    st = sim.state()
    assert st.x[0, 2] - r == pytest.approx(0.0, abs=tol(precision, 10) * h0)
    assert abs(st.v[0, 2]) < tol(precision, 10) * np.sqrt(g * h0)
    energy.append(ts.observe.total_energy(st, scene.gravity))
    sim.advance_to(3 * t_rest)
    st = sim.state()
    assert st.x[0, 2] - r == pytest.approx(0.0, abs=tol(precision, 10) * h0)
    assert abs(st.v[0, 2]) < tol(precision, 10) * np.sqrt(g * h0)
    energy.append(ts.observe.total_energy(st, scene.gravity))
    assert np.all(np.diff(energy) <= tol(precision, 10) * abs(energy[0]))
    assert sim.stats["wall_rests"] >= 1


def test_stacked_column_comes_to_rest(arch):
    r, n = 0.05, 10
    x = np.array([[0.5, 0.5, r + (2 * r + 0.001) * k] for k in range(n)])
    scene = ts.Scene.from_arrays(x, np.zeros((n, 3)), r, gravity=(0, 0, -9.81),
                                 restitution=0.5, wall_restitution=0.5,
                                 box=((0, 0, 0), (1, 1, 2)))
    sim = ts.Simulation(scene, arch=arch)
    e0 = ts.observe.total_energy(sim.state(), scene.gravity)
    sim.advance_to(1.0)
    st = sim.state()
    gaps = np.diff(st.x[:, 2]) - 2 * r
    assert gaps.min() > -0.01 * r, "no sphere sinks into another by more than 1 % of r"
    assert ts.observe.total_energy(st, scene.gravity) <= e0 * (1 + 1e-12)
