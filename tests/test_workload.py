"""The work estimate of a run, what a precision can hold, and the status lines of a run.

Pure numpy and Python: nothing here initialises Taichi or builds a Simulation.
"""
import math
import os
import signal

import pytest

import taichi_spheres as ts
from taichi_spheres import workload
from taichi_spheres.progress import Progress, status_reports
from taichi_spheres.scene import MIN_STEP_ULPS, largest_speed

ROOT = os.path.join(os.path.dirname(__file__), "..")


def one_sphere(v=(1.0, 0.0, 0.0), radius=0.05, gravity=(0.0, 0.0, 0.0), periodic=False,
               mass=None):
    return ts.Scene.from_arrays([[0.5, 0.5, 0.5]], [v], radius, gravity=gravity,
                                periodic=periodic, mass=mass)


def test_free_flight_steps_are_distance_over_the_step_move_plus_frames():
    work = workload.estimate(one_sphere(v=(1.0, 0.0, 0.0)), duration=1.0, fps=10,
                             step_fraction=0.1)
    # 1 m/s for 1 s, at most 0.1 x 0.05 m a step: 200 steps, and 11 frame ends
    assert work.frames == 11
    assert work.steps == pytest.approx(211.0)
    assert (work.fastest, work.smallest, work.v_top) == (0, 0, 1.0)
    assert not work.by_gravity and not work.by_frames


def test_gravity_speeds_up_to_a_fall_across_the_walled_box():
    g = 9.81
    walled = workload.estimate(one_sphere(v=(0, 0, 0), gravity=(0, 0, -g)), 10.0, 1, 0.1)
    assert walled.v_top == pytest.approx(math.sqrt(2 * g * 1.0))
    assert walled.by_gravity
    periodic = workload.estimate(one_sphere(v=(0, 0, 0), gravity=(0, 0, -g), periodic=True),
                                 10.0, 1, 0.1)
    assert periodic.v_top == pytest.approx(g * 10.0)        # no floor: no bound
    assert periodic.steps > walled.steps


def test_the_bundled_scenes_stay_far_below_the_limit():
    for name in ("seed_five", "gas", "pour", "polydisperse"):
        scene = ts.load_scene(os.path.join(ROOT, "scenes", f"{name}.toml"))
        run = scene.meta["run"]
        work = workload.estimate(scene, run["duration"], run["fps"], 0.1)
        assert 100 < work.steps < workload.MAX_STEPS / 100, name
        assert workload.refusal(work) is None


def test_refusal_names_gravity_the_sphere_or_the_frames():
    by_gravity = workload.estimate(one_sphere(v=(0, 0, 0), gravity=(0, 0, -1e12)), 0.2, 30, 0.1)
    text = workload.refusal(by_gravity)
    assert "gravity [0, 0, -1e+12] m/s^2" in text and "--force" in text
    assert "sphere 0" in text                        # the smallest radius
    fast = workload.estimate(one_sphere(v=(0, 1e8, 0)), 0.2, 30, 0.1)
    assert "sphere 0 moves at 1e+08 m/s" in workload.refusal(fast)
    frames = workload.estimate(one_sphere(), 1.0, 1e9, 0.1)
    assert frames.by_frames and "fps" in workload.refusal(frames)
    long = workload.estimate(one_sphere(v=(0, 0, 0), gravity=(0, 0, -9.81)), 1e9, 30, 0.1)
    text = workload.refusal(long)
    assert "it lasts 1e+09 s of simulated time" in text and "gravity" not in text


def test_frames_fall_on_the_frame_grid_and_on_the_duration():
    assert workload.frame_count(0.5, 20) == 11             # t = 0, 0.05, ..., 0.5
    assert workload.frame_count(0.3 * 3, 10) == 10         # 0.9 within round-off of 9 frames
    assert workload.frame_count(0.52, 20) == 12            # ..., 0.5, then 0.52
    assert workload.frame_count(0.02, 20) == 2
    assert [workload.frame_time(k, 0.52, 20) for k in (0, 10, 11)] == [0.0, 0.5, 0.52]


def test_precision_problems_name_the_sphere_or_gravity():
    fast = one_sphere(v=(0, 0, 2 * largest_speed("f32")))
    work = workload.estimate(fast, 0.2, 30, 0.1)
    assert workload.precision_problems(fast, "f64", work) == []
    (problem,) = workload.precision_problems(fast, "f32", work)
    assert problem.startswith("speed of sphere 0") and "f32" in problem
    heavy_g = one_sphere(v=(0, 0, 0), gravity=(0, 0, -1e37))
    problems = workload.precision_problems(heavy_g, "f32", workload.estimate(heavy_g, 1, 1, 0.1))
    assert any(p.startswith("gravity [0, 0, -1e+37]") for p in problems)
    light = one_sphere(mass=1e-40)
    problems = workload.precision_problems(light, "f32", workload.estimate(light, 1, 1, 0.1))
    assert problems and problems[0].startswith("mass of sphere 0")


def test_a_radius_too_small_for_f32_is_named():
    scene = one_sphere(radius=1e-6)
    work = workload.estimate(scene, 1e-3, 1000, 0.1)
    assert workload.precision_problems(scene, "f64", work) == []
    (problem,) = workload.precision_problems(scene, "f32", work)
    assert problem.startswith("radius of sphere 0 (1e-06 m) is below what f32 can simulate")
    assert f"{MIN_STEP_ULPS} units in the last place" in problem


@pytest.mark.parametrize("seconds, text", [(0.5, "about 0.5 s"), (110, "about 110 s"),
                                           (1500, "about 25 min"), (7200, "about 2 h"),
                                           (3e5, "about 3.5 days"), (math.inf, "forever")])
def test_rough_duration(seconds, text):
    assert workload.rough_duration(seconds) == text


class FakeSim:
    time = 0.25
    stats = dict(steps=1234, pair_collisions=5, wall_collisions=6)


def test_status_line_with_quiet_and_before_the_simulation(capsys):
    progress = Progress(duration=1.0, frames=11, quiet=True, status_every=1e9, steps=5e4)
    progress.status()
    assert capsys.readouterr().err.startswith("status: setting up")
    progress.attach(FakeSim())
    progress.frame_done(2)                     # quiet, not due: nothing
    assert capsys.readouterr().err == ""
    progress.status_every = 0.0
    progress.frame_done(3)                     # quiet, due: a status line
    err = capsys.readouterr().err
    assert err.startswith("status: frame 4/11") and "steps=1234 of ~5.0e+04" in err


@pytest.mark.skipif(not hasattr(signal, "SIGUSR1"), reason="no SIGUSR1 here")
def test_sigusr1_prints_a_status_line_while_reporting(capsys):
    progress = Progress(duration=1.0, frames=11, quiet=True, status_every=1e9)
    progress.attach(FakeSim())
    before = signal.getsignal(signal.SIGUSR1)
    with status_reports(progress):
        os.kill(os.getpid(), signal.SIGUSR1)      # handled before the next statement
    assert "status: frame 0/11  t=0.250/1 s" in capsys.readouterr().err
    assert signal.getsignal(signal.SIGUSR1) == before
