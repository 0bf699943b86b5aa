"""Which engines compile with Taichi's advanced IR optimisation: the runtime's rule (a sensitive
engine on the CPU only with SENSITIVE_KERNEL_OPTIMISATION), and that an engine's stepping
kernels compile under its own setting, whatever Taichi was initialised with. (That the passes
change no bits: test_bench_quick for the plain engine; for the sensitive engine, whose
optimised compile takes ~50 s, `results/` measures it, docs/performance.md.)"""

import itertools

import pytest
import taichi as ti

from taichi_star import SolverConfig, StarParams
from taichi_star.engine import advanced_optimisation
from taichi_star.model import build_model
from taichi_star.runtime import SENSITIVE_KERNEL_OPTIMISATION, Runtime


@pytest.fixture
def config():
    Runtime.current().ensure("cpu", "f64")
    return ti.lang.impl.current_cfg()


BOTH_TIMES_BOTH = list(itertools.product([True, False], [True, False]))


@pytest.mark.parametrize("initial, enabled", BOTH_TIMES_BOTH)
def test_the_setting_holds_inside_and_is_restored_after(config, monkeypatch, initial, enabled):
    monkeypatch.setattr(config, "advanced_optimization", initial)
    with advanced_optimisation(enabled):
        assert config.advanced_optimization is enabled
    assert config.advanced_optimization is initial
    with advanced_optimisation(None):  # None: as initialised
        assert config.advanced_optimization is initial
    with pytest.raises(RuntimeError), advanced_optimisation(enabled):
        raise RuntimeError("a kernel failed to compile")
    assert config.advanced_optimization is initial


def rule(arch, passes, sensitive_passes):
    runtime = Runtime()
    runtime.arch = arch
    runtime.kernel_optimisation, runtime.sensitive_kernel_optimisation = passes, sensitive_passes
    return runtime


@pytest.mark.parametrize("passes, sensitive_passes", BOTH_TIMES_BOTH)
def test_only_a_sensitive_cpu_engine_needs_both_settings(passes, sensitive_passes):
    cpu, gpu = rule("cpu", passes, sensitive_passes), rule("gpu", passes, sensitive_passes)
    assert cpu.engine_kernel_optimisation(sensitive=False) is passes
    assert cpu.engine_kernel_optimisation(sensitive=True) is (passes and sensitive_passes)
    assert gpu.engine_kernel_optimisation(sensitive=False) is passes
    assert gpu.engine_kernel_optimisation(sensitive=True) is passes  # not measured on a GPU


def test_by_default_a_sensitive_engine_compiles_without_the_passes():
    assert SENSITIVE_KERNEL_OPTIMISATION is False
    runtime = Runtime()
    assert runtime.sensitive_kernel_optimisation is False
    runtime.configure_compiler(True, True)
    assert runtime.sensitive_kernel_optimisation is True
    runtime.configure_compiler(True)  # None: back to the default
    assert runtime.sensitive_kernel_optimisation is False


def test_each_engine_launches_its_stepping_kernels_under_its_own_setting(config, monkeypatch):
    """A runtime with the passes on builds a sensitive engine without them and a plain one with
    them; each launch (where a kernel compiles the first time) sees the engine's setting, and
    Taichi's is back to what it was after it."""
    initial = config.advanced_optimization
    runtime = rule("cpu", True, False)
    model = build_model([StarParams()])
    seen = []
    for sensitive in (True, False):
        engine = runtime.new_engine(model, SolverConfig(), sensitive)
        monkeypatch.setattr(engine, "advance_kernel",
                            lambda steps: seen.append(config.advanced_optimization))
        monkeypatch.setattr(engine, "advance_adaptive_kernel",
                            lambda steps: seen.append(config.advanced_optimization))
        engine.advance(1)
        engine.advance_adaptive(1)
        assert config.advanced_optimization is initial
    assert seen == [False, False, True, True]
