"""pytest plugin of ``tools/suite_time.py --census``: one JSON line per compiled engine
the tests build (taichi_spheres/engine.py), written by each pytest(-xdist) worker to
``$ENGINE_CENSUS_DIR/<worker>.jsonl``: the test that built it, the Taichi runtime's
generation, the engine's kind (its key without the generation, the precision by name)
and its room for spheres and cells. Loaded with ``-p engine_census_plugin`` (tools/ on
PYTHONPATH); without ENGINE_CENSUS_DIR it does nothing."""
from __future__ import annotations

import dataclasses
import json
import os

CENSUS_ENV = "ENGINE_CENSUS_DIR"


def engine_kind(key) -> str:
    """An engine key (engine.EngineKey) as text, without the runtime's generation (a
    re-initialised runtime builds the same kind again) and with the precision by name."""
    return repr(dataclasses.replace(key, generation=0, real=str(key.real)))


def pytest_configure(config):
    out_dir = os.environ.get(CENSUS_ENV)
    if not out_dir:
        return
    from taichi_spheres import engine
    built = engine.Engine.__init__
    path = os.path.join(out_dir, os.environ.get("PYTEST_XDIST_WORKER", "main") + ".jsonl")

    def logged(self, key, capacity, cell_capacity):
        built(self, key, capacity, cell_capacity)
        test = os.environ.get("PYTEST_CURRENT_TEST", "").split(" ")[0]
        with open(path, "a", encoding="utf-8") as out:
            out.write(json.dumps(dict(test=test, generation=key.generation,
                                      kind=engine_kind(key), spheres=capacity,
                                      cells=cell_capacity)) + "\n")

    engine.Engine.__init__ = logged
