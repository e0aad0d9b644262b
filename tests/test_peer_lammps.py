"""tools/peer_lammps.py: its overlap check finds every overlapping pair and wall, its
LAMMPS set-up sends the lattice scene's commands and a scene file's walls and gravity,
and a saved LAMMPS run of --scene mode is reused only for the same initial state.
Neither Taichi nor LAMMPS runs here (a recording stand-in takes LAMMPS's commands)."""
import argparse
import json
import os
import sys
import types

import numpy as np
import pytest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tools"))

import peer_lammps  # noqa: E402  (tools/peer_lammps.py)
import taichi_spheres as ts  # noqa: E402

POUR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "scenes", "pour.toml")


class RecordingLammps:
    """Stands in for lammps.lammps: keeps the commands it is sent."""

    def __init__(self, cmdargs):
        self.log = [("args", cmdargs)]

    def command(self, text):
        self.log.append(text)

    def create_atoms(self, n, ids, types_, x, v):
        self.log.append(("create_atoms", n))


@pytest.mark.parametrize("n", [1, 2, 60, 500])
def test_near_pairs_is_brute_force(n):
    rng = np.random.default_rng(n)
    x = rng.random((n, 3)) * [0.5, 0.3, 1.0]
    cut = 0.12
    i, j = peer_lammps.near_pairs(x, cut)
    d = np.linalg.norm(x[:, None] - x[None], axis=2)
    want = set(zip(*map(np.ndarray.tolist, np.nonzero(np.triu(d < cut, 1)))))
    assert set(zip(i.tolist(), j.tolist())) == want
    assert len(i) == len(want)


def test_largest_overlaps():
    """A pair 1 mm into each other (r = 10, 20 mm) and a sphere 2 mm into the top wall."""
    x = np.array([[0.1, 0.1, 0.1], [0.1, 0.1, 0.129], [0.3, 0.3, 0.988]])
    r = np.array([0.01, 0.02, 0.014])
    pair, wall = peer_lammps.largest_overlaps(x, r, np.zeros(3), np.ones(3))
    assert pair == pytest.approx(0.001 / 0.03)
    assert wall == pytest.approx(0.002 / 0.028)
    assert peer_lammps.largest_overlaps(x[:1], r[:1], np.zeros(3), np.ones(3)) == (0.0, 0.0)


def test_lattice_setup_commands():
    """The lattice scene keeps its per-type radius and density and its walls at 0 and hi."""
    x, v, hi = peer_lammps.initial_state(1000, 12345)
    log = peer_lammps.lammps_setup(types.SimpleNamespace(lammps=RecordingLammps), x, v, hi,
                                   5e9, 0.3, 5e-6, 1).log
    model = ("hertz/material 5e+09 0.9 0.3 damping coeff_restitution tangential "
             "linear_nohistory 0.0 0.0")
    for cmd in ("region box block -0.05 1.05 -0.05 1.05 -0.05 1.05", "set type 1 diameter 0.03",
                "set type 1 density 1000.0", f"pair_coeff * * {model}",
                f"fix wx all wall/gran granular {model} xplane 0.0 1.0",
                "fix grav all gravity 9.81 vector 0 0 -1", "neighbor 0.003 bin"):
        assert cmd in log


def test_scene_setup_commands(monkeypatch):
    """A scene's box, restitutions and gravity reach LAMMPS; radii and masses per atom."""
    scene = ts.load_scene(POUR).replace(wall_restitution=0.7, gravity=(0.0, -9.81, 0.0))
    written = {}
    monkeypatch.setattr(peer_lammps, "set_per_atom",
                        lambda lmp, radius, mass: written.update(radius=radius, mass=mass))
    log = peer_lammps.lammps_scene_setup(types.SimpleNamespace(lammps=RecordingLammps), scene,
                                         1, 5e9, 0.3, 5e-6).log
    assert written["radius"] is scene.radius and written["mass"] is scene.mass
    assert f"pair_coeff * * {peer_lammps.granular_model(5e9, 0.3, 0.5)}" in log
    assert (f"fix wz all wall/gran granular {peer_lammps.granular_model(5e9, 0.3, 0.7)} "
            f"zplane 0.0 1.0") in log
    assert "fix grav all gravity 9.81 vector 0 -1 0" in log
    assert not any("set type" in c for c in log if isinstance(c, str))


def _scene_args(*extra):
    ap = argparse.ArgumentParser()
    args = argparse.Namespace(scene=POUR, phases=None, threads=None, out=None,
                              lammps_threads=1, young=5e9, poisson=0.3, dt=5e-6,
                              overlap_every=10, only="taichi", lammps_json=None,
                              tuning=None, step_fraction=None)
    for key, value in extra:
        setattr(args, key, value)
    return args, ap


def test_scene_defaults():
    """--scene runs on one thread, its phases default to half the [run] duration and it."""
    args, ap = _scene_args()
    scene = peer_lammps.scene_args(args, ap)
    assert scene.n == 2000 and args.threads == 1 and args.phases == [1.0, 2.0]
    assert args.scene_file == os.path.join("scenes", "pour.toml")
    assert args.out.endswith(os.path.join("docs", "peer_lammps_pour.md"))


def test_rerun_command_keeps_the_report_file_and_tuning():
    """The report's last line reruns it into the same file with the same settings."""
    args, ap = _scene_args()
    peer_lammps.scene_args(args, ap)
    assert peer_lammps.rerun_command(args) == \
        "python tools/peer_lammps.py --scene scenes/pour.toml --phases 1 2 --only taichi"
    args.out, args.tuning = "docs/peer_lammps_pour_fast.md", dict(contact_iterations=40,
                                                                  shock_propagation="on")
    assert peer_lammps.rerun_command(args).endswith(
        "--only taichi --out docs/peer_lammps_pour_fast.md --tuning contact_iterations=40 "
        "shock_propagation=on")


def test_step_fraction_goes_to_the_simulation_and_the_rerun_command(monkeypatch, capsys):
    """--step-fraction: in (0, 1], with --out (the default report is the defaults'),
    handed to taichi_spheres' Simulation and named in the report's rerun command;
    without --scene an error."""
    import taichi_spheres as ts
    args, ap = _scene_args(("step_fraction", 0.15), ("out", "docs/peer_lammps_pour_sf.md"))
    scene = peer_lammps.scene_args(args, ap)
    assert peer_lammps.rerun_command(args).endswith(
        "--only taichi --out docs/peer_lammps_pour_sf.md --step-fraction 0.15")
    assert peer_lammps.rerun_text(args).endswith(
        "--step-fraction 0.15 --lammps-json FILE`.")
    assert peer_lammps.step_fraction_text(0.15) == ", step_fraction 0.15"
    assert peer_lammps.step_fraction_text(None) == ""
    seen = []

    def fake(*_, **keywords):
        seen.append(keywords)
        raise RuntimeError("no run")
    monkeypatch.setattr(ts, "Simulation", fake)
    for step_fraction in (0.15, None):
        with pytest.raises(RuntimeError):
            peer_lammps.run_taichi_scene(scene, [1.0, 2.0], 1, step_fraction=step_fraction)
    assert seen[0]["step_fraction"] == 0.15 and seen[1]["step_fraction"] == 0.1
    # (the run's own settings, never the scene file's [physics] values)
    assert all(k["precision"] == "f64" and k["max_sweeps"] == 32 for k in seen)
    for bad, words in (((("step_fraction", 1.5), ("out", "x.md")),
                        "--step-fraction: step_fraction must be a number in (0, 1], got 1.5"),
                       ((("step_fraction", 0.15),), "--step-fraction needs --out")):
        args, ap = _scene_args(*bad)
        with pytest.raises(SystemExit):
            peer_lammps.scene_args(args, ap)
        assert words in capsys.readouterr().err
    with pytest.raises(SystemExit):
        peer_lammps.main(["--step-fraction", "0.15", "--no-write"])
    assert "--step-fraction needs --scene" in capsys.readouterr().err


def test_saved_run_needs_the_same_scene(tmp_path):
    args, ap = _scene_args(("phases", [1.0, 2.0]))
    peer_lammps.scene_args(args, ap)
    saved = dict(settings=peer_lammps.settings(args, peer_lammps.SCENE_SAVED_KEYS),
                 result={}, overlap=[0.01, 0.02])
    path = tmp_path / "lammps.json"
    path.write_text(json.dumps(saved))
    assert peer_lammps.load_lammps(str(path), args, peer_lammps.SCENE_SAVED_KEYS)["overlap"] \
        == (0.01, 0.02)
    args.scene_digest = "0" * 16
    with pytest.raises(ValueError, match="scene_digest"):
        peer_lammps.load_lammps(str(path), args, peer_lammps.SCENE_SAVED_KEYS)


def test_tuning_items_become_tuning_keywords():
    """--tuning NAME=VALUE: numbers and True/False as Python values, other text as
    strings; a bad name or value, an item without '=', or --tuning without --out stops
    with an error."""
    ap = argparse.ArgumentParser()
    assert peer_lammps.tuning_args(["relaxation=1.8", "contact_iterations=40",
                                    "shock_propagation=on", "warm_start=False"], ap) == \
        dict(relaxation=1.8, contact_iterations=40, shock_propagation="on", warm_start=False)
    assert peer_lammps.tuning_args(None, ap) == {}
    for bad in (["relaxaton=1.8"], ["relaxation"], ["relaxation=2.5"]):
        with pytest.raises(SystemExit):
            peer_lammps.tuning_args(bad, ap)
    args, ap = _scene_args(("tuning", ["relaxation=1.8"]))
    with pytest.raises(SystemExit):
        peer_lammps.scene_args(args, ap)


def test_saved_lammps_run_only_on_its_cpu_model():
    """A saved LAMMPS run from another CPU model is not reused: LAMMPS runs again, or
    with --only taichi the tool stops (wall times compare only on one machine)."""
    from machine import cpu_name
    args, ap = _scene_args(("lammps_json", "saved.json"))
    here = dict(cpu=cpu_name(), result={})
    assert peer_lammps.same_machine(here, args, ap) is here
    elsewhere = dict(cpu="Some Other CPU", result={})
    with pytest.raises(SystemExit):
        peer_lammps.same_machine(elsewhere, args, ap)
    args.only = "both"
    assert peer_lammps.same_machine(elsewhere, args, ap) is None


def test_scene_report_says_whether_the_machine_was_shared():
    """The load averages at the start and end of a run say whether other work ran: above
    the run's own threads by more than half a core, the report says the machine was
    shared."""
    args = types.SimpleNamespace(threads=1, lammps_threads=1)
    alone = peer_lammps.machine_load_text((1.0, 1.2), args)
    assert alone.startswith("no other work on the machine: load average 1.0")
    shared = peer_lammps.machine_load_text((0.2, 1.9), args)
    assert shared.startswith("shared machine:") and "1.9 at the end" in shared
