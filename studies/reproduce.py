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

from .cli import (COMMITTED_RESULTS, REPRODUCED_RESULTS, OneLineParser, StudyArgumentError,
                  check_future_folder, in_checkout, parse_values)
from .provenance import program

DESCRIPTION = "Regenerate the main committed results/ with their studies' full runs (hours)."


def command(name: str, into: Path, made_here=()):
    """The command line of result `name` written into `into`, after the results `made_here`
    this run wrote there before it: elasticities reads that run's Sobol table where it made
    one elsewhere than in the committed results/ (it read the committed one, and outside a
    checkout, which has none, failed after hours of the others: a review, 2026-12)."""
    flags = REPRODUCED_RESULTS[name]
    study, flags = (flags[0], flags[1:]) if flags and not flags[0].startswith("-") \
        else (name, flags)
    if study == "elasticities" and "sensitivity" in made_here \
            and into.resolve() != COMMITTED_RESULTS:
        flags = [*flags, "--sobol", str(into / "sensitivity.csv")]
    # the package this module runs in: `studies` in the checkout, `taichi_star.studies` once
    # installed (`python -m studies` failed outside the checkout: an audit, 2026-12)
    return [sys.executable, "-m", __package__, study, *flags, "--no-progress", "--out",
            str(into)]


def main(argv=None):
    parser = OneLineParser(prog=f"{program()} reproduce", description=DESCRIPTION)
    parser.add_argument("--only", default=None,
                        help=f"comma list of {', '.join(REPRODUCED_RESULTS)}, each once, run "
                             f"in that order (default all)")
    parser.add_argument("--into", default=None,
                        help="output folder (default the repository's results/, in a checkout)")
    parser.add_argument("--dry-run", action="store_true", help="print the commands only")
    args = parser.parse_args(argv)
    names = (list(REPRODUCED_RESULTS) if args.only is None
             else parse_values(args.only, "--only", str))
    unknown = [n for n in names if n not in REPRODUCED_RESULTS]
    if unknown:
        raise StudyArgumentError(f"--only: unknown result {unknown[0]!r}; choose from "
                                 f"{', '.join(REPRODUCED_RESULTS)}")
    # in the list's order, whatever --only's: a result made of another's comes after it
    # (elasticities before sensitivity read the committed Sobol table: a review, 2026-12)
    names = [name for name in REPRODUCED_RESULTS if name in names]
    if args.into is None:
        # an installed package has no results/: its default wrote into site-packages, where
        # an uninstall left it (an audit, 2026-12)
        if not in_checkout():
            raise StudyArgumentError(
                f"--into: needed outside a checkout of the repository (the committed results/ "
                f"are not here, {COMMITTED_RESULTS}): give a folder, e.g. --into runs/reproduce")
        args.into = str(COMMITTED_RESULTS)
    if not args.into.strip():  # Path("") is the current folder
        raise StudyArgumentError("--into: an empty folder name (give a folder, e.g. runs/mine)")
    into = Path(args.into)
    check_future_folder(into, False, "--into")
    for number, name in enumerate(names):
        line = command(name, into, names[:number])
        # as a user types it (the run itself uses this interpreter, `line[0]`)
        print(" ".join(map(shlex.quote, ["python", *line[1:]])), flush=True)
        if not args.dry_run:
            status = subprocess.run(line).returncode
            if status != 0:  # the study said why, in its own line above
                print(f"reproduce: {name} failed (exit status {status}); the results written "
                      f"before it are kept", file=sys.stderr)
                raise SystemExit(status)
