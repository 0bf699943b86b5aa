"""The Taichi runtime of this process: initialisation, CPU threads and the engine cache.

Taichi is initialised once per process (`ti.init` is process-wide), so there is one `Runtime` per
process, reached through `Runtime.current()`. It initialises Taichi lazily on the first
simulation (importing taichi_star does nothing), re-initialises only when the arch or the
precision changes, and keeps the engines it compiled, per (topology, terms, integrator,
capacity), for the `simulate` calls and Simulators that follow (a Simulator holds one while it
lives; a call uses a free one while it runs).

Taichi keeps compiled kernels in an offline cache shared by every process of the user
(~/.cache/taichi), written when the process exits (`_quiet_exit`). Its key includes the fields'
identities, which follow the order in which a process builds its engines: a process loads the
kernels of an earlier one that built the same engines in the same order. Processes running at
once (a batch's worker processes, two studies) take turns at its lock file; one that finds it
taken prints "Lock .../ticache.lock failed. Please run 'ti cache clean' and try again" and
simply compiles without loading the cache, or leaves its new kernels out of it at exit.
Nothing is wrong and nothing needs cleaning, so the runtime silences exactly those two moments:
it opens the cache (a trivial kernel) and exits at log level ERROR; Taichi's warnings in between
are shown at the user's level (`taichi_log_level`: TI_LOG_LEVEL, else "warn").

Compiling a kernel, Taichi's front end writes the source position of every statement and
expression it meets (the line, and an excerpt with a caret line under it, each line passed
through textwrap) for the compiled code's debug information and its error messages. An
engine's functions are inlined wherever they are called, so the same positions are written over
and over: the paper preset's sensitive engine asks for ~80,000 of them, ~6,000 distinct, and
writing them took 15-20 % of its first call. `memoise_source_positions` makes Taichi write each
distinct one once per process; the texts, and so Taichi's messages, are unchanged. For the same
reason it read each function's source from its file at every call it inlined (~4,200 reads for
the 14 engines of `work_precision --quick`, 14 % of that run's profile with a warm cache):
`memoise_function_sources` makes it read each function's once per process.

Taichi's runtime is one per process and not safe for calls from several threads at once: two
`simulate` calls from two threads drew the same free engine and interleaved their kernels, and
both returned other numbers with status "ok" (an audit, 2026-12: four threads, four gaits, every
speed wrong, e.g. A1+A2 -7.8 mm/s against 2.0 alone). Every public call that uses Taichi
(`simulate`, each method of a `Simulator` that reads or moves its robots, so every environment
step) holds `RUNTIME_LOCK` while it runs (`one_call_at_a_time`): calls from several threads
(Dask's threaded scheduler, a thread pool, a notebook's background thread) take turns and each
gets the numbers it would get alone. Runs in parallel belong in one batch or in worker
processes (`batch.run_batch(workers=N)`).
"""

from __future__ import annotations

import atexit
import contextlib
import functools
import gc
import io
import os
import sys
import threading
import weakref
from dataclasses import dataclass
from typing import Dict, List, Optional

import numpy as np
import taichi as ti
from taichi.lang import impl
# Taichi imports its matrix functions at the first kernel compile, and their decorators inspect
# frames inside a bare `except:`, which swallowed a Ctrl-C landing there (0.9 s into `python -m
# studies fig4c`, which then ran whole: an audit, 2026-12): imported here, while the package's
# import holds Ctrl-C back (`interrupts`)
import taichi.lang.matrix_ops  # noqa: F401

from .checks import check_flag, is_whole, warn_user
from .engine import LOCKSTEP_MINIMUM_BATCH, BatchEngine, elimination_plan
from .integrators import INTEGRATORS
from .model import BatchModel, build_model
from .params import SolverConfig, check_number

# the public names (docs/api.md), those the studies use among them (tests/test_layering.py)
__all__ = ["Runtime", "available_archs", "CPU_LANES", "LANES_MINIMUM_WORK", "GPU_BLOCK_DIM",
           "GPU_INSTANCE_MINOR", "kernel_optimisation_default", "taichi_log_level",
           "check_batch_memory",
           "MemoryBudgetError", "RUNTIME_LOCK", "one_call_at_a_time"]

ARCHS = ("cpu", "gpu", "cuda", "vulkan", "metal")
RUNTIME_LOCK = threading.RLock()
"""Held by every public call that uses Taichi while it runs (module docstring); re-entrant, so
a call may make others (a planner's `simulate`, an environment's Simulator)."""


def one_call_at_a_time(function):
    """`function`, run holding `RUNTIME_LOCK`: a call from another thread waits for it."""
    @functools.wraps(function)
    def holding_the_runtime(*args, **kwargs):
        with RUNTIME_LOCK:
            return function(*args, **kwargs)
    return holding_the_runtime

MIN_CAPACITY = 64
PARALLEL_LOOP_MINIMUM = 1024
"""Taichi 1.7's CPU backend parallelises a range-for only from about this many iterations."""
MAX_CPU_THREADS = 4096
"""Most CPU threads `configure` gives Taichi: above the cores of the largest servers, a bound
against a mistyped number only."""
GPU_BLOCK_DIM = 32
"""Threads (one instance each) per GPU block; chosen by `python -m studies bench --arch gpu`."""
GPU_INSTANCE_MINOR = True
"""GPU layout of the per-instance fields: instance-minor (coalesced); chosen by the same bench."""
CPU_LANES = 8
"""Instances whose Newton systems the CPU's vector units factor and solve together in an engine
with lanes (`engine.BatchEngine` `lanes`: a group's instances interleave their solves round by
round, and with Newton's Jacobian from `engine.LOCKSTEP_MINIMUM_BATCH` simulated instances their
systems are solved in lockstep; the same bits as one at a time)."""
LANES_MINIMUM_WORK = 4_000_000
"""Robot-steps (simulated instances × fixed steps) from which a `simulate` call's engine has
CPU_LANES lanes by default, when it runs fixed steps with Newton's Jacobian on at least
`engine.LOCKSTEP_MINIMUM_BATCH` instances and carries no tangents (`Runtime.engine_lanes`).
The lanes step 1.04-1.23x as fast, but their kernel compiles in ~7 s against ~2.6 s with an
empty cache and loads from Taichi's offline cache in ~3 s against ~0.8 s in each new process;
from this much work they no longer lose: a call of 4.0 M robot-steps (1,024 robots, 3.91 s)
took as long with and without them with an empty cache and ~3 % less with a warm one (a
2-core AMD EPYC; as long with a warm one on a 2-core Intel Xeon, whose cache holds the batch's
matrices, so that one instance's LU is as fast as the lanes'). Shorter calls, adaptive steps,
the chord Jacobian, tangents and Simulators (whose work is not known ahead) run one instance
at a time (docs/performance.md, "SIMD across instances")."""
KERNEL_OPTIMISATION = True
"""Taichi's advanced IR optimisation passes (`ti.init(advanced_optimization=...)`): on, an engine
steps 10-13 % faster; off, it compiles faster (~0.7x as long on the CPU, where the passes leave
out the CFG optimisation: CPU_CFG_OPTIMISATION); the bits are the same either way
(`python -m studies bench --kernel-optimisation on,off` measures both and compares the final
states). `Runtime.configure_compiler` changes it for this process; the environment variable
KERNEL_OPTIMISATION_ENV = "0" turns it off for this process and the worker processes it starts
(what the test suite does: its many short runs are mostly compilation)."""
KERNEL_OPTIMISATION_ENV = "TAICHI_STAR_KERNEL_OPTIMISATION"
CPU_CFG_OPTIMISATION = False
"""Whether the passes of KERNEL_OPTIMISATION include Taichi's control-flow-graph optimisation
(`ti.init(cfg_optimization=...)`: store-to-load forwarding and dead-store elimination over a
whole kernel, by reaching-definition and liveness analyses) on the CPU. Off: on the engine's
large kernels those analyses were most of the compilation (the sensitive engine's first call
~48 s, ~37 s of it in them) and LLVM, which compiles the kernels after, does the same work, so
the engines step as fast and compute the same bits without them (measured:
results/bench_cfg_optimisation, docs/performance.md). On a GPU Taichi's default (on) stays:
not measured there. `Runtime.configure_compiler` changes it for comparisons."""


def kernel_optimisation_default() -> bool:
    """KERNEL_OPTIMISATION unless the environment variable KERNEL_OPTIMISATION_ENV says "0"/"1"
    (ValueError for anything else)."""
    value = os.environ.get(KERNEL_OPTIMISATION_ENV, "").strip()
    if value not in ("", "0", "1"):
        raise ValueError(f"{KERNEL_OPTIMISATION_ENV} must be 0 or 1, got {value!r}")
    return KERNEL_OPTIMISATION if value == "" else value == "1"


def available_archs() -> List[str]:
    """The arch names this machine can run ("cpu" always; "gpu" when one of the GPU backends
    is available)."""
    names = ["cpu"]
    # probing a backend that is not there logs Taichi's own warning ("libcuda.so lib not
    # found"), which would print before the one-line error naming the available archs
    level = next(name for name in ("trace", "debug", "info", "warn", "error", "critical")
                 if ti._logging.is_logging_effective(name))
    ti.set_logging_level(ti.ERROR)
    try:
        for name in ("cuda", "vulkan", "metal"):
            if ti.lang.misc.is_arch_supported(getattr(ti, name)):
                names.append(name)
    finally:
        ti.set_logging_level(level)
    if len(names) > 1:
        names.insert(1, "gpu")
    return names


def check_arch(arch: str) -> str:
    """`arch` if this machine has it; else ValueError naming the available ones."""
    if not isinstance(arch, str) or arch not in ARCHS:
        raise ValueError(f"arch must be one of {list(ARCHS)}, got {arch!r}")
    if arch != "cpu":
        available = available_archs()
        if arch not in available:
            raise ValueError(f"arch {arch!r} is not available on this machine; available: "
                             f"{available}")
    return arch


MEMORY_SHARE = 0.8
"""An engine may take at most this share of the memory the machine has available."""
STATE_VECTORS_PER_NODE = 10
"""2-vectors per node an engine keeps per instance: 8 state fields and the right-hand side, plus
mass and inertia counted as one."""
FIXED_BYTES_PER_INSTANCE = 512
"""Per-instance scalars (status, counters, times, actuator schedules), rounded up."""


def engine_bytes(model: BatchModel, precision: str, least_batch: int = 0) -> int:
    """Memory (bytes) of an engine for this batch (built as for at least `least_batch`
    instances, `engine_capacity`): its capacity times, per instance, the Newton matrix (2×2
    blocks of the elimination pattern), the node vectors, the terms' coefficients and
    histories, and the fixed scalars."""
    scalar = 8 if precision == "f64" else 4
    slots = Runtime.current().matrix_slots(model)
    coefficients = sum(values[0].size for table in model.coefficients.values()
                       for values in table.values())
    classes = [cls for cls, _ in model.terms_used]
    histories = sum(int(np.prod(shape)) for cls in classes
                    for shape in cls.history(model.topology, classes).values())
    per_instance = (scalar * (4 * slots + 2 * STATE_VECTORS_PER_NODE * model.topology.n_nodes
                              + coefficients + histories) + FIXED_BYTES_PER_INSTANCE)
    return engine_capacity(model.batch_size, least_batch) * per_instance


def engine_capacity(batch_size: int, least_batch: int = 0) -> int:
    """The capacity of an engine for `batch_size` instances, built as for `least_batch` where
    that is more: `simulate` streams a batch's chunks through its first chunk's engine
    (`simulation._simulate_chunk`)."""
    return batch_capacity(max(batch_size, least_batch))


def available_memory_bytes() -> Optional[int]:
    """MemAvailable of /proc/meminfo (None where there is no such file)."""
    try:
        with open("/proc/meminfo") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def check_memory(model: BatchModel, precision: str, arch: str, least_batch: int = 0):
    """ValueError, before anything is allocated, when a CPU engine for this batch (built as for
    at least `least_batch` instances) would take more than MEMORY_SHARE of the available
    memory (`simulate` streams a large batch in chunks that fit, so this refuses only a machine
    without room for the smallest engine)."""
    if arch != "cpu":
        return
    available = available_memory_bytes()
    needed = engine_bytes(model, precision, least_batch)
    if available is not None and needed > MEMORY_SHARE * available:
        raise ValueError(
            f"params: a batch of {model.batch_size} instances needs about {needed / 2**30:.2f} GiB "
            f"for its engine, more than {MEMORY_SHARE:.0%} of the {available / 2**30:.2f} GiB "
            f"available (the memory budget); free memory or run fewer instances")


class MemoryBudgetError(ValueError):
    """A run refused before any compute because it would not fit in memory
    (`check_host_memory`): a ValueError naming the argument to change, which a command line
    can report as a refused input (an animation of 10,000 frames of 255 gaits ended the
    animate study in a traceback: an audit, 2026-12)."""


def check_host_memory(name: str, what: str, needed: float, remedy: str):
    """MemoryBudgetError (a ValueError) naming the argument `name`, before any compute, when
    `needed` bytes of host memory (`what` says for what) are more than MEMORY_SHARE of the
    available memory: the run would end in a MemoryError after its compute, or before it
    while listing its stops (an audit: a 26-s run's shapes lost so); `remedy` says what to
    change."""
    available = available_memory_bytes()
    if available is not None and needed > MEMORY_SHARE * available:
        raise MemoryBudgetError(
            f"{name}: {what} would need about {needed / 2**30:.3g} GiB of memory, more than "
            f"{MEMORY_SHARE:.0%} of the {available / 2**30:.2f} GiB available: {remedy}")


def check_batch_memory(params, precision: str, arch: str, replicas: int = 1):
    """ValueError, before the batch's model is built, when a CPU engine holding all of
    `params` (each with `replicas` instances: sensitivities add them) and the model's arrays
    would take more than MEMORY_SHARE of the available memory; both are measured on the first
    MIN_CAPACITY instances' model, as `stream_chunk_size` does (a Simulator of 10^6 robots
    built its model for 49 s and 6 GB, then failed in NumPy; an audit). Off the CPU the engine
    is on the device and the model alone is counted. Smaller batches are left to
    `check_memory`, on the model itself."""
    count = len(params) * replicas
    if count <= MIN_CAPACITY:
        return
    probe = build_model(params[:MIN_CAPACITY])
    needed = probe.nbytes / probe.batch_size * count
    if arch == "cpu":
        per_instance = engine_bytes(probe, precision) / batch_capacity(probe.batch_size)
        needed += per_instance * batch_capacity(count)
    check_host_memory("params", f"an engine and model of {count:,} instances"
                      if arch == "cpu" else f"a model of {count:,} instances", needed,
                      "run fewer instances at once (simulate streams a batch in chunks that fit)")


RECORDS_REMEDY = "record less often, fewer instances or a shorter run"
"""What to change when a run's records would not fit (`check_host_memory`)."""


CPU_ENGINE_BUDGET_BYTES = 512 * 2**20
"""Largest CPU engine `simulate` builds (bytes): a larger batch is streamed through one engine of
at most this size, chunk by chunk (on the CPU the throughput stops growing with the batch at a
few hundred instances, so chunking costs nothing and bounds the memory of any batch)."""
FREE_ENGINES_BYTES = CPU_ENGINE_BUDGET_BYTES
"""Fields (bytes) of the CPU engines a process keeps for later calls, the one a call or a new
Simulator takes included (that one whatever its size): past it the least recently used engines
that no Simulator holds are destroyed (`Runtime.free_engine`). Every engine was kept: a
notebook's calls of 1,000, 2,000 and 3,000 robots kept 150, 250 and 384 MB of fields, RSS
1.1 GB after the last (an audit, 2026-12). A coarse robot's engine has a few MB of fields,
so the budget holds dozens; what stays of an engine destroyed, its compiled kernels (~20 MB
of the process each), Taichi gives no way to free."""


def stream_chunk_size(params, precision: str, arch: str, replicas: int = 1) -> int:
    """Robots per chunk when `simulate` streams `params` (a validated batch), each simulated as
    `replicas` instances (itself and its sensitivities' replicas), through one engine: all of
    them on a GPU, and on the CPU as many as fit in CPU_ENGINE_BUDGET_BYTES (or MEMORY_SHARE of
    the available memory, if less), in equal chunks (of one robot more or less; the last chunk
    takes the first's engine, `simulation._simulate_chunk`). The per-instance size is measured
    on the first MIN_CAPACITY robots' model; a batch of no more instances than that is never cut
    (the smallest engine holds it, and `check_memory` refuses it where even that does not fit).
    Chunks of the robots' instances, rounded down to whole robots, left a sliver (100 robots
    with one sensitivity as 33, 33, 33 and 1: a review, 2026-12)."""
    if arch != "cpu" or len(params) * replicas <= MIN_CAPACITY:
        return len(params)
    budget = CPU_ENGINE_BUDGET_BYTES
    available = available_memory_bytes()
    if available is not None:
        budget = min(budget, MEMORY_SHARE * available)
    probe = build_model(params[:MIN_CAPACITY])
    per_instance = engine_bytes(probe, precision) / batch_capacity(probe.batch_size)
    fitting = MIN_CAPACITY
    while 2 * fitting * per_instance <= budget:
        fitting *= 2
    robots = max(1, fitting // replicas)
    if len(params) <= robots:
        return len(params)
    chunks = -(-len(params) // robots)
    return -(-len(params) // chunks)


def batch_capacity(batch_size: int) -> int:
    """Engine capacity for a batch: the next power of two, at least MIN_CAPACITY, so that
    batches of similar size share one compiled engine (padding instances are inactive and cost
    nothing; every small batch shares the 64-instance engine, which saves a compilation of
    several seconds per batch size)."""
    return max(MIN_CAPACITY, 1 << max(batch_size - 1, 0).bit_length())


SOURCE_POSITIONS_KEPT = 1 << 16
"""Most source positions `memoise_source_positions` keeps (it starts afresh beyond: a few MB)."""
MEMOISED_TAICHI = (1, 7)
"""Taichi versions (major, minor) whose position writer and source readers
`memoise_source_positions` and `memoise_function_sources` were checked against (what their keys
hold is what those read)."""


def _source_position_key(context, node) -> tuple:
    """Everything the position text of `node` in `context` is made of in Taichi 1.7: the file,
    the function and its offsets, the node's span, and the source lines the span covers (they
    also fix what else the text reads: whether the node is a loop, a branch or a function, and
    where its body begins)."""
    return (context.file, context.func.func.__name__, context.lineno_offset, context.indent,
            node.lineno, node.end_lineno, node.col_offset, node.end_col_offset,
            tuple(context.src[node.lineno - 1:node.end_lineno]))


def memoise_source_positions(context_class=None, taichi_version=ti.__version__) -> bool:
    """Make `context_class.get_pos_info` (Taichi's `ASTTransformerContext`; the module docstring
    says why) return each distinct position's text from a cache, the text the original writes.
    Done once (a second call changes nothing); left alone for a Taichi version other than
    MEMOISED_TAICHI or one without that method. Returns whether the memo is in place."""
    if context_class is None:
        from taichi.lang.ast import ast_transformer_utils
        context_class = getattr(ast_transformer_utils, "ASTTransformerContext", None)
    write = getattr(context_class, "get_pos_info", None)
    if write is None or tuple(taichi_version[:2]) != MEMOISED_TAICHI:
        return False
    if hasattr(write, "unmemoised"):
        return True
    texts: Dict[tuple, str] = {}

    @functools.wraps(write)
    def position(context, node):
        key = _source_position_key(context, node)
        text = texts.get(key)
        if text is None:
            if len(texts) >= SOURCE_POSITIONS_KEPT:
                texts.clear()
            text = texts[key] = write(context, node)
        return text

    position.unmemoised = write
    context_class.get_pos_info = position
    return True


def memoise_function_sources(module=None, taichi_version=ti.__version__) -> bool:
    """Make `module.getsourcelines` and `module.getsourcefile` (Taichi's `kernel_impl`, whose
    front end reads a kernel's or a function's source at every call of it that it compiles; the
    module docstring says why) answer from a cache: per function object (held weakly, so a
    function that is deleted or redefined in a notebook is read afresh) and its code object (a
    function given another `__code__` is read afresh); the lines are a copy each time, as the
    original's are. A function that cannot be held weakly is read as before. Done once (a
    second call changes nothing); left alone for a Taichi version other than MEMOISED_TAICHI or
    a module without those two readers. Returns whether the memo is in place. A function whose
    file is edited while the process runs compiles as it was first read, as its bytecode runs."""
    if module is None:
        from taichi.lang import kernel_impl as module
    readers = [getattr(module, name, None) for name in ("getsourcelines", "getsourcefile")]
    if None in readers or tuple(taichi_version[:2]) != MEMOISED_TAICHI:
        return False
    if all(hasattr(reader, "unmemoised") for reader in readers):
        return True

    def memoised(read, copy):
        answers = weakref.WeakKeyDictionary()

        @functools.wraps(read)
        def answer(function):
            code = getattr(function, "__code__", None)
            try:
                kept = answers.get(function)
            except TypeError:  # not weakly referable: read every time
                return read(function)
            if kept is None or kept[0] is not code:
                kept = answers[function] = (code, read(function))
            return copy(kept[1])

        answer.unmemoised = read
        return answer

    module.getsourcelines = memoised(readers[0], lambda lines: (list(lines[0]), lines[1]))
    module.getsourcefile = memoised(readers[1], lambda path: path)
    return True


@ti.kernel
def _open_kernel_cache():
    """Nothing: compiling it makes Taichi open its offline cache (see the module docstring)."""
    pass


TAICHI_LOG_LEVELS = ("trace", "debug", "info", "warn", "error", "critical", "off")
"""The levels of Taichi's logger, most verbose first (`ti.set_logging_level`)."""


def taichi_log_level() -> str:
    """Taichi's log level between the runtime's quiet moments (module docstring): the user's
    TI_LOG_LEVEL where it names one of `TAICHI_LOG_LEVELS` (Taichi's import refuses any other
    word), else "warn". The runtime gives ti.init a level of its own, which overrode the
    variable for the whole process, with a warning line (an audit, 2026-12)."""
    level = os.environ.get("TI_LOG_LEVEL", "")
    return level if level in TAICHI_LOG_LEVELS else ti.WARN


def _quiet_exit():
    """Taichi's exit, which writes the offline cache, at log level ERROR (module docstring).
    Called explicitly: left to the interpreter's shutdown, Taichi's program was never finalized
    (the engines' kernels and fields keep it alive to the end) and nothing was written, so every
    process compiled every engine again (measured: an empty cache folder after a run)."""
    ti.set_logging_level(ti.ERROR)
    try:
        ti.reset()
    except (RuntimeError, OSError) as error:
        # an offline cache folder it cannot write (a read-only HOME) gave a traceback at every
        # exit, the run's results written (an audit, 2026-12): one line
        print(f"taichi_star: Taichi's offline cache was not written ({error}): the next "
              f"process compiles its kernels again; TI_OFFLINE_CACHE_FILE_PATH names a writable "
              f"folder", file=sys.stderr)


def read_only_cache_note(folder: str) -> Optional[str]:
    """What to tell a user whose offline cache `folder` exists but cannot be written (a shared
    or read-only mount), or None. Taichi takes a lock file in the folder before it loads a
    kernel from it, fails there, and compiles every kernel again, saying nothing once the
    runtime has silenced its lock messages (module docstring): a filled read-only cache was
    used by no run and said by none (an audit, 2026-12: a coarse robot's first call 3.2 s
    against 0.7 s)."""
    if not os.path.isdir(folder) or os.access(folder, os.W_OK):
        return None
    return (f"Taichi's offline cache folder {folder} cannot be written, and Taichi loads no "
            f"kernel from a folder it cannot lock: every process compiles its engines again. "
            f"Set TI_OFFLINE_CACHE_FILE_PATH to a writable folder (a copy of this one keeps its "
            f"kernels)")


@dataclass
class EngineSlot:
    """One engine of the runtime's and who holds it: a weak reference to the Simulator that
    leased it, or None (free; a `simulate` call uses a free engine only while it runs)."""

    engine: BatchEngine
    holder: Optional[weakref.ref] = None
    last_use: int = 0
    """The runtime's count of engines handed out when this one last was (`free_engine`), or
    when the Simulator that held it went (`lease_engine`)."""

    def held(self) -> bool:
        """Whether a living Simulator holds the engine."""
        return self.holder is not None and self.holder() is not None


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
        self.cpu_lanes: Optional[int] = None
        self.kernel_optimisation = kernel_optimisation_default()
        self.cpu_cfg_optimisation = CPU_CFG_OPTIMISATION
        self.log_level = taichi_log_level()
        self.engines: Dict[tuple, List[EngineSlot]] = {}
        """The engines built in this process, per `engine_key`: each free for the next call or
        Simulator, or held by a living Simulator (`free_engine`)."""
        self.uses = 0
        """Engines handed out so far (`free_engine`) and Simulators gone (`lease_engine`): the
        clock of `EngineSlot.last_use`."""
        self.slot_counts: Dict[tuple, int] = {}
        """Newton-matrix blocks per model engine key (`matrix_slots`)."""
        self.started = False
        """Whether Taichi has been started in this process (`ensure`; a re-initialisation
        asked for by `configure` leaves it True)."""
        self.thread_restarts = 0
        """How many times Taichi was started again on another thread (`build_here`)."""
        self.told_read_only_cache = False
        """Whether `ensure` has warned that the offline cache cannot be written
        (`read_only_cache_note`)."""
        self.restart_reason: Optional[str] = None
        """Why Taichi must be started again though arch and precision are as asked (a build
        stopped half way), for `check_no_simulator_lives`' message; None otherwise."""
        self.taichi_thread: Optional[int] = None
        """The thread that started Taichi (`ensure`): the only one it builds fields on
        (`build_here`)."""
        self.forked_after_start = False
        """Whether this process is a fork of one in which Taichi had started (`_after_fork`):
        then it cannot run Taichi (`check_not_forked`)."""
        self.taichi_program = None
        """Taichi's runtime object as `ensure` last started it, the program the engines of
        `engines` live in: a `ti.init` or `ti.reset` made outside `ensure` replaces it, and
        with it every engine built (`program_replaced`)."""
        self.adopted_program = None
        """A program this package started outside `ensure` for kernels of its own
        (`adopt_program`): replaced as a user's is, but not warned of."""

    @classmethod
    def _after_fork(cls):
        """In a forked child: a runtime whose Taichi had started is marked unusable (Taichi's
        thread pool is not in the child, and its first kernel launch hung: an audit, 2026-12,
        a multiprocessing Pool after one `simulate`, gymnasium's AsyncVectorEnv)."""
        if cls._current is not None and cls._current.started:
            cls._current.forked_after_start = True

    def program_replaced(self) -> bool:
        """Whether Taichi was started again outside this package (a user's `ti.init` or
        `ti.reset`) since `ensure` started it: the engines built before are gone with their
        program, and running one aborted the process (an audit, 2026-12)."""
        return self.started and impl.get_runtime() is not self.taichi_program

    def check_engine_usable(self, engine):
        """RuntimeError before `engine`, built earlier, runs (every use of a Simulator's or an
        EngineProfile's engine): where Taichi was started again since it was built, by a
        `ti.init` outside this package (`program_replaced`) or by this package after one (the
        engine is no longer among `engines`: a later `ensure` or `adopt_program` dropped the
        engines of the destroyed program; the first check alone passed once `ensure` had
        started Taichi again, and a Simulator that lived through a study's own `ti.init` ran
        its destroyed engine: a review, 2026-12), or in a forked process (`check_not_forked`)."""
        if self.program_replaced() or not any(slot.engine is engine
                                               for slots in self.engines.values()
                                               for slot in slots):
            raise RuntimeError(
                "Taichi was started again (ti.init or ti.reset outside taichi_star) after this "
                "engine was built, which destroyed it with its program: build the Simulator "
                "(environment, EngineProfile) again, and keep your own Taichi code in another "
                "process or after taichi_star's")
        self.check_not_forked()

    def check_not_forked(self):
        """RuntimeError in a process forked after Taichi had started in its parent (`ensure`,
        and every use of a Simulator's engine: one made by the parent and stepped in the
        child hung)."""
        if self.forked_after_start:
            raise RuntimeError(
                "this process was forked from one in which Taichi had started, and Taichi's "
                "threads do not survive a fork (its first kernel would wait for ever): start "
                "worker processes with the 'spawn' or 'forkserver' method "
                "(multiprocessing.get_context('spawn'), gymnasium's "
                "AsyncVectorEnv(..., context='spawn')), or before the first simulation")

    @classmethod
    def current(cls) -> "Runtime":
        """This process's runtime (created on first use)."""
        if cls._current is None:
            cls._current = cls()
        return cls._current

    def configure(self, cpu_threads: Optional[int] = None, log_level=None):
        """Settings for the next initialisation (a Dask worker or a worker process calls this
        before its first simulation); forces a re-initialisation if Taichi is up.
        `cpu_threads`: Taichi's CPU threads, an integer in [1, MAX_CPU_THREADS] (None: all
        cores); ValueError naming it otherwise."""
        if cpu_threads is not None:
            # 0 made the first simulation kill the process (SIGFPE), -1 or 2.5 fail inside
            # Taichi in its words, True count as 1 thread (an audit, 2026-12)
            cpu_threads = check_number("cpu_threads", cpu_threads, 1, MAX_CPU_THREADS,
                                       integer=True)
        self.cpu_threads = cpu_threads
        if log_level is not None:
            self.log_level = log_level
        self.arch = None

    def ensure(self, arch: str = "cpu", precision: str = "f64"):
        """Initialise Taichi for arch and precision unless it already is (ValueError for an
        arch this machine does not have)."""
        check_arch(arch)
        replaced = self.program_replaced()
        if replaced:
            # the engines went with the program a user's ti.init replaced: start Taichi again
            # for this run. A living Simulator's engine is gone with it and refuses to run
            # (`check_engine_usable`), so it holds nothing back: it refused this run, saying
            # that starting Taichi would destroy engines already destroyed (a review, 2026-12)
            self.arch = None
        self.check_not_forked()
        if self.arch == arch and self.precision == precision:
            return
        if self.restart_reason is not None:
            self.check_no_simulator_lives(arch, precision, self.restart_reason,
                                          "restart the Python process (their engines cannot "
                                          "run either)")
        elif not replaced:
            self.check_no_simulator_lives(arch, precision)
        threads = {} if self.cpu_threads is None else {"cpu_max_num_threads": self.cpu_threads}
        memoise_source_positions()
        memoise_function_sources()
        # forgotten before ti.init destroys them: a Ctrl-C inside it left the engines of the
        # destroyed program handed out to the next call, which crashed the process (an audit,
        # 2026-12); now that call starts Taichi again
        self.arch = self.precision = None
        self.engines.clear()
        current = impl.get_runtime()
        if current is not self.taichi_program and current is not self.adopted_program \
                and current.prog is not None:
            # a program started by the user (ti.init, or a field used), before the first
            # simulation or since the last: ti.init below destroys its fields and kernels, and
            # using them afterwards crashed the process (an audit; after a simulation, a review)
            warn_user("Taichi was already started outside taichi_star: starting it for the "
                      "simulation destroys that program's fields and kernels, and using them "
                      "afterwards crashes the process; keep your own Taichi code in another "
                      "process, or start it after taichi_star's last use")
        # ti.init prints "[Taichi] Starting on arch=..." unconditionally; warnings still go to
        # Taichi's logger, except a taken cache lock's (module docstring) and the line it
        # writes, before it takes log_level, where the user set TI_LOG_LEVEL ("overridden by
        # ti.init argument"): the level after it is the user's (`taichi_log_level`)
        ti.set_logging_level(ti.ERROR)
        with contextlib.redirect_stdout(io.StringIO()):
            ti.init(arch=getattr(ti, arch), default_fp=ti.f64 if precision == "f64" else ti.f32,
                    fast_math=False, advanced_optimization=self.kernel_optimisation,
                    cfg_optimization=self.cpu_cfg_optimisation if arch == "cpu" else True,
                    offline_cache=True, log_level=ti.ERROR, **threads)
            _open_kernel_cache()
        ti.set_logging_level(self.log_level)
        atexit.unregister(_quiet_exit)
        atexit.register(_quiet_exit)
        self.arch, self.precision = arch, precision
        self.restart_reason = None
        self.taichi_thread = threading.get_ident()
        self.taichi_program = impl.get_runtime()
        self.adopted_program = None
        self.started = True
        # last, once Taichi's start is recorded: a warning raised as an error (a user's
        # filter) left a started program unrecorded, and every later call was refused as a
        # user's program (a review, 2026-12)
        note = read_only_cache_note(impl.get_runtime().prog.config().offline_cache_file_path)
        if note is not None and not self.told_read_only_cache:
            self.told_read_only_cache = True  # once a process: each restart opens it again
            warn_user(note)

    def build_here(self):
        """Make this thread the one Taichi builds on, before an engine is built. Taichi builds
        fields only on the thread that started it (its LLVM backend asserts otherwise, and the
        half-built fields broke every later call of the process: an audit, 2026-12, a
        `simulate` of a new topology from a thread pool); the engines it built run from any
        thread. From another thread, Taichi is started again on this one (the engines built so
        far are dropped; their kernels come back from the offline cache), unless a living
        Simulator holds one (RuntimeError, `check_no_simulator_lives`). From the second such
        restart on, a RuntimeWarning (once per process): threads that take turns building
        engines restart Taichi at every turn, ~2 s each (a review, 2026-12: 180 times the
        calls' own time), where engines built once from one thread serve every thread."""
        if self.taichi_thread == threading.get_ident():
            return
        self.thread_restarts += 1
        if self.thread_restarts == 2:
            warn_user("Taichi was started again on another thread to build an engine, a second "
                      "time (it builds engines only on the thread that started it, and each "
                      "restart drops the engines built so far: ~2 s each); threads that take "
                      "turns building engines of different batches restart it at every turn. "
                      "Make the first call of each batch shape (topology, integrator, "
                      "precision, size) from one thread: the engines it builds run from any "
                      "thread")
        arch, precision = self.arch, self.precision
        self.check_no_simulator_lives(
            arch, precision, "a new engine built from a thread other than the one that started "
            "Taichi, the only one it builds on",
            "make this call from the thread that started Taichi (the first to simulate) or in "
            "another process")
        self.arch = None
        self.ensure(arch, precision)

    def check_no_simulator_lives(self, arch: str, precision: str,
                                 why: str = "a run in another precision, arch or compiler "
                                            "setting",
                                 remedy: Optional[str] = None):
        """RuntimeError, before Taichi is initialised again (for another arch, precision or
        compiler setting, or on another thread: `why`), where a living Simulator (an
        environment's too) holds an engine:
        `ti.init` destroys the program its kernels and fields live in, and the Simulator would
        then crash the process at its next call or go on from another Simulator's state (an
        audit, 2026-12: an f32 `simulate` beside an f64 Simulator). A Simulator let go but not
        yet collected (a reference cycle) does not count."""
        if not any(slot.held() for slots in self.engines.values() for slot in slots):
            return
        gc.collect()
        held = sum(slot.held() for slots in self.engines.values() for slot in slots)
        remedy = remedy or f"make this run in {self.precision} or in another process"
        if held:
            raise RuntimeError(
                f"cannot start Taichi for {arch} in {precision}: {held} living Simulator(s) "
                f"(or environments) hold engines of the Taichi program this process runs "
                f"({self.precision}), and starting another ({why}) would destroy them; let "
                f"them go first (del the Simulator, env.close()), or {remedy}")

    def configure_gpu(self, block_dim: int = GPU_BLOCK_DIM, instance_minor: bool = GPU_INSTANCE_MINOR):
        """GPU launch and layout settings of the engines built from now on (for benchmarks that
        compare them; the defaults are the measured best)."""
        # a bool or a float was taken as a number, a text or 2.0 a TypeError, and
        # instance_minor="no" switched the layout on (an audit, 2026-12)
        if not is_whole(block_dim) or not 1 <= block_dim <= 1024 or block_dim & (block_dim - 1):
            raise ValueError(f"block_dim must be a power of two in [1, 1024], got {block_dim!r}")
        self.gpu_block_dim = int(block_dim)
        self.gpu_instance_minor = check_flag("instance_minor", instance_minor)

    def configure_lanes(self, lanes: Optional[int] = None):
        """Lanes of the CPU engines used from now on: None, the default, where they pay
        (`engine_lanes`); 1 (none) or 2, 4, 8, 16 for every CPU engine (a Simulator's too),
        for comparisons and long-lived Simulators."""
        if lanes is not None and (isinstance(lanes, bool)
                                  or not isinstance(lanes, (int, np.integer))
                                  or lanes not in (1, 2, 4, 8, 16)):
            raise ValueError(f"lanes must be 1, 2, 4, 8 or 16 (or None: where they pay), "
                             f"got {lanes!r}")
        self.cpu_lanes = None if lanes is None else int(lanes)

    def engine_lanes(self, batch_size: int, solver: SolverConfig, sensitive: bool = False,
                     robot_steps: Optional[int] = None) -> int:
        """Lanes of the engine for a batch of `batch_size` instances (replicas included) run
        with `solver` for `robot_steps` (None: not known ahead), see `configure_lanes`: 1 on a
        GPU; on the CPU the configured number, or by default CPU_LANES where they pay
        (LANES_MINIMUM_WORK), else 1."""
        if self.arch != "cpu":
            return 1
        if self.cpu_lanes is not None:
            return self.cpu_lanes
        pays = robot_steps is not None and robot_steps >= LANES_MINIMUM_WORK \
            and batch_size >= LOCKSTEP_MINIMUM_BATCH and not sensitive \
            and not solver.adaptive and solver.jacobian == "newton"
        return CPU_LANES if pays else 1

    def configure_compiler(self, kernel_optimisation: Optional[bool] = None,
                           cpu_cfg_optimisation: Optional[bool] = None):
        """Whether Taichi's advanced IR optimisation compiles the engines (see
        KERNEL_OPTIMISATION) and, with it, its control-flow-graph optimisation on the CPU (see
        CPU_CFG_OPTIMISATION); None: the defaults. Forces a re-initialisation if Taichi is up."""
        if kernel_optimisation is None:
            kernel_optimisation = kernel_optimisation_default()
        if cpu_cfg_optimisation is None:
            cpu_cfg_optimisation = CPU_CFG_OPTIMISATION
        self.kernel_optimisation = check_flag("kernel_optimisation", kernel_optimisation)
        self.cpu_cfg_optimisation = check_flag("cpu_cfg_optimisation", cpu_cfg_optimisation)
        self.arch = None

    def adopt_program(self):
        """Take the Taichi program now running for one this package started (a study that
        started Taichi itself for kernels of its own, `studies.simd`), not a user's: the next
        simulation starts Taichi again without the warning `ensure` gives for a user's
        program. The engines built before went with the program they lived in: dropped, and a
        living Simulator's refuses to run (`check_engine_usable`; taking this program for the
        engines' own let such a Simulator run its destroyed engine: a review, 2026-12)."""
        self.adopted_program = impl.get_runtime()
        self.engines.clear()
        self.arch = None

    def matrix_slots(self, model: BatchModel) -> int:
        """2×2 blocks of the Newton matrix's elimination pattern for this batch's engine (the
        symbolic factorisation, done once per topology and term set in this process)."""
        if model.engine_key not in self.slot_counts:
            self.slot_counts[model.engine_key] = elimination_plan(
                model.topology, model.terms_used).n_slots
        return self.slot_counts[model.engine_key]

    def loop_spread(self, capacity: int) -> int:
        """Iterations of the engine's parallel loop per instance: on the CPU enough to reach
        PARALLEL_LOOP_MINIMUM iterations (below that Taichi runs the loop on one thread)."""
        if self.arch != "cpu":
            return 1
        return max(1, -(-PARALLEL_LOOP_MINIMUM // capacity))

    def new_engine(self, model: BatchModel, solver: SolverConfig, sensitive: bool = False,
                   lanes: int = 1, least_batch: int = 0) -> BatchEngine:
        """A new engine (its own device state) for this batch (built as for at least
        `least_batch` instances, `engine_capacity`), `sensitive` if it is to carry tangents,
        with `lanes` on the CPU (`engine.BatchEngine`). Taichi must be initialised
        (`ensure`)."""
        check_memory(model, solver.precision, self.arch, least_batch)
        capacity = engine_capacity(model.batch_size, least_batch)
        gpu = self.arch != "cpu"
        try:
            return BatchEngine(model, capacity, INTEGRATORS[solver.integrator](),
                               instances_per_block=self.gpu_block_dim if gpu else 1,
                               loop_spread=self.loop_spread(capacity), even_spread=not gpu,
                               instance_minor=gpu and self.gpu_instance_minor,
                               sensitive=sensitive, lanes=lanes)
        except BaseException:
            # a build stopped half way (Ctrl-C, an error) leaves Taichi's field builder
            # unfinished, and every later kernel launch of the process failed (an audit,
            # 2026-12): the next call starts Taichi again (or says why it cannot)
            self.arch = None
            self.restart_reason = ("the last engine's build stopped half way, which leaves "
                                   "Taichi unable to run any kernel")
            raise

    def engine_key(self, model: BatchModel, solver: SolverConfig, sensitive: bool = False,
                   lanes: int = 1, least_batch: int = 0) -> tuple:
        """What an engine is compiled for: topology and terms, integrator, capacity
        (`engine_capacity`), whether it carries tangents and, on a GPU, its launch and layout
        settings (on the CPU its `lanes`)."""
        gpu = (self.gpu_block_dim, self.gpu_instance_minor) if self.arch != "cpu" else (lanes,)
        return (model.engine_key, solver.integrator,
                engine_capacity(model.batch_size, least_batch), sensitive) + gpu

    def free_engine(self, model: BatchModel, solver: SolverConfig, sensitive: bool = False,
                    robot_steps: Optional[int] = None, least_batch: int = 0) -> EngineSlot:
        """The slot of an engine for this batch (built as for at least `least_batch` instances:
        its capacity and lanes), run for `robot_steps` (None: not known ahead; `engine_lanes`),
        that no living Simulator holds (one is built if there is none): `simulate` calls and
        Simulators draw on the same engines, so a Simulator made after a `simulate` of the same
        topology, terms and integrator (or after another Simulator is gone) compiles nothing.
        The engines kept stay within FREE_ENGINES_BYTES (`bound_engines`)."""
        lanes = self.engine_lanes(max(model.batch_size, least_batch), solver, sensitive,
                                  robot_steps)
        key = self.engine_key(model, solver, sensitive, lanes, least_batch)
        slot = self.unheld_slot(key)
        if slot is None and key in self.engines:
            # each engine of the batch's key held: a Simulator let go but kept in a reference
            # cycle (a caught exception's traceback holds the frames that made it) goes only
            # when the collector runs, which takes milliseconds where a build takes seconds
            # (the test suite built engines for Simulators in such cycles, 2026-12-07)
            gc.collect()
            slot = self.unheld_slot(key)
        if slot is None:
            self.build_here()
            # room for it first: the engines kept and it within the budget
            self.bound_engines(engine_bytes(model, solver.precision, least_batch))
            # may refuse: no entry
            slot = EngineSlot(self.new_engine(model, solver, sensitive, lanes, least_batch))
            self.engines.setdefault(key, []).append(slot)
        self.uses += 1
        slot.last_use = self.uses
        self.bound_engines(slot.engine.arena.nbytes, keep=slot)
        return slot

    def unheld_slot(self, key: tuple) -> Optional[EngineSlot]:
        """The first engine of `key` that no living Simulator holds; None if there is none."""
        return next((slot for slot in self.engines.get(key, []) if not slot.held()), None)

    def bound_engines(self, taken_bytes: int, keep: Optional[EngineSlot] = None):
        """`release_engines` down to FREE_ENGINES_BYTES beside the `taken_bytes` of the engine
        a call or Simulator takes (`keep`), on the CPU and on the thread that started Taichi
        alone: a tree destroyed from another thread broke Taichi's own books, and every later
        build of the process failed (a review, 2026-12); a GPU's engines stay as they were
        (measured on none; a GPU's memory pool is Taichi's own)."""
        if self.arch == "cpu" and self.taichi_thread == threading.get_ident():
            self.release_engines(FREE_ENGINES_BYTES - taken_bytes, keep=keep)

    def release_engines(self, budget_bytes: float = 0.0,
                        keep: Optional[EngineSlot] = None) -> int:
        """Destroy the engines that no living Simulator holds, `keep` aside, least recently
        used first, until the fields of those left take at most `budget_bytes` (default 0:
        all of them); returns how many were destroyed. Their memory goes back to the system;
        a later call of such a batch builds its engine again (seconds, its kernels mostly from
        Taichi's offline cache). `free_engine` keeps FREE_ENGINES_BYTES. RuntimeError from
        another thread than the one that started Taichi, the only one that may destroy its
        fields (`build_here`)."""
        if self.taichi_thread is not None and self.taichi_thread != threading.get_ident():
            raise RuntimeError("release_engines must be called from the thread that started "
                               "Taichi (the first to simulate): it alone may destroy fields")
        free = sorted(((key, slot) for key, slots in self.engines.items() for slot in slots
                       if slot is not keep and not slot.held()),
                      key=lambda entry: entry[1].last_use)
        kept = sum(slot.engine.arena.nbytes for _, slot in free)
        destroyed = 0
        for key, slot in free:
            if kept <= budget_bytes:
                break
            kept -= slot.engine.arena.nbytes
            others = [other for other in self.engines[key] if other is not slot]
            if others:
                self.engines[key] = others
            else:
                del self.engines[key]
            slot.engine.arena.destroy()
            destroyed += 1
        return destroyed

    def lease_engine(self, model: BatchModel, solver: SolverConfig, owner,
                     sensitive: bool = False) -> BatchEngine:
        """An engine of its own for `owner` (a Simulator) while the owner lives (`free_engine`;
        `sensitive`: one that carries tangents). No call or other Simulator uses it meanwhile;
        when the owner goes, the engine counts as used then (`EngineSlot.last_use`: an hour's
        Simulator kept its lease's stamp, and went before engines of calls made since, a
        review, 2026-12)."""
        slot = self.free_engine(model, solver, sensitive)

        def let_go(_reference):
            # on whichever thread drops the owner, without the runtime's lock (a collection
            # may run inside a locked call): a race only ties two stamps
            self.uses += 1
            slot.last_use = self.uses

        slot.holder = weakref.ref(owner, let_go)
        return slot.engine

    def engine_for(self, model: BatchModel, solver: SolverConfig, tangents: int = 0,
                   robot_steps: Optional[int] = None, least_batch: int = 0) -> BatchEngine:
        """A free engine for this batch's topology, terms, integrator and capacity (built as
        for at least `least_batch` instances; `free_engine`; `robot_steps`: the call's work, if
        known), loaded with the batch at rest, its gaits firing every period. With `tangents`
        > 0 the batch is B instances and their replicas (`BatchEngine.load`) and the engine a
        sensitive one. It stays free: the next call may load it again."""
        slot = self.free_engine(model, solver, tangents > 0, robot_steps, least_batch)
        slot.holder = None
        slot.engine.load(model, solver, tangents=tangents)
        return slot.engine


def prepare_engine(params, solver: SolverConfig = SolverConfig(), arch: str = "cpu") -> BatchEngine:
    """For the tests, which drive the engine directly (its kernels, fields and step counts):
    Taichi initialised, the batch's engine built (or reused from the cache) and loaded with the
    batch at rest."""
    model = build_model(params)
    runtime = Runtime.current()
    runtime.ensure(arch, solver.precision)
    return runtime.engine_for(model, solver)


def _fresh_lock_in_child():
    """A forked child's own `RUNTIME_LOCK`: the parent's, taken by another of its threads at
    the fork, would be held for ever by a thread the child does not have, and the child's
    first call waited for ever instead of being told to use spawn (a review, 2026-12)."""
    global RUNTIME_LOCK
    RUNTIME_LOCK = threading.RLock()


os.register_at_fork(after_in_child=_fresh_lock_in_child)
os.register_at_fork(after_in_child=Runtime._after_fork)
