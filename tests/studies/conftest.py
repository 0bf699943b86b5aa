"""Fixtures shared by the study tests."""

import pytest

import taichi_star


@pytest.fixture
def no_compute(monkeypatch):
    """Any simulation fails the test: argument errors must come before compute."""
    def forbidden(*args, **kwargs):
        raise AssertionError("simulate was called despite invalid arguments")
    monkeypatch.setattr("taichi_star.batch.tasks.simulate", forbidden)
    monkeypatch.setattr(taichi_star, "simulate", forbidden)
