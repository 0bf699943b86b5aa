"""Checks of an argument's kind that modules at every level share: this module imports nothing
of the package, so the lowest (`gait`, `timegrid`) can use it too."""

import contextlib
import contextvars
import math
import numbers
import os
import struct
import sys
import warnings
from typing import Optional

import numpy as np

PACKAGE_FOLDER = os.path.dirname(os.path.abspath(__file__)) + os.sep
"""The package's source folder: the frames of its own code (`warn_user`)."""


def is_whole(value) -> bool:
    """Whether `value` is an integer, Python's or NumPy's, and not a bool (to Python True is 1,
    but never a count here)."""
    return isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_))


def is_real(value) -> bool:
    """Whether `value` is a real number, Python's or NumPy's, and not a bool (a flag is no
    quantity here)."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def is_subnormal(value) -> bool:
    """Whether the real number `value`, as the float it is stored as, is subnormal: not 0 and
    below 2.2e-308 in magnitude. Read from its bits, which no CPU mode changes: once Taichi has
    started, arithmetic flushes such a number to 0 (docs: numerics, "Subnormals in the rest of
    the process")."""
    try:
        bits = struct.unpack("<Q", struct.pack("<d", float(value)))[0]
    except OverflowError:
        return False
    return (bits >> 52) & 0x7FF == 0 and bits & ((1 << 52) - 1) != 0


def check_not_subnormal(name: str, value):
    """ValueError naming `name` where the real number `value` is subnormal (`is_subnormal`):
    stored, it would be one number before Taichi's start and 0 after."""
    if is_subnormal(value):
        raise ValueError(f"{name} must not be a subnormal number (not 0 and below "
                         f"{sys.float_info.min:g} in magnitude), which arithmetic flushes to 0 "
                         f"once Taichi has started: the same value would mean another number "
                         f"before and after; got {value!r}")


def is_finite_real(value) -> bool:
    """Whether `value` is a real number (`is_real`) that a float holds as a finite number: NaN,
    ±inf and an integer or fraction beyond float's range (10**400: an OverflowError in float)
    are not."""
    if not is_real(value):
        return False
    try:
        return math.isfinite(float(value))
    except OverflowError:
        return False


def check_finite(name: str, value, lowest: float, lowest_included: bool = False,
                 unit: str = ""):
    """ValueError naming `name` unless `value` is a real number (`is_real`) that a float holds
    as a finite number (`is_finite_real`) above `lowest`, or at it with `lowest_included`;
    `unit` follows the bound in the message (" s"). Checked without float arithmetic on the
    value first: math.isfinite(10**400) raised an OverflowError (an audit, 2026-12)."""
    if is_finite_real(value) and (float(value) >= lowest if lowest_included
                                  else float(value) > lowest):
        return
    relation = ">=" if lowest_included else ">"
    raise ValueError(f"{name} must be a finite number {relation} {lowest:g}{unit}, got "
                     f"{shown(value)}")


def shown(value) -> str:
    """`value` as an error message shows it: its repr, a number too long to read by its length
    (10**400: "an integer of 401 digits"; a fraction of such numbers: its first characters and
    their count)."""
    text = repr(value)
    if len(text) <= 40:
        return text
    if is_whole(value):
        return f"an integer of {len(str(abs(int(value))))} digits"
    return f"{text[:24]}... ({len(text)} characters)"


def check_choice(name: str, value, choices):
    """ValueError naming `name` and `choices` unless `value` is one of the words `choices`."""
    # a word first: `in` on an array or a list of words would compare element-wise or fail
    if not isinstance(value, str) or value not in choices:
        raise ValueError(f"{name} must be one of {list(choices)}, got {value!r}")


def check_flag(name: str, value) -> bool:
    """`value` as a bool if it is one (NumPy's included); else ValueError naming it (a text
    such as "no" would otherwise switch the option on)."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False, got {value!r}")
    return bool(value)


_TOLD_BY_CALLER: contextvars.ContextVar = contextvars.ContextVar("told_by_caller",
                                                                default=frozenset())
"""Kinds of `warn_user` warnings that a caller up the stack tells itself (`told_by_caller`)."""


@contextlib.contextmanager
def told_by_caller(*kinds: str):
    """Within it, `warn_user(..., kind=k)` of a listed kind says nothing in this thread: the
    caller tells it itself (`run_batch` tells its chunks' long-run and "ok"-instance warnings
    once, with the batch's numbers). A context variable, per thread: `warnings.catch_warnings`,
    used before, swaps the filters of the whole process, and two threads' batches left each
    other's "ignore" filters installed for good (an audit, 2026-12: a capped run afterwards
    warned nothing)."""
    token = _TOLD_BY_CALLER.set(_TOLD_BY_CALLER.get() | frozenset(kinds))
    try:
        yield
    finally:
        _TOLD_BY_CALLER.reset(token)


def warn_user(message: str, category=RuntimeWarning, kind: Optional[str] = None):
    """`warnings.warn` attributed to the first caller outside the package: the user's line (a
    script's, a notebook cell's, a study's), whichever public route led here. Fixed stack
    levels pointed inside the library on some routes (an audit, 2026-12: simulate's record and
    long-work warnings, Simulator.advance's, run_batch's). `kind`: what a caller may tell
    itself instead (`told_by_caller`)."""
    if kind is not None and kind in _TOLD_BY_CALLER.get():
        return
    level, frame = 2, sys._getframe(1)
    while frame is not None and frame.f_code.co_filename.startswith(PACKAGE_FOLDER):
        level, frame = level + 1, frame.f_back
    warnings.warn(message, category, stacklevel=level)
