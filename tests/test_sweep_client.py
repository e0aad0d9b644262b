"""Several sweeps on one Dask client: each gets every run done (no sweep cancels the
runs of the next)."""
import pytest

import taichi_spheres as ts
from taichi_spheres.builders import gas

distributed = pytest.importorskip("distributed")


def test_two_sweeps_in_a_row_on_one_client():
    scene = gas(8, packing=0.1, periodic=False, gravity=(0.0, 0.0, 0.0), seed=1)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        for values in ([0.5, 0.9], [0.6, 0.8]):
            rows = ts.sweep(scene, {"restitution": values}, duration=0.05, client=client)
            assert [row["error"] for row in rows] == [None, None]
            assert [row["restitution"] for row in rows] == values
            assert all(row["steps"] > 0 for row in rows)
