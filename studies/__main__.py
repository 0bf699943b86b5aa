"""`python -m studies <name> [options]`; `python -m studies <name> --help` for a study's flags."""

import importlib
import sys

from . import STUDIES
from .common import StudyArgumentError


def usage() -> str:
    lines = ["usage: python -m studies <name> [--arch cpu|gpu] [--out DIR] [--quick] ...",
             "", "studies:"]
    lines += [f"  {name:<10} {text}" for name, text in STUDIES.items()]
    return "\n".join(lines)


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(usage())
        return 0 if argv else 2
    name, rest = argv[0], argv[1:]
    if name not in STUDIES:
        print(f"python -m studies: error: unknown study {name!r}; choose one of "
              f"{', '.join(STUDIES)}", file=sys.stderr)
        return 2
    module = importlib.import_module(f"studies.{name}")
    try:
        module.main(rest)
    except StudyArgumentError as error:
        print(f"python -m studies {name}: error: {error}", file=sys.stderr)
        return 2
    except SystemExit as exit_:  # argparse: --help, or an unknown / malformed flag
        return exit_.code if isinstance(exit_.code, int) else 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
