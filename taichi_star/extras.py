"""Optional dependencies, imported only by the functions that need them.

The core install (``pip install taichi_star``) brings Taichi, NumPy, pandas and tqdm: enough for
`simulate`, `Simulator` and `run_batch` (without a run store). Everything else comes with an
extra, named in the error a missing one raises:

- ``plots``: matplotlib (the main job, ``taichi-star fig4c``, and the studies that only plot);
- ``envs``: gymnasium (the Gymnasium environments, `taichi_star.envs`);
- ``studies``: what every study needs (plots, envs, dask, cma, SALib, pyarrow);
- ``io``: pyarrow, xarray, netCDF4 (Parquet: `to_parquet`, `run_batch(run_dir=...)`; netCDF:
  `to_xarray`, `to_netcdf`);
- ``video``: matplotlib, pillow, imageio-ffmpeg (`SimulationResult.animate`);
- ``dask``: dask.distributed (`run_batch(..., scheduler=...)`);
- ``docs``: mkdocs-material, mkdocstrings (building the documentation);
- ``rl``: stable-baselines3 and torch (large; not part of ``all``), the environments and plots;
- ``all``: every extra but ``rl``.
"""

from __future__ import annotations

import importlib
import importlib.util
from types import ModuleType

# the public names (docs/api.md), those the studies use among them (tests/test_layering.py)
__all__ = ["require", "missing_extra"]

EXTRA_MODULES = {
    "plots": ("matplotlib",),
    "envs": ("gymnasium",),
    "studies": ("matplotlib", "gymnasium", "distributed", "cma", "SALib", "pyarrow", "scipy",
                "PIL"),
    "io": ("pyarrow", "xarray", "netCDF4"),
    "video": ("matplotlib", "PIL", "imageio_ffmpeg"),
    "dask": ("distributed",),
    "rl": ("gymnasium", "matplotlib", "stable_baselines3", "torch"),
}
"""The top-level modules each extra of pyproject.toml installs (those the code imports), by
extra; `missing_extra` checks them."""


def missing_message(module: str, extra: str) -> str:
    """What to tell a user who lacks `module`: the extra that installs it."""
    return (f"{module} is not installed: it comes with the {extra!r} extra: "
            f'pip install "taichi_star[{extra}]"')


def first_missing(modules, extra: str) -> str:
    """`missing_message` of the first of `modules` (top-level names) that cannot be found, without
    importing any; "" when all are installed."""
    for module in modules:
        if importlib.util.find_spec(module) is None:
            return missing_message(module, extra)
    return ""


def missing_extra(extra: str) -> str:
    """`first_missing` of the modules of `extra` (a key of `EXTRA_MODULES`): "" when it is
    installed, else the one line telling the user which extra to install."""
    return first_missing(EXTRA_MODULES[extra], extra)


def require(module: str, extra: str) -> ModuleType:
    """Import `module` (a dotted name) and return it; if it is not installed, raise an
    ImportError that names the extra providing it, e.g. ``pip install "taichi_star[io]"``."""
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as missing:
        # only the package asked for (or one of its parents) counts as "not installed"; an
        # import error inside an installed package is that package's problem and propagates
        if missing.name is None or not (module == missing.name
                                        or module.startswith(missing.name + ".")):
            raise
        raise ImportError(missing_message(module, extra)) from missing
