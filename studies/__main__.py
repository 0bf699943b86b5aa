"""`python -m studies <name> [options]`; `python -m studies <name> --help` for a study's flags."""

import ast
import contextlib
import errno
import importlib
import os
import signal
import sys
import threading
import warnings
from pathlib import Path

from . import program  # the package's light first module, loaded already: never interrupted

try:
    # taichi_star holds a Ctrl-C back while its libraries load (`interrupts`), and so do the
    # studies while theirs load: raised once they have, never lost nor turned into an ImportError
    from taichi_star.interrupts import deferred_interrupt

    with deferred_interrupt():
        import taichi_star
        from taichi_star.batch import RunStoreError
        from taichi_star.runtime import MemoryBudgetError
        from taichi_star.extras import missing_extra

        from . import EXTRA_OF_STUDY, STEADY_SPEED_STUDIES, study_names
        from . import cli
        from .cli import StudyArgumentError, StudyOutputError, configure_logging, interrupted
except KeyboardInterrupt:
    # Ctrl-C while the libraries load (a second or more): one line, as during a study, not the
    # traceback of pandas' or pyarrow's import (an audit, 2026-12)
    print(f"{program()}: interrupted while loading; nothing was run", file=sys.stderr)
    raise SystemExit(130) from None


FULL_DISK = (errno.ENOSPC, errno.EDQUOT)
"""Errors of a write that found no room: a one-line error, not a traceback."""


class Terminated(KeyboardInterrupt):
    """SIGTERM (`kill`, a batch scheduler's stop, a container's shutdown) raised in the study as
    an interrupt: Python's default for SIGTERM ends the process at once, so the run store's lock
    stayed and the run's empty output folder with it (an audit, 2026-12). As a KeyboardInterrupt
    it takes Ctrl-C's way out: every handler that keeps a run's work on Ctrl-C keeps it here."""


def _raise_terminated(signum, frame):
    raise Terminated


@contextlib.contextmanager
def sigterm_as_interrupt():
    """Run the block with SIGTERM raised as `Terminated`, where Python's default handler is in
    place and this is the main thread (only it may set a handler); a handler of the program
    that called `main` is left alone. The previous handler is back afterwards."""
    if (threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGTERM) is not signal.SIG_DFL):
        yield
        return
    signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)


@contextlib.contextmanager
def one_line_warnings(name: str):
    """Within it, a RuntimeWarning (the library's word to the user: a long run's hours,
    instances "ok" after capped solves) is printed as one line, "taichi-star sweep: warning:
    ...", as the errors are, not Python's two lines of file, line and source (an audit,
    2026-12); other categories (a library's deprecation, a fault of code) keep Python's format,
    which says where. Only the printing changes: a caller recording warnings (pytest, a
    notebook's `catch_warnings`) gets the same warnings."""
    python_format = warnings.formatwarning

    def formatted(message, category, filename, lineno, line=None):
        if issubclass(category, RuntimeWarning):
            return f"{program()} {name}: warning: {message}\n"
        return python_format(message, category, filename, lineno, line)

    warnings.formatwarning = formatted
    try:
        yield
    finally:
        warnings.formatwarning = python_format


def description(name: str) -> str:
    """The study's DESCRIPTION, read from its source without importing it (a study whose extra
    is not installed cannot be imported, and is still listed)."""
    source = (Path(__file__).parent / f"{name}.py").read_text(encoding="utf-8")
    for node in ast.parse(source).body:
        if isinstance(node, ast.Assign) and [getattr(t, "id", None) for t in node.targets] \
                == ["DESCRIPTION"]:
            return ast.literal_eval(node.value)
    raise LookupError(f"study {name} has no DESCRIPTION")


def missing_requirement(name: str) -> str:
    """"" when the extra the study `name` needs is installed (or it needs none), else the one
    line saying which extra to install."""
    extra = EXTRA_OF_STUDY[name]
    return missing_extra(extra) if extra else ""


def usage() -> str:
    lines = [f"usage: {program()} <name> [--out DIR] [--quick] [--arch cpu|gpu] ...",
             "", "studies:"]
    for name in study_names():
        extra = EXTRA_OF_STUDY[name]
        needs = f" (needs the {extra!r} extra)" if missing_requirement(name) else ""
        lines.append(f"  {name:<15} {description(name).splitlines()[0]}{needs}")
    return "\n".join(lines)


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):  # no study named: the list is the answer
        print(usage())
        return 0
    if argv[0] == "--version":
        print(f"taichi_star {taichi_star.__version__}")
        return 0
    name, rest = argv[0], argv[1:]
    if name not in study_names():
        print(f"{program()}: error: unknown study {name!r}; choose one of "
              f"{', '.join(study_names())}", file=sys.stderr)
        return 2
    missing = missing_requirement(name)
    if missing:  # before the study is imported, so before any compute
        print(f"{program()} {name}: error: {missing}", file=sys.stderr)
        return 2
    configure_logging()
    cli.OPENED.clear()  # this run's output folders alone (`interrupted`)
    try:
        # the study's import inside: Ctrl-C while it loads its libraries is one line too
        with sigterm_as_interrupt(), one_line_warnings(name), (
                contextlib.nullcontext() if name in STEADY_SPEED_STUDIES
                else cli.steady_speeds_unread()):
            importlib.import_module(f"{__package__}.{name}").main(rest)
    except (StudyArgumentError, StudyOutputError, RunStoreError, MemoryBudgetError) as error:
        # a run too large for memory is refused before any compute, naming the argument
        print(f"{program()} {name}: error: {error}", file=sys.stderr)
        for out in cli.OPENED:  # a refusal leaves no empty folder the run made
            out.remove_if_unused()
        return 2
    except BrokenPipeError:
        # the reader of the study's printed output left (`| head`): stop quietly, as a Unix
        # tool does; stdout's last flush at exit then goes nowhere
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
    except OSError as error:
        if error.errno not in FULL_DISK:
            raise
        # a plot or animation written outside Output's tables (those give StudyOutputError)
        print(f"{program()} {name}: error: cannot write {error.filename or 'a file'} "
              f"({error.strerror}); the files written before are intact", file=sys.stderr)
        return 2
    except KeyboardInterrupt as stop:
        # Ctrl-C or SIGTERM: one line saying what is kept, not the traceback of wherever the run
        # was, and a shell's exit status for it (128 + the signal's number)
        terminated = isinstance(stop, Terminated)
        print(f"{program()} {name}: {'terminated' if terminated else 'interrupted'}; "
              f"{interrupted()}", file=sys.stderr)
        return 128 + (signal.SIGTERM if terminated else signal.SIGINT)
    except SystemExit as exit_:  # argparse's --help (its refusals are StudyArgumentError)
        # as Python's own exit: None is success, a number its status, a message a failure
        if exit_.code is None:
            return 0
        return exit_.code if isinstance(exit_.code, int) else 2
    except Exception:
        # a fault's traceback is shown as it is, but leaves no empty folder the run made
        for out in cli.OPENED:
            out.remove_if_unused()
        raise
    return 0


if __name__ == "__main__":
    sys.exit(main())
