"""The runtime's compiler settings on the CPU: Taichi's control-flow-graph optimisation is off
(`runtime.CPU_CFG_OPTIMISATION`). That the engines compute the same bits with the advanced
passes on and off: test_bench_quick; with the CFG optimisation on and off (the sensitive
engine compiles for ~50 s with it): `results/bench_cfg_optimisation`."""

import pytest
import taichi as ti

from taichi_star.runtime import CPU_CFG_OPTIMISATION, Runtime


def test_taichi_runs_without_the_cfg_optimisation_on_the_cpu():
    """And with the runtime's other settings as configured: the advanced optimisation as
    `kernel_optimisation` says, and Taichi's warnings shown (the runtime starts Taichi at
    ERROR, then sets the configured level: a mutation audit, 2026-12, found neither read)."""
    runtime = Runtime.current()
    runtime.ensure("cpu", "f64")
    assert CPU_CFG_OPTIMISATION is False and runtime.cpu_cfg_optimisation is False
    assert ti.lang.impl.current_cfg().cfg_optimization is False
    assert ti.lang.impl.current_cfg().advanced_optimization is runtime.kernel_optimisation
    assert ti._logging.is_logging_effective("warn")


def test_configure_compiler_sets_both_settings_for_the_next_initialisation():
    runtime = Runtime()
    runtime.arch = "cpu"
    runtime.configure_compiler(True, True)
    assert (runtime.kernel_optimisation, runtime.cpu_cfg_optimisation) == (True, True)
    assert runtime.arch is None  # re-initialised at the next simulation
    runtime.configure_compiler(False)  # None: the default
    assert (runtime.kernel_optimisation, runtime.cpu_cfg_optimisation) == (False, False)


@pytest.mark.parametrize("arguments, name", [(("on",), "kernel_optimisation"),
                                             ((True, 1), "cpu_cfg_optimisation")])
def test_configure_compiler_takes_only_bools(arguments, name):
    with pytest.raises(ValueError, match=f"^{name} must be True or False, got"):
        Runtime().configure_compiler(*arguments)
