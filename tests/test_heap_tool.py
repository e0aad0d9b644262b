"""tools/heap.py's measures: the angle of repose from a heap's surface profile, the
fixed-base angle, pours from other seeds and the summary over pours (numpy only)."""
from __future__ import annotations

import math
import os
import sys

import numpy as np
import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tools"))

import heap  # noqa: E402  (tools/heap.py)
import taichi_spheres as ts  # noqa: E402

HEAP_SCENE = os.path.join(HERE, "..", "scenes", "heap.toml")


def cone_of_spheres(angle_deg, radius=0.003, base_radius=0.06, floor=0.14, centre=(0.15, 0.15)):
    """Spheres whose tops lie on a cone of the given angle over a platform at z = floor:
    one sphere at the middle of each radial bin (one diameter wide) along a ray, the edge
    sphere's top a diameter above the platform."""
    slope = math.tan(math.radians(angle_deg))
    rho = (np.arange(int(round(base_radius / (2 * radius)))) + 0.5) * 2 * radius
    top = floor + 2 * radius + slope * (base_radius - rho)
    x = np.stack([centre[0] + rho, np.full_like(rho, centre[1]), top - radius], axis=1)
    return x, np.full(len(rho), radius)


@pytest.mark.parametrize("angle", [8.0, 15.0, 30.0])
def test_both_angles_of_a_cone_of_spheres(angle):
    x, r = cone_of_spheres(angle)
    base = dict(floor=0.14, below=0.195, centre=(0.15, 0.15), within=0.06)
    profile, height, samples = heap.repose_angle(x, r, **base)
    assert samples >= 3
    assert profile == pytest.approx(angle, abs=1e-9)
    # the top sphere stands half a bin (one radius) off the axis
    rise = math.tan(math.radians(angle)) * (0.06 - r[0])
    assert heap.base_angle(base, height, r) == pytest.approx(math.degrees(math.atan(rise / 0.06)))


def test_fixed_base_angle_of_one_layer_is_zero_and_without_a_platform_nan():
    assert heap.fixed_base_angle(0.006, 0.06, 0.006) == 0.0
    assert heap.fixed_base_angle(0.006 + 0.06, 0.06, 0.006) == pytest.approx(45.0)
    assert math.isnan(heap.base_angle(dict(floor=0.0), 0.02, np.full(3, 0.003)))


def test_a_flat_topped_deposit_has_no_profile_angle():
    x, r = cone_of_spheres(0.0)
    x, r = np.concatenate([x, x + [0, 0, 2 * r[0]]]), np.concatenate([r, r])  # two layers
    base = dict(floor=0.14, below=0.195, centre=(0.15, 0.15), within=0.06)
    profile, height, samples = heap.repose_angle(x, r, **base)
    assert math.isnan(profile) and samples == 0
    assert height == pytest.approx(4 * r[0])


def test_pours_from_other_seeds():
    own = heap.heap_scene(HEAP_SCENE)
    assert np.array_equal(own.x, ts.load_scene(HEAP_SCENE).x)
    assert np.array_equal(heap.heap_scene(HEAP_SCENE, 7).x, own.x)   # the file's own seed
    other = heap.heap_scene(HEAP_SCENE, 8)
    assert other.n == own.n and not np.array_equal(other.x, own.x)
    flat = heap.heap_scene(HEAP_SCENE, flat=True)
    lengths = [(g.inside, g.length) for g in flat.geometry if isinstance(g, ts.Cone)]
    assert (False, 1e-6) in lengths and (False, 1e-3) not in lengths
    assert np.array_equal(flat.x, own.x)


def test_summary_over_pours_skips_heaps_the_fit_could_not_measure():
    rows = [dict(mu=0.3, mu_r=0.1, angle=a, base_angle=b, height=h)
            for a, b, h in ((20.0, 18.0, 0.02), (math.nan, 16.0, 0.016), (22.0, 20.0, 0.024))]
    rows.append(dict(mu=0.6, mu_r=0.1, angle=25.0, base_angle=24.0, height=0.026))
    low, high = heap.summarise(rows)
    assert (low["n"], low["fits"]) == (3, 2)
    assert low["angle"] == pytest.approx(21.0) and low["angle_sd"] == pytest.approx(math.sqrt(2))
    assert low["base_angle"] == pytest.approx(18.0) and low["base_angle_sd"] == pytest.approx(2.0)
    assert (high["n"], high["angle"]) == (1, 25.0) and math.isnan(high["angle_sd"])
    assert heap.mean_sd(21.0, 1.4142) == "21.0 ± 1.4"
    assert heap.mean_sd(0.026, math.nan, 1e3) == "26.0"


def test_a_lammps_heap_starts_without_overlaps_when_held():
    """LAMMPS's final positions overlap (soft contacts): the held scene keeps the spheres
    below the funnel that LAMMPS did not lose, at rest, with radii shrunk just enough."""
    import peer_lammps_heap
    scene = heap.heap_scene(HEAP_SCENE)
    r = float(scene.radius[0])
    x = np.full((scene.n, 3), np.nan)
    x[:3] = [[0.05, 0.05, r], [0.05 + 2 * r * (1 - 1e-3), 0.05, r], [0.25, 0.25, 0.1]]
    x[3] = [0.1, 0.1, 0.3]                                  # still in the funnel's column
    x[4] = [0.15, 0.15, 0.1395 + r]      # on LAMMPS's disc, inside the 1 mm platform cone
    held, shrink = peer_lammps_heap.held_scene(scene, x, below=0.195)
    assert held.n == 4 and np.array_equal(held.x, x[[0, 1, 2, 4]])
    platform = [g for g in held.geometry if not g.inside][0]
    assert platform.length == 1e-6 and platform.point[2] == pytest.approx(0.1395 - 5e-7)
    assert shrink == pytest.approx(1e-3 + 5e-4)
    assert held.radius == pytest.approx(np.full(4, r * (1 - shrink)))
    assert np.array_equal(held.mass, scene.mass[:4]) and not held.v.any()
    x[5] = [0.15, 0.15, 0.1]          # under the platform (its back face): not kept
    on_platform, _ = peer_lammps_heap.held_scene(scene, x, below=0.195, floor=0.14)
    assert np.array_equal(on_platform.x, x[[4]])


def test_summary_table_has_a_column_per_key_and_none_for_single_pours():
    rows = [dict(mu=0.3, mu_r=0.1, code=code, angle=a, base_angle=a, height=0.02)
            for code in ("taichi_spheres", "LAMMPS") for a in (20.0, 22.0)]
    lines = heap.summary_lines(rows, ("mu", "mu_r", "code"))
    assert lines[3].split("|")[1:5] == [" mu ", " mu_r ", " code ", " pours "]
    assert lines[4] == "|---" * 7 + "|"
    assert lines[5].startswith("| 0.3 | 0.1 | taichi_spheres | 2 | 21.0 ± 1.4 (2) |")
    assert heap.summary_lines(rows[:1]) == []


def test_a_held_sphere_pressed_into_the_platform_shrinks_more_or_is_refused():
    import peer_lammps_heap
    scene = heap.heap_scene(HEAP_SCENE)
    r = float(scene.radius[0])
    x = np.full((scene.n, 3), np.nan)
    x[0] = [0.15, 0.15, 0.1395 + r * (1 - 2e-3)]     # 2e-3 r into LAMMPS's disc
    held, shrink = peer_lammps_heap.held_scene(scene, x)
    assert shrink == pytest.approx(4e-3)              # 5e-4 doubled three times
    x[0, 2] = 0.1395 + 0.5 * r                        # half a radius in: not mended
    with pytest.raises(ValueError, match="inside geometry"):
        peer_lammps_heap.held_scene(scene, x)


def test_lammps_contact_model_text_names_twisting_only_when_asked():
    """tools/lammps_silo.py contact_model: sds rolling with mu_r > 0, sds twisting
    limited to mu_r r_eff unless twisting=False (peer_lammps_heap.py --no-twisting),
    neither without rolling friction."""
    import lammps_silo
    roll = (2.0, 0.1)
    both = lammps_silo.contact_model(5e9, 0.3, 0.5, 0.3, 0.1, roll, 0.003)
    assert "rolling sds 2 0.1 0.1" in both
    assert both.endswith(f"twisting sds {2.0 * 0.003 ** 2:.10g} {0.1 * 0.003 ** 2:.10g} "
                         f"{0.1 * 0.003:.10g}")
    rolling_only = lammps_silo.contact_model(5e9, 0.3, 0.5, 0.3, 0.1, roll, 0.003,
                                             twisting=False)
    assert "rolling sds" in rolling_only and "twisting" not in rolling_only
    assert "rolling" not in lammps_silo.contact_model(5e9, 0.3, 0.5, 0.3, 0.0, roll, 0.003)
