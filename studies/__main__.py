"""`python -m studies <name> [options]`; `python -m studies <name> --help` for a study's flags."""

import errno
import importlib
import sys
from pathlib import Path

from taichi_star.batch import RunStoreError
from taichi_star.extras import first_missing

from . import study_names
from .cli import StudyArgumentError, StudyOutputError, configure_logging


FULL_DISK = (errno.ENOSPC, errno.EDQUOT)
"""Errors of a write that found no room: a one-line error, not a traceback."""


STUDIES_EXTRA = ("matplotlib", "PIL", "cma", "SALib", "scipy", "gymnasium")
"""What the studies import beyond the core (pyproject.toml's `studies` extra)."""


def program() -> str:
    """How the user called the studies: the installed `taichi-star` command, or `python -m
    studies` in a checkout (`python -m taichi_star.studies` installed)."""
    if Path(sys.argv[0]).name == "taichi-star":
        return "taichi-star"
    return f"python -m {__package__}"


def usage() -> str:
    lines = [f"usage: {program()} <name> [--out DIR] [--quick] [--arch cpu|gpu] ...",
             "", "studies:"]
    for name in study_names():
        description = importlib.import_module(f"{__package__}.{name}").DESCRIPTION
        lines.append(f"  {name:<15} {description.splitlines()[0]}")
    return "\n".join(lines)


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    missing = first_missing(STUDIES_EXTRA, "studies")
    if missing:  # before any compute (and before the list, which imports every study)
        print(f"{program()}: error: {missing}", file=sys.stderr)
        return 2
    if not argv or argv[0] in ("-h", "--help"):  # no study named: the list is the answer
        print(usage())
        return 0
    name, rest = argv[0], argv[1:]
    if name not in study_names():
        print(f"{program()}: error: unknown study {name!r}; choose one of "
              f"{', '.join(study_names())}", file=sys.stderr)
        return 2
    configure_logging()
    module = importlib.import_module(f"{__package__}.{name}")
    try:
        module.main(rest)
    except (StudyArgumentError, StudyOutputError, RunStoreError) as error:
        print(f"{program()} {name}: error: {error}", file=sys.stderr)
        return 2
    except OSError as error:
        if error.errno not in FULL_DISK:
            raise
        # a plot or animation written outside Output's tables (those give StudyOutputError)
        print(f"python -m studies {name}: error: cannot write {error.filename or 'a file'} "
              f"({error.strerror}); the files written before are intact", file=sys.stderr)
        return 2
    except SystemExit as exit_:  # argparse: --help, or an unknown / malformed flag
        return exit_.code if isinstance(exit_.code, int) else 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
