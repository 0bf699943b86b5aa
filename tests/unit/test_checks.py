"""The argument checks the public functions share (`taichi_star.checks`): `check_finite`, the
one check of "a finite number above a bound" (its bound included or not, numbers a float
cannot hold), and the caller `warn_user` attributes a warning to."""

import math

import numpy as np
import pytest

from taichi_star.checks import check_finite


@pytest.mark.parametrize("value, included, accepted", [
    (0.0, False, False), (np.nextafter(0.0, 1.0), False, True),   # > 0: 0 out, the next in
    (0.0, True, True), (np.nextafter(0.0, -1.0), True, False),    # >= 0: 0 in, the one below out
    (np.float32(2.5), False, True), (np.int64(3), False, True), (7, True, True),
    (True, False, False), ("1", False, False), (None, True, False),
    (math.inf, False, False), (math.nan, True, False), (10**400, False, False)])
def test_a_finite_number_above_the_bound_passes_and_nothing_else(value, included, accepted):
    if accepted:
        assert check_finite("x", value, 0.0, lowest_included=included) is None
    else:
        with pytest.raises(ValueError, match=rf"^x must be a finite number "
                                             rf"{'>=' if included else '>'} 0, got "):
            check_finite("x", value, 0.0, lowest_included=included)


def test_the_message_names_the_bound_its_unit_and_the_value_as_shown():
    with pytest.raises(ValueError) as error:
        check_finite("period_s", 1.5, 2.0, unit=" s")
    assert str(error.value) == "period_s must be a finite number > 2 s, got 1.5"
    # an integer past a float's range: an OverflowError of math.isfinite (an audit, 2026-12)
    with pytest.raises(ValueError) as error:
        check_finite("ratio", -10**400, 1.0, lowest_included=True)
    assert str(error.value) == "ratio must be a finite number >= 1, got an integer of 401 digits"


def test_a_warning_from_a_file_whose_path_starts_like_the_packages_is_the_callers():
    """`warn_user` attributes a warning to the first frame outside the package's folder: a
    user's script beside it whose name starts with the folder's (taichi_star_demo.py) is
    outside (the folder's path without its separator took it for the package's: a mutation
    audit, 2026-12)."""
    import warnings

    from taichi_star.checks import PACKAGE_FOLDER, warn_user

    script = PACKAGE_FOLDER.rstrip("/\\") + "_demo.py"
    code = compile("def call():\n    warn('told')\n", script, "exec")
    namespace = {"warn": warn_user}
    exec(code, namespace)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        namespace["call"]()
    assert [(w.filename, w.lineno, str(w.message)) for w in caught] == [(script, 2, "told")]
