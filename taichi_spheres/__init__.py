"""taichi_spheres: parallel hard-sphere simulation with exact rewind to contact.

Importing the package never initialises Taichi, nor imports it: :class:`Scene`,
:func:`load_scene` and :mod:`observe` are plain numpy, and the names that need Taichi
(:class:`Simulation`, :class:`State`) import it on first use, as do the names of the
trajectory and sweep modules (:class:`GSDWriter`, :func:`scene_from_gsd`,
:func:`sweep`), which import gsd or Dask. :class:`Simulation` initialises Taichi for the
arch it is asked to run on.
"""
import importlib
import importlib.util

from .scene import Scene
from .geometry import Cone, Cylinder, Plane, Sink
from .materials import Material
from .scenefile import load_scene
from . import observe

__all__ = ["Scene", "Plane", "Cylinder", "Cone", "Sink", "Material", "Simulation", "State", "load_scene", "observe", "GSDWriter",
           "scene_from_gsd", "sweep", "__version__"]
__version__ = "0.1.0"

#: public names imported from their module on first use (those modules import Taichi)
_LAZY = {"Simulation": ".simulation", "State": ".state", "GSDWriter": ".trajectory",
         "scene_from_gsd": ".trajectory", "sweep": ".sweeps"}


def __getattr__(name):
    """The lazy public names, and submodules (``ts.simulation``) on first use."""
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name], __name__), name)
        globals()[name] = value
        return value
    if not name.startswith("_") and importlib.util.find_spec(f"{__name__}.{name}"):
        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
