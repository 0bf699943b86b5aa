"""Fixtures shared by the study tests."""

import importlib

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
