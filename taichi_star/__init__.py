"""taichi_star: a Taichi data-parallel batch simulator of the star-shaped soft swimming robot.

Importing the package has no side effects (no `ti.init`); `simulate` initialises Taichi itself.
"""

from .actuation import CurvatureProfile
from .gait import Gait, symmetry_classes
from .params import SolverConfig, StarParams
from .simulation import SimulationResult, available_archs, simulate

__all__ = ["simulate", "SimulationResult", "available_archs", "StarParams", "SolverConfig", "CurvatureProfile", "Gait",
           "symmetry_classes"]
