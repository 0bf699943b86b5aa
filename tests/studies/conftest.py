"""Fixtures shared by the study tests."""

import contextlib
import importlib
import warnings

import pytest

import taichi_star
import studies


def study_modules():
    """Every module of the studies package, imported (a study whose extra is missing is left
    out: it cannot run either)."""
    modules = []
    for name in (*studies.study_names(), *studies.HELPERS):
        try:
            modules.append(importlib.import_module(f"studies.{name}"))
        except ImportError:
            continue
    return modules


@pytest.fixture
def no_compute(monkeypatch):
    """Any simulation fails the test: argument errors must come before compute. Patched where
    the library runs a batch's chunks, in the package, and in every study module that bound
    `simulate` by name (`from taichi_star import simulate`, which the package's patch does not
    reach); the modules are imported first, so that none binds the forbidden function while
    the patch is on and keeps it after."""
    def forbidden(*args, **kwargs):
        raise AssertionError("simulate was called despite invalid arguments")
    modules = study_modules()
    monkeypatch.setattr("taichi_star.batch.tasks.simulate", forbidden)
    monkeypatch.setattr(taichi_star, "simulate", forbidden)
    for module in modules:
        if getattr(module, "simulate", None) is taichi_star.simulation.simulate:
            monkeypatch.setattr(module, "simulate", forbidden)


@pytest.fixture
def warnings_before_call(monkeypatch):
    """A context manager (owner, name) -> (caught, seen): every warning of its block recorded
    ("always"), and in `seen`, per call of `owner.name` in the block, the messages told before
    that call; `owner.name` is restored when the block ends. For a study that must tell
    something before it builds what the call builds."""
    @contextlib.contextmanager
    def recording(owner, name):
        seen = []
        original = getattr(owner, name)
        with monkeypatch.context() as patch, warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")

            def spy(*args, **kwargs):
                seen.append([str(w.message) for w in caught])
                return original(*args, **kwargs)
            patch.setattr(owner, name, spy)
            yield caught, seen
    return recording


class PastTheChecks(Exception):
    """A study got past its checks to a stubbed next step (`checked_run`): nothing ran."""


@pytest.fixture
def checked_run(capsys):
    """(stub, run) for a study's checks alone: `stub` stands in for its first step after them
    (it raises PastTheChecks); `run(argv, refused)` runs `python -m studies` on argv, asserting
    exit status 2 where `refused` and that the stub was reached otherwise, and returns (its
    stderr, the messages of its LongWorkWarnings)."""
    from studies.__main__ import main as studies_main

    def stub(*args, **kwargs):
        raise PastTheChecks

    def run(argv, refused):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            if refused:
                assert studies_main(argv) == 2
            else:
                with pytest.raises(PastTheChecks):
                    studies_main(argv)
        return capsys.readouterr().err, [str(w.message) for w in caught
                                         if w.category is taichi_star.LongWorkWarning]

    return stub, run
