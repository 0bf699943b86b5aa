"""Command-line studies over taichi_star: `python -m studies <name> [--out DIR] [--quick] ...`
(`python -m studies` lists them, `python -m studies <name> --help` gives a study's flags).

Each study is a module of this package with a `DESCRIPTION` and a `main(argv)`: parameters ->
`taichi_star.batch.run_batch` -> tables (CSV, each with a JSON provenance sidecar) -> plots drawn
from those tables. Studies use only the public API of taichi_star; what they share is in
`studies.cli` (flags, output folders), `studies.provenance`, `studies.figures` (the Fig. 4c/4b
tables and plots), `studies.identify` (parameter boxes and the calibration objective) and
`studies.optimise` (independent gradient searches with batched evaluations).
"""

import pkgutil
import sys
from pathlib import Path

HELPERS = ("cli", "provenance", "figures", "identify", "optimise", "__main__")
"""Modules of this package that are not studies."""

EXTRA_OF_STUDY = {
    "animate": "plots", "bench": "plots", "calibrate": "studies", "convergence": "plots",
    "elasticities": "plots", "env_bench": "envs", "fig4c": "plots", "gait_design": "studies",
    "gaits": "plots", "gradient_fit": "studies", "jacobians": "plots", "model_select": "studies",
    "plan": "plots", "predictability": "plots", "primitives": "plots", "reproduce": None,
    "rl": "rl",
    "scaling": None,
    "sensitivity": "studies", "sensitivity_check": "plots", "simd": "plots", "stability": "plots",
    "strokes": "plots", "sweep": "studies",
    "work_precision": "plots",
}
"""The extra of pyproject.toml each study needs beyond the core (None: the core alone), checked
by the launcher before the study is imported. "plots" (matplotlib) keeps the main job, fig4c,
light; a study that needs more than one extra names "studies", which holds them all but rl's
(stable-baselines3 and torch, gigabytes: the "rl" extra, in no other).
reproduce runs every study, each in its own process that checks its own extra (its
--dry-run, which prints them, needs none). scaling times Dask clusters unless --no-dask, and
checks for it itself."""


STEADY_SPEED_STUDIES = ("fig4c", "gaits", "sweep")
"""The studies that report the steady speeds: a run whose time grid leaves them NaN or short of
a cycle is told there (`taichi_star.SteadySpeedWarning`). The others do not read them (stability
keeps them in its table with the whole summary, NaN where its grid leaves them), and their
grids (stability's steps, a fitted or varied period, a --dt) were told "a dt that divides the
period" gives them, to no purpose (a review, 2026-12): the launcher leaves it unsaid around
them (`cli.steady_speeds_unread`; a study's `main` called from Python says it)."""


def program() -> str:
    """How the user called the studies: the installed `taichi-star` command, or `python -m
    studies` in a checkout (`python -m taichi_star.studies` installed): what their usage, their
    messages and the commands their files record say (an installed package's files recorded
    `python -m studies`, which it does not have: an audit, 2026-12). Here, in the package's
    light first module, so that a Ctrl-C while the libraries load is told under it too."""
    if Path(sys.argv[0]).name == "taichi-star":
        return "taichi-star"
    return f"python -m {__package__}"


def study_names():
    """The studies: every module of this package but the helpers, sorted."""
    return sorted(module.name for module in pkgutil.iter_modules(__path__)
                  if module.name not in HELPERS)
