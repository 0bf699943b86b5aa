"""The Taichi runtime of this process: initialisation, CPU threads and the engine cache.

Taichi is initialised once per process (`ti.init` is process-wide), so there is one `Runtime` per
process, reached through `Runtime.current()`. It initialises Taichi lazily on the first
simulation (importing taichi_star does nothing), re-initialises only when the arch or the
precision changes, and keeps one compiled engine per (topology, terms, integrator, capacity).
"""

from __future__ import annotations

import contextlib
import io
import weakref
from typing import Dict, List, Optional, Tuple

import taichi as ti

from .engine import BatchEngine
from .integrators import INTEGRATORS
from .model import BatchModel, build_model
from .params import SolverConfig

ARCHS = ("cpu", "gpu", "cuda", "vulkan", "metal")
MIN_CAPACITY = 64
PARALLEL_LOOP_MINIMUM = 1024
"""Taichi 1.7's CPU backend parallelises a range-for only from about this many iterations."""
GPU_BLOCK_DIM = 32
"""Threads (one instance each) per GPU block; chosen by `python -m studies bench --arch gpu`."""
GPU_INSTANCE_MINOR = True
"""GPU layout of the per-instance fields: instance-minor (coalesced); chosen by the same bench."""


def available_archs() -> List[str]:
    """The arch names this machine can run ("cpu" always; "gpu" when one of the GPU backends
    is available)."""
    names = ["cpu"]
    for name in ("cuda", "vulkan", "metal"):
        if ti.lang.misc.is_arch_supported(getattr(ti, name)):
            names.append(name)
    if len(names) > 1:
        names.insert(1, "gpu")
    return names


def check_arch(arch: str) -> str:
    """`arch` if this machine has it; else ValueError naming the available ones."""
    if arch not in ARCHS:
        raise ValueError(f"arch must be one of {list(ARCHS)}, got {arch!r}")
    if arch != "cpu":
        available = available_archs()
        if arch not in available:
            raise ValueError(f"arch {arch!r} is not available on this machine; available: "
                             f"{available}")
    return arch


def batch_capacity(batch_size: int) -> int:
    """Engine capacity for a batch: the next power of two, at least MIN_CAPACITY, so that
    batches of similar size share one compiled engine (padding instances are inactive and cost
    nothing; every small batch shares the 64-instance engine, which saves a compilation of
    several seconds per batch size)."""
    return max(MIN_CAPACITY, 1 << max(batch_size - 1, 0).bit_length())


class Runtime:
    """See the module docstring. `cpu_threads` (None: Taichi's default, all cores) and
    `log_level` take effect at the next initialisation."""

    _current: Optional["Runtime"] = None

    def __init__(self):
        self.arch: Optional[str] = None
        self.precision: Optional[str] = None
        self.cpu_threads: Optional[int] = None
        self.gpu_block_dim = GPU_BLOCK_DIM
        self.gpu_instance_minor = GPU_INSTANCE_MINOR
        self.log_level = ti.WARN
        self.engines: Dict[tuple, BatchEngine] = {}
        self.leases: Dict[tuple, List[Tuple[BatchEngine, weakref.ref]]] = {}

    @classmethod
    def current(cls) -> "Runtime":
        """This process's runtime (created on first use)."""
        if cls._current is None:
            cls._current = cls()
        return cls._current

    def configure(self, cpu_threads: Optional[int] = None, log_level=None):
        """Settings for the next initialisation (a Dask worker or a worker process calls this
        before its first simulation); forces a re-initialisation if Taichi is up."""
        self.cpu_threads = cpu_threads
        if log_level is not None:
            self.log_level = log_level
        self.arch = None

    def ensure(self, arch: str = "cpu", precision: str = "f64"):
        """Initialise Taichi for arch and precision unless it already is (ValueError for an
        arch this machine does not have)."""
        check_arch(arch)
        if self.arch == arch and self.precision == precision:
            return
        threads = {} if self.cpu_threads is None else {"cpu_max_num_threads": self.cpu_threads}
        # ti.init prints "[Taichi] Starting on arch=..." unconditionally; warnings still go to
        # Taichi's logger
        with contextlib.redirect_stdout(io.StringIO()):
            ti.init(arch=getattr(ti, arch), default_fp=ti.f64 if precision == "f64" else ti.f32,
                    fast_math=False, offline_cache=True, log_level=self.log_level, **threads)
        self.arch, self.precision = arch, precision
        self.engines.clear()
        self.leases.clear()

    def configure_gpu(self, block_dim: int = GPU_BLOCK_DIM, instance_minor: bool = GPU_INSTANCE_MINOR):
        """GPU launch and layout settings of the engines built from now on (for benchmarks that
        compare them; the defaults are the measured best)."""
        if block_dim < 1 or block_dim > 1024 or block_dim & (block_dim - 1):
            raise ValueError(f"block_dim must be a power of two in [1, 1024], got {block_dim}")
        self.gpu_block_dim = int(block_dim)
        self.gpu_instance_minor = bool(instance_minor)

    def loop_spread(self, capacity: int) -> int:
        """Iterations of the engine's parallel loop per instance: on the CPU enough to reach
        PARALLEL_LOOP_MINIMUM iterations (below that Taichi runs the loop on one thread)."""
        if self.arch != "cpu":
            return 1
        return max(1, -(-PARALLEL_LOOP_MINIMUM // capacity))

    def new_engine(self, model: BatchModel, solver: SolverConfig) -> BatchEngine:
        """A new engine (its own device state) for this batch. Taichi must be initialised
        (`ensure`)."""
        capacity = batch_capacity(model.batch_size)
        gpu = self.arch != "cpu"
        return BatchEngine(model, capacity, INTEGRATORS[solver.integrator](),
                           instances_per_block=self.gpu_block_dim if gpu else 1,
                           loop_spread=self.loop_spread(capacity),
                           instance_minor=gpu and self.gpu_instance_minor)

    def engine_key(self, model: BatchModel, solver: SolverConfig) -> tuple:
        """What an engine is compiled for: topology and terms, integrator, capacity and, on a
        GPU, its launch and layout settings."""
        gpu = (self.gpu_block_dim, self.gpu_instance_minor) if self.arch != "cpu" else ()
        return (model.engine_key, solver.integrator, batch_capacity(model.batch_size)) + gpu

    def lease_engine(self, model: BatchModel, solver: SolverConfig, owner) -> BatchEngine:
        """An engine of its own for `owner` (a Simulator) while the owner lives: one whose
        previous owner is gone is reused (no recompilation), else a new one."""
        key = self.engine_key(model, solver)
        leases = self.leases.setdefault(key, [])
        for index, (engine, holder) in enumerate(leases):
            if holder() is None:
                leases[index] = (engine, weakref.ref(owner))
                return engine
        engine = self.new_engine(model, solver)
        leases.append((engine, weakref.ref(owner)))
        return engine

    def engine_for(self, model: BatchModel, solver: SolverConfig) -> BatchEngine:
        """The cached engine for this batch's topology, terms, integrator and capacity (created
        on first use), loaded with the batch at rest, its gaits firing every period."""
        key = self.engine_key(model, solver)
        if key not in self.engines:
            self.engines[key] = self.new_engine(model, solver)
        engine = self.engines[key]
        engine.load(model, solver)
        return engine


def prepare_engine(params, solver: SolverConfig = SolverConfig(), arch: str = "cpu") -> BatchEngine:
    """For benchmarks and tools that drive the engine directly: Taichi initialised, the batch's
    engine built (or reused from the cache) and loaded with the batch at rest."""
    model = build_model(params)
    runtime = Runtime.current()
    runtime.ensure(arch, solver.precision)
    return runtime.engine_for(model, solver)
