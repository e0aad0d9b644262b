"""Substeps (Rules.substeps, stepping.Stepper.collide_in_substeps): drift and impacts
in substeps that no sphere crosses more than step_fraction x r_min of, the contact
solver once per step, whose length the spheres its rows hold bound (at most 2 D /
impact speed). Impacts stay exact, a bed still holds, a step ends early at a
collision of a sphere that had a contact row, and a run continues from a checkpoint
bit for bit.

Tolerances as in test_contact_solver.py (overlaps / diameter, speeds in m/s).
"""
import numpy as np
import pytest

import taichi_spheres as ts
from taichi_spheres import observe
from conftest import brute_overlap, walled_gravity_gas
from taichi_spheres.builders import fcc_block
from taichi_spheres.config import Tuning
from taichi_spheres.reference import EventDrivenReference
from taichi_spheres.scene import Scene

G = 9.81
R = 0.01
SUBSTEPS = Tuning().with_(substeps=True)


def _column_and_ball(height=0.5, n=10):
    """n spheres of radius R stacked on the floor (1e-4 m apart) and one more of the
    same size ``height`` [m] above the top one, all at rest (e = 0.5)."""
    x = np.zeros((n + 1, 3))
    x[:, :2] = 0.05
    x[:n, 2] = R + (2 * R + 1e-4) * np.arange(n)
    x[n, 2] = x[n - 1, 2] + height
    return Scene.from_arrays(x, np.zeros_like(x), np.full(n + 1, R),
                             box=((0, 0, 0), (0.1, 0.1, x[n, 2] + 0.1)), gravity=(0, 0, -G),
                             restitution=0.5, wall_restitution=0.5)


def test_substeps_take_true_or_false():
    assert Tuning().with_(substeps=True).physics.substeps is True
    with pytest.raises(ValueError, match="substeps"):
        Tuning().with_(substeps=1)


def test_gravity_gas_in_substeps_follows_the_reference(arch):
    """test_reference's walled gas under gravity (none resting): in substeps the engine
    still follows the event-driven reference, collision for collision, and the
    solver's steps span several substeps."""
    if arch == "metal":
        pytest.skip("needs f64")
    scene = walled_gravity_gas()
    sim = ts.Simulation(scene, arch=arch, precision="f64", step_fraction=0.01,
                        tuning=SUBSTEPS)
    ref = EventDrivenReference(scene)
    sim.advance_to(0.5)
    ref.advance_to(0.5)
    a, b = sim.state(), ref.state()
    assert sim.stats["substeps"] > 2 * sim.stats["steps"]
    assert sim.stats["pair_collisions"] == ref.stats["pair_collisions"] > 100
    assert sim.stats["wall_collisions"] == ref.stats["wall_collisions"] > 100
    assert sim.stats["energy_contacts"] == 0
    L = float(scene.box_size[0])
    assert np.abs(a.x - b.x).max() < 1e-6 * L
    assert np.abs(a.v - b.v).max() < 1e-5


def test_ball_onto_a_column_in_substeps(arch, precision):
    """A ball falling 0.5 m onto a settled column of 10: while it falls the column is
    solved once per several substeps; its landing ends a step early (shorter than
    asked: a sphere with contact rows was hit); the total energy never rises above
    its start; after 2 s all rest without overlap, and advance_to lands on time."""
    sim = ts.Simulation(_column_and_ball(), arch=arch, precision=precision, tuning=SUBSTEPS)
    energy0 = sim.energy_budget()["current"]
    ended_early, worst = 0, -np.inf
    while sim.time < 0.5:
        asked = min(sim.max_step(), 0.5 - sim.time)
        taken = sim.step(asked)
        sim.time += taken
        ended_early += taken < asked and sim.last_step["pair_collisions"] > 0
        worst = max(worst, sim.energy_budget()["current"] - energy0)
    assert sim.stats["substeps"] > 2 * sim.stats["steps"]
    assert ended_early >= 1
    assert worst <= 1e-9 * abs(energy0) if precision == "f64" else worst <= 1e-5 * abs(energy0)
    sim.advance_to(2.0)
    assert sim.time == 2.0
    st = sim.state()
    assert brute_overlap(st, sim.scene) <= 1e-4
    assert np.abs(st.v).max() <= (1e-6 if precision == "f64" else 1e-3)


def test_fcc_block_holds_in_substeps(arch):
    """The 256-sphere FCC block settles and holds at rest as without substeps."""
    sim = ts.Simulation(fcc_block(4), arch=arch, tuning=SUBSTEPS)
    sim.advance(1.0)
    x = sim.state().x.copy()
    sim.advance(1.0)
    st = sim.state()
    assert np.abs(st.x - x).max() <= 1e-4 * 2 * R
    assert np.abs(st.v).max() <= 1e-6
    assert brute_overlap(st, sim.scene) <= 1e-4
    assert sim.stats["sweep_limit_hits"] == 0


@pytest.mark.parametrize("relaxation", [1.0, 1.8])
def test_settled_block_in_a_new_simulation_gains_no_energy(arch, relaxation):
    """The settled FCC block handed to a new Simulation (no load flags, no warm start):
    its spheres rest on each other and approach only by round-off. Those pairs are no
    impacts to come (ContactRows.inert_impact_row): with inert rows the lower layer
    was stopped while the upper ones kept falling, the position pass pushed their
    overlaps out and kept their speed, and the first step raised the total energy by
    ~3.5e-5 J (half of (g h)^2 per sphere). Now the energy never rises and the block
    stays at rest."""
    tuning = SUBSTEPS.with_(relaxation=relaxation)
    sim = ts.Simulation(fcc_block(4), arch=arch, tuning=tuning)
    sim.advance(1.0)
    st = sim.state()
    fresh = ts.Simulation(sim.scene, arch=arch, tuning=tuning)
    fresh.set_state(st.x, st.v)
    energy = [fresh.energy_budget()["current"]]
    for _ in range(20):
        fresh.advance(fresh.max_step())
        energy.append(fresh.energy_budget()["current"])
    assert max(energy) <= energy[0] * (1 + 1e-12)
    assert np.abs(fresh.state().v).max() <= 1e-6


def test_checkpoint_in_substeps_continues_bit_for_bit(arch):
    """A run in substeps stopped at a checkpoint while the ball is in flight and
    continued in a new Simulation gives the same bits as the run straight through
    (the step bound of the held spheres and the rows' near flags travel with it)."""
    scene = _column_and_ball()
    sim = ts.Simulation(scene, arch=arch, tuning=SUBSTEPS)
    sim.advance_to(0.2)
    ckpt = sim.checkpoint()
    sim.advance_to(0.6)
    other = ts.Simulation(scene, arch=arch, tuning=SUBSTEPS)
    other.restore(ckpt)
    other.advance_to(0.6)
    assert sim.stats["pair_collisions"] > 0
    assert observe.state_digest(other.state(), other.precision) == \
        observe.state_digest(sim.state(), sim.precision)
    assert other.stats["substeps"] == sim.stats["substeps"]


def test_substeps_same_bits_fused_and_kernel_by_kernel(arch):
    """The fused step and the kernel-by-kernel path give the same bits in substeps."""
    if arch != "cpu":
        pytest.skip("the fused step is a CPU path")
    scene = _column_and_ball()
    out = []
    for fused in (False, True):
        sim = ts.Simulation(scene, arch=arch, fused=fused, tuning=SUBSTEPS)
        sim.advance_to(0.6)
        out.append((observe.state_digest(sim.state(), sim.precision), sim.stats["substeps"]))
    assert out[0] == out[1]


def test_sphere_falling_through_a_thin_sink_in_substeps_leaves(arch):
    """A ball falling at ~3.7 m/s through a sink 2 mm thick beside a resting column
    (which lets the solver's steps span ~30 mm of the ball's fall): the substep in
    which its centre is inside the sink ends the step, and it is discharged."""
    n = 10
    x = np.zeros((n + 1, 3))
    x[:n, :2] = 0.05
    x[:n, 2] = R + (2 * R + 1e-4) * np.arange(n)
    x[n] = (0.15, 0.05, 1.0)
    scene = Scene.from_arrays(x, np.zeros_like(x), np.full(n + 1, R),
                              box=((0, 0, 0), (0.2, 0.1, 1.1)), gravity=(0, 0, -G),
                              restitution=0.5, wall_restitution=0.5,
                              sinks=[ts.Sink((0.1, 0.0, 0.3), (0.2, 0.1, 0.302))])
    sim = ts.Simulation(scene, arch=arch, tuning=SUBSTEPS)
    sim.advance_to(0.5)
    assert sim.stats["substeps"] > 2 * sim.stats["steps"]
    assert sim.stats["discharged"] == 1 and sim.n == n


@pytest.mark.parametrize("recycle", [False, True])
def test_silo_discharges_in_substeps(arch, recycle):
    """test_friction's small silo with an orifice, in substeps: spheres falling below
    the orifice take substeps while the bed above is solved at its own pace; they
    leave (or, recycled, come back at the top), and the energy stays booked."""
    from test_friction import _silo
    sim = ts.Simulation(_silo(hole=0.02, recycle=recycle), arch=arch, precision="f64",
                        tuning=SUBSTEPS)
    n0 = sim.n
    sim.advance(0.5)
    s = sim.stats
    assert s["discharged"] > 0
    assert sim.n == (n0 if recycle else n0 - s["discharged"])
    assert s["substeps"] > s["steps"]
    budget = sim.energy_budget()
    assert abs(budget["unaccounted"]) < 1e-6 * abs(budget["initial"])
