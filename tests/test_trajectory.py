"""GSD trajectories (HOOMD schema): frames written by GSDWriter read back through
gsd.hoomd, the box and type conventions, frames every N steps, and scenes read from a
frame."""
import dataclasses

import numpy as np
import pytest

import taichi_spheres as ts
from taichi_spheres import builders, trajectory

gsd_hoomd = pytest.importorskip("gsd.hoomd")


def walled_scene():
    """Five spheres of two sizes in a 1 m box with walls and gravity, offset origin."""
    x = np.array([[0.3, 0.3, 0.5], [0.7, 0.3, 0.5], [0.3, 0.7, 0.5], [0.7, 0.7, 0.5],
                  [0.5, 0.5, 0.8]]) + 2.0
    v = np.array([[1.0, 0.5, 0.0], [-1.0, 0.2, 0.3], [0.4, -0.8, 0.0], [0.0, 0.0, 1.0],
                  [0.3, 0.3, -1.0]])
    radius = np.array([0.1, 0.1, 0.1, 0.1, 0.05])
    return ts.Scene.from_arrays(x, v, radius, box=((2, 2, 2), (3, 3, 3)), restitution=0.9,
                                wall_restitution=0.9)


def test_frames_round_trip_through_gsd_hoomd(tmp_path):
    scene = walled_scene()
    sim = ts.Simulation(scene)
    path = tmp_path / "run.gsd"
    with ts.GSDWriter(path) as writer:
        writer.append(sim)
        sim.advance(0.3)
        writer.append(sim)
    st = sim.state()
    with gsd_hoomd.open(str(path)) as traj:
        assert len(traj) == 2
        first, last = traj[0], traj[1]
    np.testing.assert_array_equal(last.configuration.box, [1, 1, 1, 0, 0, 0])
    assert first.configuration.step == 0 and last.configuration.step == sim.stats["steps"] > 0
    assert last.particles.N == 5 and last.particles.position.dtype == np.float64
    # HOOMD convention: the box is centred at the origin
    np.testing.assert_allclose(last.particles.position, st.x - 2.5, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(last.particles.velocity, st.v)
    np.testing.assert_array_equal(last.particles.diameter, 2 * scene.radius)
    np.testing.assert_array_equal(last.particles.mass, scene.mass)
    assert last.particles.types == ["r=0.05", "r=0.1"]
    np.testing.assert_array_equal(last.particles.typeid, [1, 1, 1, 1, 0])
    log = last.log
    assert log["taichi_spheres/time"][0] == pytest.approx(0.3)
    assert log["taichi_spheres/pair_collisions"][0] == sim.stats["pair_collisions"]
    assert log["taichi_spheres/kinetic_energy"][0] == pytest.approx(ts.observe.kinetic_energy(st))
    # read back into the scene's own coordinates: velocities exact, positions to the
    # rounding of the centre shift
    frame = trajectory.read_frame(path)
    np.testing.assert_array_equal(frame.v, st.v)
    np.testing.assert_allclose(frame.x, st.x, rtol=0, atol=4 * np.finfo(float).eps * 3)
    np.testing.assert_array_equal(frame.box_lo, [2, 2, 2])
    assert frame.periodic == (False, False, False) and frame.time == pytest.approx(0.3)


def test_periodic_positions_lie_in_the_centred_box(tmp_path):
    scene = builders.gas(64, packing=0.2, radius=0.1)
    sim = ts.Simulation(scene)
    sim.advance(0.5)
    with ts.GSDWriter(tmp_path / "gas.gsd") as writer:
        writer.append(sim)
    with gsd_hoomd.open(str(tmp_path / "gas.gsd")) as traj:
        frame = traj[0]
    half = 0.5 * np.asarray(frame.configuration.box[:3])
    assert np.all(frame.particles.position >= -half) and np.all(frame.particles.position < half)
    assert frame.log["taichi_spheres/periodic"].tolist() == [1, 1, 1]
    assert frame.particles.types == ["r=0.1"]


def test_frames_every_n_steps_leave_the_run_unchanged(tmp_path):
    scene = walled_scene()
    plain = ts.Simulation(scene)
    plain.advance(0.2)
    sim = ts.Simulation(scene)
    writer = ts.GSDWriter(tmp_path / "every.gsd")
    tap = trajectory.StepFrames(sim, writer, 7)
    sim.advance(0.2)
    tap.flush()
    tap.detach()
    writer.close()
    np.testing.assert_array_equal(sim.state().x, plain.state().x)
    assert "step" not in vars(sim)
    with gsd_hoomd.open(str(tmp_path / "every.gsd")) as traj:
        steps = [int(f.configuration.step) for f in traj]
        times = [float(f.log["taichi_spheres/time"][0]) for f in traj]
    assert steps == list(range(0, sim.stats["steps"] + 1, 7))
    assert times == sorted(times) and times[0] == 0.0


def test_a_resumed_writer_keeps_the_frames_up_to_its_step(tmp_path):
    path = tmp_path / "resume.gsd"
    sim = ts.Simulation(walled_scene())
    with ts.GSDWriter(path) as writer:
        for _ in range(4):
            writer.append(sim)
            sim.advance(0.05)
    steps = [int(f.configuration.step) for f in gsd_hoomd.open(str(path))]
    with ts.GSDWriter(path, keep_until_step=steps[1]) as writer:
        writer.append(sim)
    again = [int(f.configuration.step) for f in gsd_hoomd.open(str(path))]
    assert again == steps[:2] + [sim.stats["steps"]]
    assert not (tmp_path / "resume.gsd.before-resume.gsd").exists()


def test_spin_is_written_as_hoomd_angular_momentum(tmp_path):
    """A state with omega (rotation) gets moment_inertia and angmom = 2 (0, I omega)."""
    scene = walled_scene()
    omega = np.arange(15, dtype=float).reshape(5, 3)
    state = dataclasses.make_dataclass("Spinning", ["x", "v", "radius", "mass", "time",
                                                    "omega"])(
        scene.x, scene.v, scene.radius, scene.mass, 0.0, omega)
    frame = trajectory.make_frame(state, {"steps": 0}, scene)
    inertia = 0.4 * scene.mass * scene.radius ** 2
    np.testing.assert_allclose(frame.particles.moment_inertia[:, 2], inertia)
    np.testing.assert_allclose(frame.particles.angmom[:, 1:], 2 * inertia[:, None] * omega)
    np.testing.assert_array_equal(frame.particles.angmom[:, 0], 0.0)


def test_scene_from_gsd_continues_a_run(tmp_path):
    scene = walled_scene()
    sim = ts.Simulation(scene)
    sim.advance(0.1)
    with ts.GSDWriter(tmp_path / "a.gsd") as writer:
        writer.append(sim)
    again = ts.scene_from_gsd(tmp_path / "a.gsd", gravity=scene.gravity, restitution=0.9,
                              wall_restitution=0.9)
    np.testing.assert_array_equal(again.box_lo, scene.box_lo)
    np.testing.assert_array_equal(again.v, sim.state().v)
    np.testing.assert_array_equal(again.radius, scene.radius)
    assert again.periodic == scene.periodic and again.name == "a"
    assert again.meta["group_names"] == ["r=0.05", "r=0.1"]
    assert again.meta["initial"]["time"] == pytest.approx(0.1)


def test_spin_comes_back_from_a_frame(tmp_path):
    """A frictional run's frame holds angmom; scene_from_gsd gives the spheres their
    spins back (omega = angmom / 2 I)."""
    scene = walled_scene()
    scene = ts.Scene.from_arrays(scene.x, scene.v, scene.radius, mass=scene.mass,
                                 box=(scene.box_lo, scene.box_hi), gravity=scene.gravity,
                                 restitution=0.9, wall_restitution=0.9, friction=0.5,
                                 omega=np.arange(15, dtype=float).reshape(5, 3))
    sim = ts.Simulation(scene)
    sim.advance(0.05)
    with ts.GSDWriter(tmp_path / "spin.gsd") as writer:
        writer.append(sim)
    again = ts.scene_from_gsd(tmp_path / "spin.gsd", gravity=scene.gravity, friction=0.5)
    np.testing.assert_allclose(again.omega, sim.state().omega, rtol=1e-12)
    assert np.any(again.omega != 0)
    smooth = ts.scene_from_gsd(tmp_path / "spin.gsd", gravity=scene.gravity)
    assert not smooth.frictional and not smooth.omega.any()     # spins act only with friction


def test_first_frame_after_a_discharge(tmp_path):
    """A writer whose first frame comes after a sink took spheres out types the spheres
    of the scene the run started from."""
    x = np.array([[0.2 + 0.1 * k, 0.5, 0.15 if k < 2 else 0.6] for k in range(8)])
    radius = np.where(np.arange(8) % 2 == 0, 0.03, 0.04)
    scene = ts.Scene.from_arrays(x, np.zeros_like(x), radius, gravity=(0, 0, -9.81),
                                 sinks=[ts.Sink((0, 0, 0), (1, 1, 0.1))])
    sim = ts.Simulation(scene)
    sim.advance_to(0.25)
    assert 0 < sim.n < 8
    with ts.GSDWriter(tmp_path / "late.gsd") as writer:
        writer.append(sim)
        sim.advance_to(0.3)
        writer.append(sim)
    with gsd_hoomd.open(str(tmp_path / "late.gsd")) as traj:
        frames = list(traj)
    assert frames[-1].particles.N == sim.n
    want = np.where(sim.sphere_ids % 2 == 0, 0, 1)         # r=0.03, r=0.04
    np.testing.assert_array_equal(frames[-1].particles.typeid, want)
    assert frames[-1].particles.types == ["r=0.03", "r=0.04"]


def test_a_frame_with_spheres_behind_a_finite_shell_starts_a_new_scene(tmp_path):
    """A sphere that went under a platform cone (its back face) in a run is where the
    run may put it: the frame starts a new scene with the same geometry."""
    platform = ts.Cone((0.5, 0.5, 0.3), (0, 0, 1), 0.3, 0.0, 0.1, inside=False)
    x = np.array([[0.5, 0.5, 0.6], [0.5, 0.5, 0.15], [0.2, 0.2, 0.1]])
    scene = ts.Scene.from_arrays(x, np.zeros_like(x), 0.05, gravity=(0, 0, -9.81),
                                 geometry=[platform])
    sim = ts.Simulation(scene)
    sim.advance(0.05)
    with ts.GSDWriter(tmp_path / "heap.gsd") as writer:
        writer.append(sim)
    again = ts.scene_from_gsd(tmp_path / "heap.gsd", gravity=scene.gravity,
                              geometry=[platform])
    np.testing.assert_allclose(again.x, sim.state().x, rtol=0, atol=1e-15)  # box-centred
    assert platform.gap(again.x[1:2], 0.05)[0] < 0 < platform.gap(again.x[1:2], 0.05,
                                                                   both_faces=True)[0]


def test_frames_of_other_tools_use_the_hoomd_box(tmp_path):
    """A HOOMD file without our log: box centred at the origin, periodic, default mass."""
    frame = gsd_hoomd.Frame()
    frame.configuration.box = [2.0, 2.0, 2.0, 0, 0, 0]
    frame.particles.N = 2
    frame.particles.position = [[-0.5, 0, 0], [0.5, 0, 0]]
    frame.particles.diameter = [0.4, 0.4]
    with gsd_hoomd.open(str(tmp_path / "other.gsd"), "w") as traj:
        traj.append(frame)
    scene = ts.scene_from_gsd(tmp_path / "other.gsd")
    np.testing.assert_array_equal(scene.box_lo, [-1, -1, -1])
    np.testing.assert_array_equal(scene.x[1], [0.5, 0, 0])
    assert scene.periodic == (True, True, True)
    np.testing.assert_array_equal(scene.mass, [1.0, 1.0])
    np.testing.assert_array_equal(scene.gravity, [0, 0, 0])


@pytest.mark.parametrize("case, words", [
    ("missing", ["GSD file not found"]),
    ("frame", ["has 1 frame", "frame 3 does not exist"]),
    ("tilted", ["tilted box"]),
    ("not gsd", ["cannot read GSD file"]),
])
def test_bad_frames_are_named(tmp_path, case, words):
    path = tmp_path / "f.gsd"
    if case == "not gsd":
        path.write_text("not a gsd file")
    elif case != "missing":
        frame = gsd_hoomd.Frame()
        frame.configuration.box = [1, 1, 1, 0.5 if case == "tilted" else 0, 0, 0]
        frame.particles.N = 1
        frame.particles.position = [[0, 0, 0]]
        with gsd_hoomd.open(str(path), "w") as traj:
            traj.append(frame)
    with pytest.raises(ValueError) as err:
        trajectory.read_frame(path, 3 if case == "frame" else -1)
    assert all(w in str(err.value) for w in words), str(err.value)


def test_freud_reads_the_contact_value_of_carnahan_starling(tmp_path):
    """freud's radial distribution function of an equilibrated elastic gas at phi = 0.3,
    from our GSD file: its contact value matches Carnahan-Starling,
    g(sigma+) = (1 - phi/2) / (1 - phi)^3, within 4 standard errors over frames."""
    freud = pytest.importorskip("freud")
    phi, sigma = 0.3, 1.0
    sim = ts.Simulation(builders.gas(2000, packing=phi, radius=sigma / 2))
    sim.advance(1.0)                                # ~5 collisions per sphere
    with ts.GSDWriter(tmp_path / "gas.gsd") as writer:
        for _ in range(20):                         # ~1 collision per sphere apart
            sim.advance(0.1)
            writer.append(sim)
    contact = []
    with gsd_hoomd.open(str(tmp_path / "gas.gsd")) as traj:
        for frame in traj:
            rdf = freud.density.RDF(bins=30, r_max=1.3 * sigma, r_min=sigma)
            rdf.compute(system=frame)
            fit = np.polyfit(rdf.bin_centers - sigma, rdf.rdf, 2)   # extrapolated to sigma+
            contact.append(fit[-1])
    mean, error = np.mean(contact), np.std(contact, ddof=1) / np.sqrt(len(contact))
    theory = (1 - phi / 2) / (1 - phi) ** 3
    assert abs(mean - theory) < 4 * error, (mean, error, theory)
    assert error < 0.02 * theory


def test_ovito_sees_the_positions_and_radii(tmp_path):
    """OVITO (PyPI ovito, the [ovito] extra) imports our file: the frames, the centred
    positions, the radii and the box."""
    ovito_io = pytest.importorskip("ovito.io")
    sim = ts.Simulation(walled_scene())
    with ts.GSDWriter(tmp_path / "run.gsd") as writer:
        writer.append(sim)
        sim.advance(0.1)
        writer.append(sim)
    pipeline = ovito_io.import_file(str(tmp_path / "run.gsd"))
    assert pipeline.source.num_frames == 2
    data = pipeline.compute(1)
    st = sim.state()
    np.testing.assert_allclose(np.asarray(data.particles.positions), st.x - 2.5, atol=1e-12)
    np.testing.assert_allclose(np.asarray(data.particles["Radius"]), st.radius)
    np.testing.assert_allclose(np.asarray(data.cell[...])[:, 3], [-0.5, -0.5, -0.5])
