"""taichi_star: a Taichi data-parallel batch simulator of the star-shaped soft swimming robot.

Importing the package initialises nothing (no `ti.init`: `simulate` and `Simulator` initialise
Taichi themselves) and prints nothing: it asks Taichi not to print its version banner unless
ENABLE_TAICHI_HEADER_PRINT is set, nor to take over a notebook's output unless
TI_ENABLE_PYBUF is.
"""

import os
import sys

os.environ.setdefault("ENABLE_TAICHI_HEADER_PRINT", "false")
# where sys.stdout is not the process's (a notebook, IDLE, captured output) Taichi logs
# "Graphical python shell detected" at its import and flushes its kernels' print buffer after
# every kernel call; no kernel here prints (an audit, 2026-12)
os.environ.setdefault("TI_ENABLE_PYBUF", "0")
if "HOME" not in os.environ:
    # Taichi's import aborts the process without it (a core dump: cron, `env -i`, systemd
    # units; an audit, 2026-12): the user's home from the password database, else a temporary
    # folder, said in one line
    import pwd
    import tempfile

    try:
        os.environ["HOME"] = pwd.getpwuid(os.getuid()).pw_dir or tempfile.gettempdir()
    except KeyError:  # a user the password database does not know (a container's uid)
        os.environ["HOME"] = tempfile.gettempdir()
    print(f"taichi_star: HOME was not set (Taichi needs it); set to {os.environ['HOME']}",
          file=sys.stderr)

# the package's modules import taichi, which reads the variable above at its own import.
# A Ctrl-C meanwhile is raised once they have loaded (`interrupts`: Taichi's import-time code
# swallowed some)
from .interrupts import deferred_interrupt

with deferred_interrupt():
    from .actuation import CurvatureProfile
    from .gait import Gait, symmetry_classes
    from .params import (COMPONENT_HEIGHTS, DIFFERENTIABLE_FIELDS, JACOBIANS,
                         NEWTON_TOL_DEFAULTS, PER_ACTUATOR_FIELDS, PRESETS, SOLVER_RANGES,
                         STAR_RANGES, SolverConfig, StarParams, allowed_values, changed_fields)
    from .profiling import EngineProfile
    from .runtime import available_archs
    from .driver import RunTiming, fewest_steps
    from .simulation import SimulationResult, simulate
    from .timegrid import (MAX_STEPS_PER_INSTANCE, LongWorkWarning, SteadySpeedWarning,
                           check_work)
    from .simulator import Simulator, SimulatorSnapshot
del deferred_interrupt  # the package's namespace is its public API (`__all__`)

__version__ = "0.3.0"

__all__ = ["simulate", "SimulationResult", "RunTiming", "MAX_STEPS_PER_INSTANCE", "check_work",
           "LongWorkWarning", "SteadySpeedWarning", "fewest_steps", "Simulator",
           "SimulatorSnapshot", "available_archs",
           "StarParams", "STAR_RANGES", "allowed_values", "changed_fields", "SolverConfig",
           "SOLVER_RANGES", "NEWTON_TOL_DEFAULTS", "PRESETS", "JACOBIANS",
           "PER_ACTUATOR_FIELDS", "COMPONENT_HEIGHTS", "DIFFERENTIABLE_FIELDS",
           "CurvatureProfile", "Gait", "symmetry_classes", "EngineProfile", "__version__"]
