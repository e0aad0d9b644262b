"""taichi_spheres: parallel hard-sphere simulation with exact rewind to contact.

Importing the package never initialises Taichi; :class:`Simulation` does, for the
arch it is asked to run on.
"""
from .scene import Scene
from .scenefile import load_scene
from .simulation import Simulation
from .state import State
from . import observe

__all__ = ["Scene", "Simulation", "State", "load_scene", "observe", "__version__"]
__version__ = "0.1.0"
