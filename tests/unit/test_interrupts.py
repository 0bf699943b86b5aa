"""A Ctrl-C while the libraries load is held back and raised once they have loaded
(`taichi_star.interrupts`): Taichi's import-time code swallowed some in a bare `except:`, and
numpy's import turned one into an ImportError. Exact cases here; `python -m studies` with such
code in its imports in test_a_ctrl_c_swallowed_at_import_still_stops_the_cli."""

import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from taichi_star.interrupts import deferred_interrupt

REPO = Path(__file__).resolve().parents[2]


def swallowing_code():
    """Sends this process SIGINT inside a bare `except:`, as Taichi's kernel decorator runs its
    frame inspection: a KeyboardInterrupt raised there is lost."""
    try:
        os.kill(os.getpid(), signal.SIGINT)
        sum(range(1000))  # Python runs the handler between bytecodes: here, at the latest
    except:  # noqa: E722  (the point: code that catches everything)
        pass


def test_an_interrupt_inside_the_block_is_raised_when_it_ends(interruptible):
    reached_the_end = False
    with pytest.raises(KeyboardInterrupt):
        with deferred_interrupt():
            swallowing_code()
            # held back: the block goes on to its end
            reached_the_end = True
    assert reached_the_end
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_without_an_interrupt_the_block_ends_normally(interruptible):
    with deferred_interrupt():
        assert signal.getsignal(signal.SIGINT) is not signal.default_int_handler  # held
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_the_blocks_own_error_propagates_and_the_handler_is_restored(interruptible):
    with pytest.raises(ImportError, match="its own"):
        with deferred_interrupt():
            raise ImportError("its own")
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_an_ignored_sigint_stays_ignored(interruptible):
    """A process that ignores SIGINT (a background job of a non-interactive shell) keeps
    ignoring it: the block neither holds nor raises it."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    with deferred_interrupt():
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
        swallowing_code()
    assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN


def test_another_thread_runs_the_block_as_is(interruptible):
    """Only the main thread may set a signal handler (and receives SIGINT): elsewhere the block
    runs untouched, the main thread's handler with it."""
    seen = {}

    def in_a_thread():
        with deferred_interrupt():
            seen["handler"] = signal.getsignal(signal.SIGINT)
        seen["ended"] = True

    thread = threading.Thread(target=in_a_thread)
    thread.start()
    thread.join()
    assert seen == {"handler": signal.default_int_handler, "ended": True}


CLI_WITH_SWALLOWING_IMPORT = """
import builtins, os, runpy, signal, sys
signal.signal(signal.SIGINT, signal.default_int_handler)  # as in a terminal, even when this
                                                          # test runs in a background job
original_import = builtins.__import__
def importing(name, *args, **kwargs):
    if name == {module!r} and not getattr(builtins, "sent", False):
        builtins.sent = True
        try:
            os.kill(os.getpid(), signal.SIGINT)
            sum(range(1000))
        except:
            pass
    return original_import(name, *args, **kwargs)
builtins.__import__ = importing
sys.argv = ["studies", "--version"]
runpy.run_module("studies", run_name="__main__", alter_sys=True)
"""


@pytest.mark.parametrize("module", ["taichi", "taichi_star.batch"])
def test_a_ctrl_c_swallowed_at_import_still_stops_the_cli(module):
    """`python -m studies --version` with a Ctrl-C that code catching everything swallows
    while taichi_star's libraries load (`taichi`) or the studies' (`taichi_star.batch`): before,
    the version printed and the exit was 0 (a study ran whole: 4 of 40 Ctrl-Cs 0.08-0.47 s into
    `python -m studies fig4c`); now one line and exit 130, nothing run."""
    result = subprocess.run([sys.executable, "-c", CLI_WITH_SWALLOWING_IMPORT.format(module=module)],
                            capture_output=True, text=True, cwd=REPO, timeout=120,
                            env=dict(os.environ, PYTHONPATH=str(REPO)))
    assert result.returncode == 130, result.stderr[-2000:]
    assert result.stdout == ""
    assert result.stderr.strip().splitlines() == [
        "python -m studies: interrupted while loading; nothing was run"]


def test_taichis_matrix_functions_load_with_the_package_not_at_the_first_compile():
    """Taichi imports its matrix functions at the first kernel compile, and their decorators
    inspect frames inside a bare `except:` that swallowed a Ctrl-C landing there (0.9 s into
    `python -m studies fig4c`, which then ran whole and exited 0: an audit). The package
    imports them while its import holds Ctrl-C back, so no compile imports them later."""
    probe = "import sys, taichi_star; print('taichi.lang.matrix_ops' in sys.modules)"
    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                            cwd=REPO, timeout=120, env=dict(os.environ, PYTHONPATH=str(REPO)))
    assert result.stdout.strip() == "True", result.stderr[-2000:]
