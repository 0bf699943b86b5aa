import pytest


@pytest.fixture(scope="session")
def taichi_cpu():
    """Taichi on the CPU in f64, initialised once for the tests that call kernels directly
    (the same runtime `simulate` uses, so it does not re-initialise)."""
    from taichi_star.runtime import Runtime

    Runtime.current().ensure("cpu", "f64")
