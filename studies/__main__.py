"""`python -m studies <name> [options]`; `python -m studies <name> --help` for a study's flags."""

import errno
import importlib
import sys

from taichi_star.batch import RunStoreError

from . import study_names
from .cli import StudyArgumentError, StudyOutputError, configure_logging


FULL_DISK = (errno.ENOSPC, errno.EDQUOT)
"""Errors of a write that found no room: a one-line error, not a traceback."""


def usage() -> str:
    lines = ["usage: python -m studies <name> [--out DIR] [--quick] [--arch cpu|gpu] ...",
             "", "studies:"]
    for name in study_names():
        description = importlib.import_module(f"studies.{name}").DESCRIPTION
        lines.append(f"  {name:<15} {description.splitlines()[0]}")
    return "\n".join(lines)


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(usage())
        return 0 if argv else 2
    name, rest = argv[0], argv[1:]
    if name not in study_names():
        print(f"python -m studies: error: unknown study {name!r}; choose one of "
              f"{', '.join(study_names())}", file=sys.stderr)
        return 2
    configure_logging()
    module = importlib.import_module(f"studies.{name}")
    try:
        module.main(rest)
    except (StudyArgumentError, StudyOutputError, RunStoreError) as error:
        print(f"python -m studies {name}: error: {error}", file=sys.stderr)
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
