"""Ctrl-C while the libraries load: held back, then raised once they have loaded.

Code run at import can catch every exception: Taichi's kernel decorator inspects its caller's
frame inside a bare `except:`, which swallowed an interrupt that arrived there (measured: of 40
Ctrl-Cs 0.08-0.47 s into `python -m studies fig4c`, 4 were lost and the study ran whole, and one
became numpy's "ImportError: initialization failed" with a 28-line traceback). This module
imports only the standard library, so the package can use it before anything else."""

import contextlib
import signal
import threading

__all__ = ["deferred_interrupt"]


@contextlib.contextmanager
def deferred_interrupt():
    """Run the block with SIGINT recorded instead of raised, then raise KeyboardInterrupt if
    one came: no code inside can swallow the interrupt or turn it into another error. Only in
    the main thread with Python's own SIGINT handler installed (a notebook's or a script's);
    elsewhere (another thread, SIGINT ignored or handled by the application) the block runs as
    it would without it. An exception of the block itself propagates as it is."""
    if (threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler):
        yield
        return
    received = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: received.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if received:
        raise KeyboardInterrupt
