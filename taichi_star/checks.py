"""Checks of an argument's kind that modules at every level share: this module imports nothing
of the package, so the lowest (`gait`, `timegrid`) can use it too."""

import numbers

import numpy as np


def is_whole(value) -> bool:
    """Whether `value` is an integer, Python's or NumPy's, and not a bool (to Python True is 1,
    but never a count here)."""
    return isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_))


def is_real(value) -> bool:
    """Whether `value` is a real number, Python's or NumPy's, and not a bool (a flag is no
    quantity here)."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def check_flag(name: str, value) -> bool:
    """`value` as a bool if it is one (NumPy's included); else ValueError naming it (a text
    such as "no" would otherwise switch the option on)."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False, got {value!r}")
    return bool(value)
