import contextlib
import errno
import importlib.util
import os
import signal
from pathlib import Path

import pytest

from taichi_star import provenance
from taichi_star.runtime import KERNEL_OPTIMISATION_ENV


def pytest_configure(config):
    # the suite's runs are short, mostly compilation: without Taichi's IR optimisation passes an
    # engine compiles in 0.45-0.7x the time (docs/reliability.md) and computes the same bits
    # (test_bench_quick checks); set here, it reaches every worker process the tests start
    os.environ.setdefault(KERNEL_OPTIMISATION_ENV, "0")


@pytest.fixture(scope="session")
def tool():
    """A script of tools/ imported as a module, by name: tool("bench_builds")."""
    def load(name: str):
        path = Path(__file__).resolve().parents[1] / "tools" / f"{name}.py"
        spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module

    return load


@pytest.fixture
def full_disk(monkeypatch):
    """A context manager within which every `provenance.write_atomic` fails as on a full disk:
    its fsync raises ENOSPC after the data went to the temporary file, before the rename."""
    def no_space(descriptor):
        raise OSError(errno.ENOSPC, "No space left on device")

    @contextlib.contextmanager
    def patched():
        with monkeypatch.context() as context:
            context.setattr(provenance.os, "fsync", no_space)
            yield

    return patched


@pytest.fixture
def interruptible():
    """SIGINT raising KeyboardInterrupt in this process for the test, as in a terminal or a
    notebook: a suite started in the background by a non-interactive shell (`pytest ... &`)
    inherits SIGINT ignored (POSIX), and Python leaves an ignored SIGINT ignored, so the signal
    never reached the run: every whole-suite run of tools/suite_builds.py, started so, failed
    test_batch_interrupt's interrupt test with SIG_IGN in its message (2026-12-03)."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


@pytest.fixture
def memory_budget(monkeypatch):
    """`memory_budget(needed)` yields False, then True: the available memory set so that
    `needed` bytes are exactly the budget (MEMORY_SHARE of it: accepted), then a byte over it
    (refused); the boundary of every memory refusal."""
    from taichi_star import runtime

    def cases(needed: float):
        for available, refused in ((needed / runtime.MEMORY_SHARE, False),
                                   ((needed - 1) / runtime.MEMORY_SHARE, True)):
            monkeypatch.setattr(runtime, "available_memory_bytes", lambda: available)
            yield refused
    return cases


@pytest.fixture
def simulated_chunks(monkeypatch):
    """The robots of each chunk `simulate` runs from now on (`simulation._simulate_chunk`,
    spied on: the chunk still runs), so that a batch run whole (equal to itself, bitwise)
    cannot pass for a streamed one."""
    from taichi_star import simulation

    chunks = []
    run_chunk = simulation._simulate_chunk

    def spy(params, *args, **kwargs):
        chunks.append(list(params))
        return run_chunk(params, *args, **kwargs)

    monkeypatch.setattr(simulation, "_simulate_chunk", spy)
    return chunks


def pytest_addoption(parser):
    parser.addoption("--arch", default="cpu",
                     help="Taichi arch for the engine tests that take the `arch` fixture "
                          "(cpu, gpu): `pytest tests/model --arch gpu` runs them on a GPU")


FIRST = (
    # these re-initialise Taichi (the kernel optimisation switched on, f32: the bench and simd
    # quick runs, in the slow tier, and test_reliability's precision switch): every engine the
    # worker compiled before is dropped, and the files after them compile theirs again
    "tests/studies/test_bench.py", "tests/studies/test_simd.py",
    "tests/model/test_reliability.py",
    # then the longest files (measured on both tiers: 20-100 s each on 2 cores), so that no long
    # file is left to run alone at the end
    "tests/model/test_engine.py", "tests/model/test_wake.py", "tests/model/test_sensitivities.py",
    "tests/model/test_envs.py", "tests/studies/test_distributed.py",
    "tests/model/test_simulator.py", "tests/studies/test_work_precision.py",
    "tests/studies/test_model_select.py", "tests/studies/test_control_studies.py",
)
"""Files run first, in this order (the rest follow in collection order); with
`--no-loadscope-reorder` (pyproject's addopts) pytest-xdist hands the files to its workers in
this order, each file whole to one worker."""


def pytest_collection_modifyitems(config, items):
    rank = {path: index for index, path in enumerate(FIRST)}
    root = config.rootpath
    missing = [path for path in FIRST if not (root / path).is_file()]
    if missing:  # a renamed or removed file would silently lose its place
        raise pytest.UsageError(f"tests/conftest.py FIRST names missing files: {missing}")

    def file_rank(item):
        try:
            path = item.path.relative_to(root).as_posix()
        except ValueError:
            return len(FIRST)
        return rank.get(path, len(FIRST))

    items.sort(key=file_rank)  # stable: each file's tests keep their order


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
