import os

import pytest

from taichi_star.runtime import KERNEL_OPTIMISATION_ENV


def pytest_configure(config):
    # the suite's runs are short, mostly compilation: without Taichi's IR optimisation passes an
    # engine compiles in well under half the time and computes the same bits
    # (test_bench_quick checks); set here, it reaches every worker process the tests start
    os.environ.setdefault(KERNEL_OPTIMISATION_ENV, "0")


def pytest_addoption(parser):
    parser.addoption("--arch", default="cpu",
                     help="Taichi arch for the engine tests that take the `arch` fixture "
                          "(cpu, gpu): `pytest tests/model --arch gpu` runs them on a GPU")


@pytest.fixture(scope="session")
def arch(request):
    """The arch the engine tests run on (--arch; ValueError if this machine lacks it)."""
    from taichi_star.runtime import check_arch

    return check_arch(request.config.getoption("--arch"))


@pytest.fixture(scope="session")
def taichi_cpu():
    """Taichi on the CPU in f64, initialised once for the tests that call kernels directly
    (the same runtime `simulate` uses, so it does not re-initialise)."""
    from taichi_star.runtime import Runtime

    Runtime.current().ensure("cpu", "f64")
