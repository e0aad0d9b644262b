"""The energy-, overlap- and rate-measuring tools (tools/warm_start_energy.py,
tools/bed_energy.py, tools/bed_rest.py, tools/step_overlaps.py, tools/silo_seeds.py,
tools/solver_convergence.py, tools/bed_conditioning.py, tools/pile_rest.py): bad options are usage errors before any run, their
tables say what was measured, and their arithmetic holds on cases with known answers.
No timings or measured values are asserted (the tools are the measurement)."""
import argparse
import os
import sys
import types

import numpy as np
import pytest

from taichi_spheres.builders import box_pile

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tools"))

import bed_conditioning  # noqa: E402  (tools/bed_conditioning.py)
import bed_energy  # noqa: E402  (tools/bed_energy.py)
import bed_rest  # noqa: E402  (tools/bed_rest.py)
import bed_steps  # noqa: E402  (tools/bed_steps.py)
import pile_rest  # noqa: E402  (tools/pile_rest.py)
import silo_seeds  # noqa: E402  (tools/silo_seeds.py)
import row_activity  # noqa: E402  (tools/row_activity.py)
import solver_convergence  # noqa: E402  (tools/solver_convergence.py)
import settings_tradeoff  # noqa: E402  (tools/settings_tradeoff.py)
import silo_overlaps  # noqa: E402  (tools/silo_overlaps.py)
import step_overlaps  # noqa: E402  (tools/step_overlaps.py)
import warm_start_energy  # noqa: E402  (tools/warm_start_energy.py)


@pytest.mark.parametrize("tool, argv, words", [
    (warm_start_energy, ["--ratios", "0"], "ratios must be > 0"),
    (warm_start_energy, ["--frictions", "-0.1"], "frictions >= 0"),
    (warm_start_energy, ["--steps", "0"], "steps >= 1"),
    (step_overlaps, ["--start", "2"], "--start < --duration"),
    (step_overlaps, ["--every", "0"], "--every >= 1"),
    (step_overlaps, ["--duration", "-1"], "--start < --duration"),
    (step_overlaps, ["--variants", "fast=relax=1.8"], "unknown tuning field 'relax'"),
    (settings_tradeoff, ["--variants", "=relaxation=1.8"], "a variant is NAME=FIELD=VALUE"),
    (settings_tradeoff, ["--fills", "-1"], "--fills must be >= 0"),
    (settings_tradeoff, ["--variants", "long=step_fraction=1.5"],
     "variant 'long': step_fraction must be a number in (0, 1], got 1.5"),
    (settings_tradeoff, ["--variants", "long=step_fraction=True"],
     "variant 'long': step_fraction must be a number in (0, 1], got True"),
    (silo_overlaps, ["--first", "0"], "--first must be >= 1"),
    (bed_steps, ["--start", "2"], "--start must be >= 0 and < --end"),
    (bed_steps, ["--step-fraction", "0"], "step_fraction must be a number in (0, 1]"),
    (bed_steps, ["--tuning", "relax=1"], "unknown tuning field 'relax'"),
    (row_activity, ["--at", "-1"], "--at times must be >= 0"),
    (row_activity, ["--threshold", "1"], "--threshold must be in [0, 1)"),
    (row_activity, ["--scene", os.path.join(os.path.dirname(__file__), "..", "scenes",
                                            "heap.toml")], "the replay has no friction rows"),
    (silo_overlaps, ["--variants", "=--substeps"], "a variant is NAME=OPTIONS"),
    (silo_overlaps, ["--variants", "fine=--step-fractions 0.05"],
     "variant 'fine': options tools/silo.py does not take"),
    (silo_seeds, ["--seeds", "1"], "at least two seeds"),
    (silo_seeds, ["--jobs", "0"], "--jobs must be >= 1"),
    (silo_seeds, ["--variants", "=--substeps"], "a variant is NAME=OPTIONS"),
    (silo_seeds, ["--variants", "LAMMPS=--substeps"], "NAME not LAMMPS"),
    (silo_seeds, ["--variants", "fine=--step-fractions 0.05"],
     "variant 'fine': options tools/silo.py does not take"),
    (bed_rest, ["--until", "2"], "--until must be at least 3 s"),
    (bed_rest, ["--every", "0.3"], "--every must divide 1 s and --until"),
    (bed_rest, ["--until", "4.5", "--every", "1"], "--every must divide 1 s and --until"),
    (bed_rest, ["--fills", "-1"], "--fills and --lammps-fills must be >= 0"),
    (bed_rest, ["--lammps-fills", "-1"], "--fills and --lammps-fills must be >= 0"),
    (bed_rest, ["--every", "0"], "--every must divide 1 s"),
    (bed_rest, ["--until", "nan"], "--until must be at least 3 s"),
    (bed_rest, ["--no-lammps", "--lammps-only"], "--no-lammps runs no LAMMPS"),
    (bed_rest, ["--lammps-only", "--lammps-json", ""], "--lammps-only saves"),
    (bed_conditioning, ["--at", "0"], "--at takes times > 0"),
    (bed_conditioning, ["--at", "nan"], "--at takes times > 0"),
    (pile_rest, ["--n-side", "1"], "--n-side must be >= 2"),
    (pile_rest, ["--settle", "0"], "--settle must be a finite time > 0 s"),
    (pile_rest, ["--settle", "nan"], "--settle must be a finite time > 0 s"),
    (pile_rest, ["--settle", "inf"], "--settle must be a finite time > 0 s"),
    (pile_rest, ["--seeds", "1", "-2"], "--seeds must be >= 0"),
    (bed_conditioning, ["--truth", "0"], "--truth must be at least 1")])
def test_tools_refuse_bad_options(tool, argv, words, capsys):
    with pytest.raises(SystemExit) as exit_info:
        tool.main(argv)
    assert exit_info.value.code == 2
    assert words in capsys.readouterr().err


def test_warm_start_energy_table_has_a_row_per_case():
    rows = {(100.0, 0.5, "off"): dict(growth=9.66e-2, step=34, scaled=0),
            (100.0, 0.5, "on"): dict(growth=1.73e-4, step=49, scaled=36)}
    text = warm_start_energy.report(rows, 300)
    assert "| 100 | 0.5 | off | 9.7e-02 | 34 | 0 |" in text
    assert "| 100 | 0.5 | on | 1.7e-04 | 49 | 36 |" in text
    assert "next 300 steps" in text


def test_bed_rest_finds_when_the_energy_stays_below_the_target():
    times = bed_rest.sample_times(3.0, 0.5)
    assert list(times) == [0.5, 1.0, 1.5, 2.0, 2.5, 3.0]
    assert bed_rest.settled_from([1e-3, 1e-5, 1e-7, 2e-6, 1e-7, 1e-8], times) == "2.5"
    assert bed_rest.settled_from([1e-7] * 6, times) == "0.5"
    assert bed_rest.settled_from([1e-7] * 5 + [2e-6], times) == "not by 3"
    assert bed_rest.whole_seconds(times) == [3, 5]
    assert [bed_rest.last_second(t, times) for t in times] == [False] * 3 + [True] + [False] * 2


def test_bed_rest_motion_is_per_diameter_and_the_table_says_so():
    x0 = np.zeros((4, 3))
    x1 = np.array([[0.0, 0, 0], [0.01, 0, 0], [0, 0.02, 0], [0, 0, 0.04]])
    v = np.array([[0.0, 0, 0], [3e-3, 0, 0], [0, 4e-3, 0], [0, 0, 0]])
    m = bed_rest.motion(x0, x1, v, np.full(4, 0.02))
    assert m["median"] == pytest.approx(0.75) and m["largest"] == pytest.approx(2.0)
    assert m["rms_speed"] == pytest.approx(np.sqrt((9e-6 + 16e-6) / 4))
    times = bed_rest.sample_times(3.0, 1.0)
    run = dict(kinetic=[1e-3, 2e-6, 5e-7], wall=0.8, motion=m)
    args = argparse.Namespace(until=3.0, every=1.0, fills=2, lammps_fills=1, no_lammps=False,
                              write=False, section="long")
    text = bed_rest.report(args, times, {"defaults": run, "LAMMPS": dict(run, wall=None)},
                           {"taichi": [run, dict(run, kinetic=[1e-3, 5e-7, 4e-7])],
                            "LAMMPS": [dict(run, wall=None)], "none": []}, "run now")
    assert "| defaults | 2.0e-06 | 5.0e-07 | 3 | 7.5e-01 |" in text
    assert "| LAMMPS | 2.0e-06 | 5.0e-07 | 3 |" in text
    assert "| taichi, 2 fills: median (largest) | 1.2e-06 (2.0e-06) | 4.5e-07 (5.0e-07) | " \
        "fills at most 1e-6 at each: 1, 2 |" in text
    assert "| LAMMPS, 1 fills: median (largest) | 2.0e-06 (2.0e-06) |" in text
    assert "none" not in text and text.count("| - |") == 2
    assert "`python tools/bed_rest.py --until 3 --every 1 --fills 2 --lammps-fills 1 " \
        "--section long`" in text
    cap = bed_rest.DEFAULT_CAP
    table = bed_rest.accuracy_table({cap: dict(motion=m, sweeps=float(cap), wall=0.6),
                                     3 * cap: dict(motion=m, sweeps=2.904 * cap, wall=1.5)},
                                    3.0, True)
    assert f"| {cap} (default) | {cap} | 7.5e-01 |" in table
    assert f"| {3 * cap} | {2.904 * cap:.0f} |" in table and "checked, the same" in table
    assert "NOT the same" in bed_rest.accuracy_table({}, 3.0, False)
    growth = bed_rest.growth_table({100: [1e-5, 1e-5, 2e-5, 4e-5], 300: [1e-5] * 4,
                                    30: [0.0, 0.0, 0.0, 1e-5]}, 300, 9e-6)
    assert "| 100 | 1.0e-05 | 1.0e-05 | 2.0e-05 | 4.0e-05 | 2.00 |" in growth
    assert "| 300 | 1.0e-05 | 1.0e-05 | 1.0e-05 | 1.0e-05 | 1.00 |" in growth
    assert "| 30 | 0.0e+00 | 0.0e+00 | 0.0e+00 | 1.0e-05 | - |" in growth and "9.0e-06 m/s" in growth
    every = bed_rest.growth_table({100: [1e-5, 2e-5, 4e-5, 8e-5]}, 300, 9e-6, every=2)
    assert "| step 2 | step 4 |" in every and "| 100 | 2.0e-05 | 8.0e-05 | 2.00 |" in every


def test_bed_rest_defaults_pass_its_checks_and_name_the_command():
    args = argparse.Namespace(
        until=5.0, every=0.25, fills=8, lammps_fills=None, no_lammps=False,
        lammps_only=False, lammps_json="x.json", write=True, section="bed-rest")
    bed_rest.check_sampling(args, None)          # would call ap.error on a bad option
    assert bed_rest.command_text(args) == "python tools/bed_rest.py --write"
    args.until, args.no_lammps, args.write = 6.0, True, False
    assert bed_rest.command_text(args) == "python tools/bed_rest.py --until 6 --no-lammps"


def test_bed_rest_keeps_each_lammps_run_once_and_reuses_it(tmp_path, monkeypatch):
    runs = []
    monkeypatch.setattr(bed_rest, "run_lammps", lambda scene, times: runs.append(1) or
                        dict(kinetic=[len(runs)]))
    scene = types.SimpleNamespace(x=np.zeros((2, 3)), v=np.zeros((2, 3)), radius=np.ones(2),
                                  mass=np.ones(2), box_lo=np.zeros(3), box_hi=np.ones(3),
                                  gravity=np.array([0, 0, -9.81]), restitution=0.5,
                                  wall_restitution=0.5)
    other = types.SimpleNamespace(**dict(vars(scene), restitution=0.9))
    path = str(tmp_path / "runs.json")
    times = bed_rest.sample_times(3.0, 1.0)
    assert bed_rest.lammps_result(scene, times, path) == (dict(kinetic=[1]), "run now")
    assert bed_rest.lammps_result(scene, times, path)[0] == dict(kinetic=[1])
    assert bed_rest.lammps_result(other, times, path)[0] == dict(kinetic=[2])
    assert bed_rest.lammps_result(scene, times[:2], path)[0] == dict(kinetic=[3])
    assert len(runs) == 3 and len(bed_rest.load_runs(path)) == 3
    assert bed_rest.load_runs(str(tmp_path / "none.json")) == []


def test_bed_energy_table_quotes_lammps_from_its_stored_run():
    rows = {(100, 100, 1.0): dict(ke=[3e-3, 4e-3, 2e-3, 1.5e-3], sweeps=100.0, wall=1.25)}
    text = bed_energy.report("scenes/pour.toml", 300.0, rows)
    assert "| 100 / 100 | 1 | 3.00e-03 | 4.00e-03 | 2.00e-03 | 1.50e-03 | 5.0e-06 | 100 | 1.25 |" \
        in text
    # the stored LAMMPS pour (docs/peer_lammps_pour_lammps.json) has both phase ends
    assert "at 1 s" in text and "at 2 s" in text and "LAMMPS" in text


def test_step_overlaps_table_names_the_command_and_both_settings():
    args = argparse.Namespace(scene="scenes/pour.toml", start=1.0, duration=2.0, every=1,
                              write=True, section="step-overlaps-bed",
                              variants=step_overlaps.VARIANTS)
    row = dict(brute=6.6e-4, when=1.138, reported=6.6e-4, steps=2008, substeps=2008,
               wall=1.25, velocity=100.0, position=97.5, hits=0, kinetic=4.7e-6)
    text = step_overlaps.report(args, {"defaults": row,
                                       "former defaults": dict(row, substeps=3000)})
    assert "`python tools/step_overlaps.py --start 1 --every 1 --section step-overlaps-bed " \
        "--write`" in text
    assert "| defaults | 6.60e-04 (1.138) | 6.60e-04 | 2008 | 2008 | 1.25 | 100.0 / 97.5 | 0 " \
        "| 4.70e-06 |" in text
    assert "| former defaults | 6.60e-04 (1.138) | 6.60e-04 | 2008 | 3000 |" in text
    assert "- former defaults: `Tuning().with_(relaxation=1.0, position_iterations=100, " \
        "substeps=False, step_scaled_sweeps=False, position_extension=0)`" in text


def test_step_overlaps_and_settings_tradeoff_name_their_variants():
    """A variant's settings are Tuning fields; the command line names non-default ones."""
    assert step_overlaps.parse_variant("fast=relaxation=1.8 shock_propagation=on") == \
        ("fast", {"relaxation": 1.8, "shock_propagation": "on"})
    with pytest.raises(ValueError, match="unknown tuning field 'relax'"):
        step_overlaps.parse_variant("fast=relax=1.8")
    with pytest.raises(ValueError, match="not FIELD=VALUE"):
        step_overlaps.parse_variant("fast=relaxation")
    args = argparse.Namespace(variants=["a=relaxation=1.5"], every=1, write=False, fills=3)
    row = dict(wall=0.9, brute=5e-5, velocity=60.0, position=58.0, kinetic=2e-6, ball=1e-3,
               ball_step=1, rise=0.0,
               fills=dict(bed=1.1, fastest=0.95, slowest=1.3, steps=450, fall=4.2,
                          kinetic=[3e-6, 5e-7, 8e-7], overlaps=[4e-5, 9e-5, 2e-5]))
    text = settings_tradeoff.report(args, {"a": row})
    assert '`python tools/settings_tradeoff.py --variants "a=relaxation=1.5" --fills 3`' \
        in text
    assert "| a | 0.9 | 1.1 (0.95-1.3) | 5.00e-05 | 9.00e-05 (4.0e-05), 0 of 3 | 60 / 58 | " \
        "2.0e-06 | " \
        "8.0e-07 (5.0e-07-3.0e-06), 2 of 3 | 4.2 | 1.0e-03 (1) | 0.0e+00 |" in text
    assert "- a: `Tuning().with_(relaxation=1.5)`" in text


def test_silo_overlaps_table_gives_the_first_steps_and_the_rest():
    rows = {"substeps": dict(early=[2.8e-3, 2.4e-4], late=2.3e-5, when=0.541, steps=800)}
    text = silo_overlaps.report([("substeps", ["--substeps"])], rows, 2,
                                "python tools/silo_overlaps.py --first 2")
    assert "`python tools/silo_overlaps.py --first 2`" in text
    assert "| substeps | 2.8e-03, 2.4e-04 | 2.3e-05 (0.541) | 800 |" in text


def test_silo_seeds_table_gives_each_rate_and_the_spread():
    text = silo_seeds.report([1, 2], {"defaults": [(0.16, 30.0), (0.15, 32.0)],
                                      "substeps": [(0.14, 20.0), (0.15, 22.0)]})
    assert "`python tools/silo_seeds.py --seeds 1 2`" in text
    assert "| defaults | 0.1600 | 0.1500 | 0.1550 | 0.0071 | 0.0050 | 31.0 |" in text
    assert "| substeps | 0.1400 | 0.1500 | 0.1450 | 0.0071 | 0.0050 | 21.0 |" in text


def test_silo_seeds_variants_and_lammps_are_named_in_the_command():
    variants = [silo_seeds.parse_variant(v) for v in ["defaults=", "fine=--step-fraction 0.05"]]
    assert variants == [("defaults", []), ("fine", ["--step-fraction", "0.05"])]
    rows = {"defaults": [(0.16, 30.0), (0.15, 30.0)], "fine": [(0.15, 60.0), (0.15, 60.0)],
            "LAMMPS": [(0.15, 66.0), (0.14, 66.0)]}
    text = silo_seeds.report([1, 2], rows, variants, jobs=2)
    assert '--variants "defaults=" "fine=--step-fraction 0.05" --lammps --jobs 2`' in text
    assert "2 runs at a time" in text
    assert "| fine | 0.1500 | 0.1500 | 0.1500 | 0.0000 | 0.0000 | 60.0 |" in text
    assert "| LAMMPS | 0.1500 | 0.1400 |" in text


def test_solver_convergence_splits_an_error_into_aggregate_means_and_the_rest():
    """One error per aggregate is carried whole by the aggregates' means; an error that
    alternates within every aggregate not at all; the random share is aggregates over
    spheres. Spheres of a bed split into cubes: a uniform error is smooth on every scale,
    and one sphere's error is all in the top 1 %."""
    labels = np.repeat(np.arange(4), 5)
    smooth = np.repeat(np.arange(4.0), 5)[:, None] * np.array([[1.0, 2.0, 0.5]])
    assert solver_convergence.smooth_share(smooth, labels) == pytest.approx((1.0, 0.2))
    rough = np.tile([1.0, -1.0], 10)[:, None] * np.ones((1, 3))
    rough[4::5] = 0.0          # five per aggregate: +1, -1, +1, -1, 0 (mean 0)
    assert solver_convergence.smooth_share(rough, labels)[0] == pytest.approx(0.0, abs=1e-15)
    x = np.stack(np.meshgrid(*(np.arange(10.0),) * 3, indexing="ij"), -1).reshape(-1, 3)
    p = dict(a=np.arange(len(x)), b=np.full(len(x), -1), x=x, d=1.0)
    truth = np.zeros((len(x), 3))
    smooth_rows, top = solver_convergence.smoothness(p, truth + 1.0, truth)
    assert [row[2] for row in smooth_rows] == pytest.approx([1.0] * len(smooth_rows))
    assert smooth_rows[0][1] == 8.0             # cubes of 2 diameters: 2 x 2 x 2 spheres
    one = truth.copy()
    one[17] = 3.0
    assert dict(solver_convergence.smoothness(p, one, truth)[1])[1] == pytest.approx(1.0)


def test_row_activity_replay_skips_only_rows_that_would_change_nothing():
    """Two spheres over the floor: one falling onto it (its row takes an impulse and
    stays busy), one moving up (its row changes nothing from the first sweep on). Plain
    sweeps converge in two; the second sweep's update of the free row is the one
    exactly skippable update, and skipping it gives the same velocities."""
    from taichi_spheres.config import Rules
    p = dict(a=np.array([0, 1]), b=np.array([-1, -1]), normal=np.array([[0, 0, 1.0]] * 2),
             meff=np.array([2.0, 2.0]), target=np.zeros(2), lam=np.zeros(2),
             v=np.array([[0, 0, -1.0], [0, 0, 1.0]]), inv_mass=np.array([0.5, 0.5]),
             order=np.array([0, 1]))
    prob = solver_convergence.Problem(p)
    rules = Rules(relaxation=1.0)
    counted = row_activity.replay(prob, rules, 1e-9)
    skipped = row_activity.replay(prob, rules, 1e-9, "exact")
    assert (counted["updates"], counted["skipped"], counted["sweeps"]) == (4, 1, 2)
    assert (skipped["updates"], skipped["skipped"]) == (4, 1)
    assert counted["v"].tolist() == skipped["v"].tolist() == [[0, 0, 0], [0, 0, 1]]


def test_direct_solve_of_a_stack_on_the_floor_is_exact():
    """Two spheres stacked on the floor, both falling at 1 m/s: the Delassus matrix is
    the one the sweeps apply, and the active-set solve, started with the floor row
    alone, adds the pair row and stops both: the floor row carries both momenta (6 N s),
    the pair row the top sphere's (4 N s)."""
    p = dict(a=np.array([0, 1]), b=np.array([-1, 0]), normal=np.array([[0, 0, 1.0]] * 2),
             meff=np.array([1.0, 1.0]), target=np.zeros(2), lam=np.zeros(2),
             v=np.array([[0, 0, -1.0], [0, 0, -1.0]]), inv_mass=np.array([0.5, 0.25]),
             order=np.array([0, 1]), h=1e-3, d=1.0)
    prob = solver_convergence.Problem(p)
    W = solver_convergence.delassus(prob)
    probe = np.array([0.3, -0.7])
    assert W @ probe == pytest.approx(prob.gather(prob.scatter(probe)))
    start = np.array([True, False])            # the pair row must join the active set
    lam, solves, seconds, fill, done = solver_convergence.active_set_solve(
        W, prob.linear, start, 0.0)
    assert done == "yes" and solves == 2 and len(seconds) == 2 and fill >= 3
    assert lam == pytest.approx([6.0, 4.0])
    assert prob.velocities(lam) == pytest.approx(np.zeros((2, 3)))
    converged, warm = solver_convergence.direct_rows(prob, lam, np.zeros((2, 3)), [0.0])
    assert converged[0] == "converged" and warm[0] == "warm start"
    assert converged[2:4] == (1, "yes") and converged[6]["max"] == pytest.approx(0.0, abs=1e-15)
    # no warm impulse: the floor row joins after the first (empty) solve, the pair row
    # after the second
    assert warm[2:4] == (3, "yes") and warm[6]["max"] == pytest.approx(0.0, abs=1e-15)


def test_direct_solve_reports_a_singular_block():
    """Two identical rows (one sphere on the floor, counted twice) make W_AA exactly
    singular without a compliance; with a compliance the solve converges, the impulse
    split between the two rows."""
    p = dict(a=np.array([0, 0]), b=np.array([-1, -1]), normal=np.array([[0, 0, 1.0]] * 2),
             meff=np.array([1.0, 1.0]), target=np.zeros(2), lam=np.zeros(2),
             v=np.array([[0, 0, -1.0]]), inv_mass=np.array([1.0]), order=np.array([0, 1]),
             h=1e-3, d=1.0)
    prob = solver_convergence.Problem(p)
    W = solver_convergence.delassus(prob)
    both = np.array([True, True])
    assert solver_convergence.active_set_solve(W, prob.linear, both, 0.0)[4] == "singular"
    lam, solves, _, _, done = solver_convergence.active_set_solve(W, prob.linear, both, 1e-9)
    assert done == "yes" and lam.sum() == pytest.approx(1.0, rel=1e-6)


def test_variants_may_set_the_step_fraction():
    """A variant's step_fraction goes to the Simulation, its other fields to Tuning, and
    the table says so."""
    from taichi_spheres.config import Tuning
    name, changes = step_overlaps.parse_variant("long=step_fraction=0.2 position_iterations=100")
    assert name == "long"
    options = step_overlaps.simulation_options(changes)
    assert options == dict(step_fraction=0.2, tuning=Tuning().with_(position_iterations=100))
    assert step_overlaps.simulation_options({"relaxation": 1.5}) == \
        dict(tuning=Tuning().with_(relaxation=1.5))
    assert step_overlaps.variant_text(changes) == \
        "step_fraction=0.2, tuning=Tuning().with_(position_iterations=100)"
    assert step_overlaps.variant_text({"relaxation": 1.5}) == "Tuning().with_(relaxation=1.5)"


def test_a_variants_step_fraction_reaches_every_simulation_it_builds(monkeypatch):
    """settings_tradeoff's runs (the bed step by step, the fills, the settling block,
    the settled block and the heavy ball's drop) each build their Simulation with the
    variant's step_fraction and tuning."""
    import taichi_spheres as ts
    from taichi_spheres.config import Tuning
    seen = []

    def fake(*_, **keywords):
        seen.append(keywords)
        raise RuntimeError("no run")
    monkeypatch.setattr(ts, "Simulation", fake)
    changes = dict(step_fraction=0.2, position_iterations=100)
    options = step_overlaps.simulation_options(changes)
    tuning = Tuning().with_(position_iterations=100)
    runs = [lambda: step_overlaps.run(None, 1.0, 2.0, 1, changes),
            lambda: settings_tradeoff.pour_fills(changes, 1),
            lambda: settings_tradeoff.block_energy_rise(options),
            lambda: warm_start_energy.settled_block(0.0, tuning, 0.2)]
    for run in runs:
        with pytest.raises(RuntimeError):
            run()
    block = ts.builders.fcc_block((4, 4, 4), radius=warm_start_energy.R, restitution=0.5)
    with pytest.raises(RuntimeError):
        settled = types.SimpleNamespace(x=block.x, v=block.v, mass=block.mass,
                                        radius=block.radius)
        warm_start_energy.drop(block, settled, 8.0, "auto", 1, tuning, 0.2)
    assert len(seen) == 5
    assert all(k["step_fraction"] == 0.2 for k in seen)
    assert all(k["tuning"].physics.position_iterations == 100 for k in seen)


def test_settings_tradeoff_bed_overlap_is_the_largest_after_any_step():
    """bed_overlap restores the checkpoint and steps to the end, keeping the largest
    overlap a step reported."""
    class Steps:
        def __init__(self):
            self.left, self.last_step, self.restored = [2e-5, 9e-5, 4e-5], {}, None

        def restore(self, checkpoint):
            self.restored = checkpoint

        def step_toward(self, t_end):
            if not self.left:
                return 0.0
            self.last_step = {"max_overlap": self.left.pop(0)}
            return 0.01
    sim = Steps()
    assert settings_tradeoff.bed_overlap(sim, "at 1 s", 2.0) == 9e-5
    assert sim.restored == "at 1 s" and not sim.left


def test_bed_steps_lists_the_steps_above_the_threshold_with_their_position_pass():
    """bed_steps.steps_above: each step leaving more than the threshold, with its sweeps,
    its position cap and the position residual x h / d; and the largest overlap."""
    field = lambda value: {None: value}     # noqa: E731  (a 0-d field's [None])
    solver = types.SimpleNamespace(cap_w=field(100), residual=field(0.0))
    steps = [dict(h=0.01, max_overlap=5e-5, contact_iterations=40, position_iterations=30),
             dict(h=0.02, max_overlap=2e-4, contact_iterations=100, position_iterations=100)]

    class Sim:
        scene = types.SimpleNamespace(radius=np.array([0.01, 0.02]))
        time, last_step = 1.0, {}

        def debug_view(self):
            return types.SimpleNamespace(solver=solver)

        def step_toward(self, t_end):
            if not steps:
                return 0.0
            self.last_step = steps.pop(0)
            self.time += self.last_step["h"]
            solver.residual[None] = 3e-4 if self.last_step["h"] > 0.015 else 1e-5
            return self.last_step["h"]
    rows, worst = bed_steps.steps_above(Sim(), 2.0, 1e-4)
    assert worst == 2e-4
    assert rows == [(pytest.approx(1.03), 0.02, 100, 100, 100,
                     pytest.approx(3e-4 * 0.02 / 0.02), 2e-4)]


def test_bed_conditioning_spectrum_counts_rank_and_small_eigenvalues():
    """Eigenvalues at most 1e-10 of the largest are the null space; the smallest nonzero
    one is reported over the largest; those below 1e-3 of it are counted."""
    out = bed_conditioning.spectrum([0.0, 1e-12, 1e-4, 1.0, 2.0])
    assert out["rank"] == 3 and out["largest"] == 2.0
    assert out["smallest"] == pytest.approx(5e-5) and out["small"] == 1
    assert bed_conditioning.spectrum([])["rank"] == 0


def test_bed_conditioning_of_a_stack_on_the_floor():
    """Two spheres stacked on the floor (1/m = 0.5 and 0.25 1/kg), both rows active: W =
    [[0.5, -0.5], [-0.5, 0.75]] 1/kg, full rank, eigenvalues (1.25 -+ sqrt(1.0625)) / 2;
    a third row repeating the floor row is redundant (rank 2 of 3)."""
    p = dict(a=np.array([0, 1]), b=np.array([-1, 0]), normal=np.array([[0, 0, 1.0]] * 2),
             meff=np.array([1.0, 1.0]), target=np.zeros(2), lam=np.zeros(2),
             v=np.zeros((2, 3)), inv_mass=np.array([0.5, 0.25]), order=np.array([0, 1]))
    out = bed_conditioning.active_spectrum(solver_convergence.Problem(p), np.array([6.0, 4.0]))
    low, high = (1.25 - 1.0625 ** 0.5) / 2, (1.25 + 1.0625 ** 0.5) / 2
    assert (out["active"], out["rank"]) == (2, 2)
    assert out["largest"] == pytest.approx(high) and out["smallest"] == pytest.approx(low / high)
    p.update(a=np.array([0, 1, 0]), b=np.array([-1, 0, -1]), normal=np.array([[0, 0, 1.0]] * 3),
             meff=np.ones(3), target=np.zeros(3), lam=np.zeros(3), order=np.arange(3))
    out = bed_conditioning.active_spectrum(solver_convergence.Problem(p),
                                           np.array([3.0, 4.0, 3.0]))
    assert (out["active"], out["rank"]) == (3, 2)
    row = dict(out, at=6.0, rows=3, dofs=6, exact_speed=1e-3, engine_speed=2e-3, sweeps=100,
               error=1.5e-3, residual=1e-6)
    assert bed_conditioning.row_text(row).startswith("| 6 | 3 | 3 | 2 | 6 | 1 | 4 |")


def test_pile_rest_tells_free_sliders_from_spheres_still_settling():
    """Of the spheres faster than 1e-6 m/s at the end of the hold, those whose velocity
    did not change over the last second slide freely; drift is the largest
    displacement / diameter, of all spheres and of the others; overlap the largest at
    any sample (pairs and box walls) / diameter."""
    scene = box_pile(2, friction=0.0, seed=1)
    assert scene.n == 12 and np.allclose(scene.box_hi, (0.055, 0.055, 0.3))
    d = 2 * pile_rest.RADIUS
    x0 = np.array([[0.01, 0.01, 0.01], [0.04, 0.01, 0.01], [0.01, 0.04, 0.01]])
    v_prev = np.array([[0, 2e-6, 0], [3e-6, 0, 0], [0, 0, 1e-7]], float)
    v1 = np.array([[0, 2e-6, 0], [2e-6, 0, 0], [0, 0, 1e-7]], float)   # sphere 2: slow
    x1 = x0 + np.array([[0, 2e-5, 0], [4e-6, 0, 0], [0, 0, 0]])
    samples = [(x0, np.zeros((3, 3)))] + [(x1, v_prev), (x1, v1)]
    out = pile_rest.hold_report(samples, scene)
    assert (out["moving"], out["free"]) == (2, 1)
    assert out["largest_speed"] == pytest.approx(2e-6)
    assert out["drift"] == pytest.approx(2e-5 / d) and out["drift_others"] == pytest.approx(4e-6 / d)
    assert out["overlap"] == 0.0
    x1 = x1.copy()
    x1[2] = x1[0] + (0, 0.0199, 0)           # centres 0.0199 m apart: 1e-4 m of overlap
    assert pile_rest.hold_report(samples[:2] + [(x1, v1)], scene)["overlap"] == \
        pytest.approx(1e-4 / d)
    x1[2] = (0.0099, 0.04, 0.01)             # 1e-4 m into the wall at x = 0
    assert pile_rest.hold_report(samples[:2] + [(x1, v1)], scene)["overlap"] == \
        pytest.approx(1e-4 / d)


def test_pile_rest_table_names_each_run_and_leaves_lammps_counters_empty():
    """A row per run and fill, with '-' where LAMMPS has no counter; the command line
    without --write heads the section."""
    r = dict(kinetic=(1e-9, 2e-10), moving=3, free=1, largest_speed=2e-6, drift=1e-4,
             drift_others=5e-5, overlap=1e-5, hits=0, wall=1.25)
    assert pile_rest.row("taichi_spheres, frictionless", 2, r) == (
        "| taichi_spheres, frictionless | 2 | 1.0e-09 | 2.0e-10 | 3 | 1 | 2.0e-06 | 1.0e-04 | "
        "5.0e-05 | 1.0e-05 | 0 | 1.2 |")
    assert pile_rest.row("LAMMPS", 1, dict(r, hits=None, wall=None)).endswith("| - | - |")
    args = argparse.Namespace(n_side=10, settle=6.0)
    text = pile_rest.report(args, [("LAMMPS", 1, dict(r, hits=None, wall=None))],
                            ["--seeds", "1", "--write"])
    assert "`python tools/pile_rest.py --seeds 1`" in text
    assert "300 spheres of d = 20 mm" in text and "held from 6 to 16 s" in text
