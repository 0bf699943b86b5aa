"""The runtime's settings that need no Taichi: the compiler default and its environment
variable."""

import pytest

from taichi_star import runtime


@pytest.mark.parametrize("value, expected", [("", runtime.KERNEL_OPTIMISATION), ("0", False),
                                             ("1", True), (" 1 ", True)])
def test_kernel_optimisation_default_follows_the_environment(monkeypatch, value, expected):
    monkeypatch.setenv(runtime.KERNEL_OPTIMISATION_ENV, value)
    assert runtime.kernel_optimisation_default() is expected
    assert runtime.Runtime().kernel_optimisation is expected


@pytest.mark.parametrize("value", ["yes", "2", "off"])
def test_a_bad_kernel_optimisation_variable_is_named_in_the_error(monkeypatch, value):
    monkeypatch.setenv(runtime.KERNEL_OPTIMISATION_ENV, value)
    with pytest.raises(ValueError, match=rf"{runtime.KERNEL_OPTIMISATION_ENV} must be 0 or 1, "
                                         rf"got '{value}'"):
        runtime.kernel_optimisation_default()


def test_configure_compiler_takes_only_a_bool():
    with pytest.raises(ValueError, match="kernel_optimisation must be True or False, got 'on'"):
        runtime.Runtime().configure_compiler("on")
