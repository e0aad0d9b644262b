"""Validation against theory (issue 4): the engine's gases against kinetic theory and
the hard-sphere equation of state. Short runs by default; the long ones behind
``--slow``. ``python tools/validation.py`` runs the same cases and writes
docs/validation.md.

Every tolerance is K = 4 standard errors of the run's own statistics (block means,
the sampling error of a kurtosis, or the measured run-to-run scatter), plus, where the
theory is itself approximate, its known accuracy, named at each constant. The runs are
seeded, so a test gives the same answer every time on one machine; 4 standard errors
keep a change of trajectory (any engine change reorders round-off) from failing
a correct engine.
"""
import math
import os
import sys

import pytest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tools"))
import validation as V  # noqa: E402  (tools/validation.py)

K = 4.0
#: Carnahan-Starling is accurate to a few tenths of a percent in the stable fluid: its
#: B4 = 18 against the exact 18.36 alone is +0.25 % of Z at phi = 0.3.
CS_ACCURACY = 0.005
#: its contact value g = (Z - 1)/(4 phi) then errs by CS_ACCURACY x Z/(Z - 1) <= 0.6 %
#: for phi >= 0.3 (Enskog's rate is exact given the true contact value).
G_ACCURACY = 0.008
#: Speedy's FCC fit (0.1-0.5 % against simulations) plus the finite crystal (N < 2100)
#: and the default step's out-of-order collisions at this density (about 0.3 spheres
#: with more than one collision in a step per collision): +1.6 % at step_fraction 0.1,
#: +0.7 % at 0.03 in docs/validation.md.
SPEEDY_ACCURACY = 0.02
#: run-to-run scatter of the smid / normal ratio of the loss per collision allows for
#: the two models' different velocity-correlation deviations (-1.3 % and -1.9 % at
#: e = 0.9, see V.HAFF_SYSTEMATIC)
RATIO_SYSTEMATIC = 0.02


@pytest.fixture
def arch64(arch):
    if arch == "metal":
        pytest.skip("validation runs in f64")
    return arch


def _close(measured, theory, tolerance):
    return abs(measured / theory - 1.0) < tolerance


# ---------------------------------------------------------------- 1. Maxwell
def _check_maxwell(m):
    # the start: components uniform on [-a, a], kurtosis 9/5
    assert abs(m["k0"] - 1.8) < K * m["k0_se"], m["k0"]
    # the relaxation follows the Boltzmann equation collision by collision
    for cps, _, k, se, k_ref, se_ref in m["rows"][1:]:
        assert abs(k - k_ref) < K * math.hypot(se, se_ref), (cps, k, k_ref)
    assert m["rows"][1][2] < m["theory"] - K * m["rows"][1][3], "relaxed before colliding"
    # the end: Maxwell (snapshots 10 cps apart, several relaxation times: independent)
    assert abs(m["mean"] - m["theory"]) < K * m["se"], (m["late"], m["theory"])


def test_maxwell_relaxation(arch64):
    _check_maxwell(V.run_maxwell(n=2000, packing=0.25, marks=(1, 2, 3),
                                 late=(10, 20, 30, 40, 50, 60), arch=arch64))


@pytest.mark.slow
def test_maxwell_relaxation_long(arch64):
    _check_maxwell(V.run_maxwell(n=8000, packing=0.25, marks=(0.5, 1, 1.5, 2, 3, 4, 6),
                                 late=tuple(range(10, 101, 10)), arch=arch64))


# ---------------------------------------------------------------- 2-3. CS and Enskog
def _check_equilibrium(r):
    # a dense gas may leave a rare pair at the sweep limit (counted, resolved in the
    # next step; none in the CPU's runs, one in a window of ~15,000 collisions on
    # lavapipe in f64)
    assert r["diag"]["unresolved"] <= 1e-4 * r["collisions"]
    assert r["energy_drift"] < 1e-12
    # the window is long enough for the comparison to mean something
    assert r["z_se"] < 0.01 * r["z"] and r["gamma_se"] < 0.01 * r["gamma"]
    assert _close(r["z"], r["z_theory"], K * r["z_se"] / r["z_theory"] + CS_ACCURACY), \
        (r["phi"], r["z"], r["z_se"], r["z_theory"])
    assert _close(r["gamma"], r["gamma_theory"],
                  K * r["gamma_se"] / r["gamma_theory"] + G_ACCURACY), \
        (r["phi"], r["gamma"], r["gamma_se"], r["gamma_theory"])
    # exact for hard spheres in equilibrium: Z - 1 = Gamma sigma sqrt(pi m/kT)/6
    assert abs(r["identity"] - 1.0) < K * r["identity_se"], r["identity"]


@pytest.mark.parametrize("phi", [0.3, 0.45])
def test_carnahan_starling_and_enskog(arch64, phi):
    _check_equilibrium(V.run_equilibrium(V.eos_scene(1000, phi), window_cps=30, arch=arch64))


@pytest.mark.slow
@pytest.mark.parametrize("phi", V.PHIS)
def test_carnahan_starling_and_enskog_long(arch64, phi):
    _check_equilibrium(V.run_equilibrium(V.eos_scene(2000, phi), window_cps=100,
                                         arch=arch64))


# ---------------------------------------------------------------- 4. Haff
def _haff_allowance(e):
    """Velocity-correlation deviations grow with the inelasticity: scale the e = 0.9
    allowance by (1 - e^2)/0.19."""
    return V.HAFF_SYSTEMATIC * (1.0 - e * e) / 0.19


def _check_haff_run(h, scatter):
    # energy: what pair restitution booked is what the kinetic energy lost
    assert abs(h["unaccounted"]) < 1e-12, h["unaccounted"]
    assert h["flow"] < 3.0, "the gas did not stay homogeneous"
    sys_ = _haff_allowance(h["e"])
    assert _close(h["loss_factor"], h["loss_factor_theory"], sys_ + K * scatter["loss"]), \
        h["loss_factor"]
    assert abs(h["rate_factor"] - 1.0) < sys_ + K * scatter["rate"], h["rate_factor"]
    assert _close(h["inv_t0"], h["inv_t0_theory"], sys_ + K * scatter["inv_t0"]), \
        (h["inv_t0"], h["inv_t0_theory"])
    assert _close(h["temp_ratio"], h["temp_ratio_theory"],
                  2.0 * (sys_ + K * scatter["inv_t0"]) * h["t_end"] / (1.0 + h["t_end"])), \
        (h["temp_ratio"], h["temp_ratio_theory"])


def test_haff_cooling_normal_and_smid(arch64):
    runs = {model: V.run_haff(e=0.9, model=model, n=1000, packing=0.1, t_end=2.0,
                              arch=arch64) for model in ("normal", "smid")}
    for h in runs.values():
        _check_haff_run(h, V.HAFF_SCATTER)
    # the smid rule also scales the tangential relative velocity by e: twice the loss
    ratio = runs["smid"]["loss_factor"] / runs["normal"]["loss_factor"]
    assert _close(ratio, 2.0, RATIO_SYSTEMATIC + K * math.sqrt(2.0) * V.HAFF_SCATTER["loss"]), \
        ratio


@pytest.mark.slow
@pytest.mark.parametrize("e", [0.9, 0.8])
def test_haff_cooling_long(arch64, e):
    seeds = (0, 1, 2, 3)
    ens = {model: V.haff_ensemble(e, model, seeds=seeds, n=1000, packing=0.1, t_end=2.0,
                                  arch=arch64) for model in ("normal", "smid")}
    sys_ = _haff_allowance(e)
    for h in ens.values():
        assert h["unaccounted"] < 1e-12 and h["flow"] < 3.0
        for key, scatter in (("loss", "loss"), ("rate", "rate"), ("inv_t0", "inv_t0")):
            # the standard error of 4 seeds is itself uncertain: not below the e = 0.9 value
            se = max(h[key + "_se"], V.HAFF_SCATTER[scatter] / math.sqrt(len(seeds)))
            assert abs(h[key]) < sys_ + K * se, (h["model"], key, h[key], h[key + "_se"])
    (ratio, se), = V.haff_ratios(list(ens.values()), "loss_factor").values()
    se = max(se, 2.0 * math.sqrt(2.0 / len(seeds)) * V.HAFF_SCATTER["loss"])
    assert abs(ratio - 2.0) < 2.0 * RATIO_SYSTEMATIC * (1.0 - e * e) / 0.19 + K * se, ratio


# ---------------------------------------------------------------- 5. dense
def _check_dense(d):
    assert d["energy_drift"] < 1e-12, d["energy_drift"]
    assert d["diag"]["unresolved"] == 0
    assert abs(d["identity"] - 1.0) < K * d["identity_se"], d["identity"]
    # an FCC start at phi = 0.55 (above melting, 0.545) stays a crystal: its pressure
    # is Speedy's crystal branch, far below the CS fluid branch
    assert _close(d["z"], d["z_speedy"], K * d["z_se"] / d["z_speedy"] + SPEEDY_ACCURACY), \
        (d["z"], d["z_speedy"])
    assert d["z"] < 0.8 * d["z_theory"]


def test_dense_fcc(arch64):
    _check_dense(V.run_dense(cells=6, packing=0.55, window_cps=30, arch=arch64))


@pytest.mark.slow
@pytest.mark.parametrize("step_fraction", [0.1, 0.03])
def test_dense_fcc_long(arch64, step_fraction):
    _check_dense(V.run_dense(cells=8, packing=0.55, window_cps=100, arch=arch64,
                             step_fraction=step_fraction))
