"""Regenerate the main committed results: the studies below in full, with the flags the docs
quote, written into results/ (or --into DIR); the rest are run by hand (docs:
reproducibility).

    python -m studies reproduce [--only fig4c,sweep] [--into results] [--dry-run]

Each study runs as its own `python -m studies <name> ... --out <into>` process, one after the
other, and the first failure stops the run. The whole set takes hours on a 2-core machine;
`--dry-run` prints the commands.
"""

from __future__ import annotations

import shlex
import subprocess
import sys
from pathlib import Path

from .cli import (COMMITTED_RESULTS, OneLineParser, StudyArgumentError, check_future_folder,
                  parse_values)

DESCRIPTION = "Regenerate the main committed results/ with their studies' full runs (hours)."

COMMANDS = {
    "fig4c": [],
    "fig4c_accurate": ["fig4c", "--preset", "accurate", "--prefix", "fig4c_accurate"],
    "convergence": [],
    "gaits": ["--workers", "2"],
    "sweep": ["--alpha", "0.2:1.2:6", "--added-mass", "0,0.5,1,2",
              "--youngs-modulus", "2e6,5e6,1e7", "--workers", "2"],
    "calibrate": ["--preset", "accurate"],
    "crossval": ["calibrate", "--preset", "accurate", "--cross-validate"],
    "animate": [],
    "bench": ["--batch-sizes", "1,8,64,512,2048", "--repeats", "2"],
    "jacobians": [],
    "work_precision": [],
    "stability": ["--workers", "2"],
    "scaling": [],
    "sensitivity": ["--preset", "accurate"],
    "elasticities": ["--check", "alpha,drag_perpendicular,joint_radius,tip_radius,cylinder_drag,"
                     "cylinder_diameter,fluid_density,limb_stiffness_ratio,youngs_modulus,"
                     "added_mass_coeff,thickness"],
    "elasticities_accurate": ["elasticities", "--preset", "accurate", "--prefix",
                              "elasticities_accurate", "--check", "alpha,drag_perpendicular"],
}
"""Result name -> the study's flags (the study is the name unless the flags start with it)."""


def command(name: str, into: Path):
    flags = COMMANDS[name]
    study, flags = (flags[0], flags[1:]) if flags and not flags[0].startswith("-") \
        else (name, flags)
    # the package this module runs in: `studies` in the checkout, `taichi_star.studies` once
    # installed (`python -m studies` failed outside the checkout: an audit, 2026-12)
    return [sys.executable, "-m", __package__, study, *flags, "--no-progress", "--out",
            str(into)]


def main(argv=None):
    parser = OneLineParser(prog="python -m studies reproduce", description=DESCRIPTION)
    parser.add_argument("--only", default=None,
                        help=f"comma list of {', '.join(COMMANDS)}, each once (default all)")
    parser.add_argument("--into", default=str(COMMITTED_RESULTS),
                        help="output folder (default the repository's results/)")
    parser.add_argument("--dry-run", action="store_true", help="print the commands only")
    args = parser.parse_args(argv)
    names = list(COMMANDS) if args.only is None else parse_values(args.only, "--only", str)
    unknown = [n for n in names if n not in COMMANDS]
    if unknown:
        raise StudyArgumentError(f"--only: unknown result {unknown[0]!r}; choose from "
                                 f"{', '.join(COMMANDS)}")
    if not args.into.strip():  # Path("") is the current folder
        raise StudyArgumentError("--into: an empty folder name (give a folder, e.g. runs/mine)")
    into = Path(args.into)
    check_future_folder(into, False, "--into")
    for name in names:
        line = command(name, into)
        # as a user types it (the run itself uses this interpreter, `line[0]`)
        print(" ".join(map(shlex.quote, ["python", *line[1:]])), flush=True)
        if not args.dry_run:
            status = subprocess.run(line).returncode
            if status != 0:  # the study said why, in its own line above
                print(f"reproduce: {name} failed (exit status {status}); the results written "
                      f"before it are kept", file=sys.stderr)
                raise SystemExit(status)
