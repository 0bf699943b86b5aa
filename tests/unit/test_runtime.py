"""The runtime's settings that need no engine: the compiler default and its environment
variable, the offline cache's lock, the arch probe."""

import os
import subprocess
import sys

import numpy as np
import pytest

from taichi_star import runtime


@pytest.mark.parametrize("value, expected", [("", runtime.KERNEL_OPTIMISATION), ("0", False),
                                             ("1", True), (" 1 ", True)])
def test_kernel_optimisation_default_follows_the_environment(monkeypatch, value, expected):
    monkeypatch.setenv(runtime.KERNEL_OPTIMISATION_ENV, value)
    assert runtime.kernel_optimisation_default() is expected
    assert runtime.Runtime().kernel_optimisation is expected


@pytest.mark.parametrize("value", ["yes", "2", "off"])
def test_a_bad_kernel_optimisation_variable_is_named_in_the_error(monkeypatch, value):
    monkeypatch.setenv(runtime.KERNEL_OPTIMISATION_ENV, value)
    with pytest.raises(ValueError, match=rf"{runtime.KERNEL_OPTIMISATION_ENV} must be 0 or 1, "
                                         rf"got '{value}'"):
        runtime.kernel_optimisation_default()


CACHE_PROBE = """
import sys, taichi as ti
if sys.argv[1] == "populate":
    ti.init(arch=ti.cpu, log_level=ti.WARN)
    @ti.kernel
    def one():
        pass
    one()
    ti.reset()  # writes the offline cache
elif sys.argv[1] == "taichi":
    ti.init(arch=ti.cpu, log_level=ti.WARN)
    @ti.kernel
    def two():
        pass
    two()
else:
    from taichi_star.runtime import Runtime
    Runtime.current().ensure("cpu")
    @ti.kernel
    def three():
        pass
    three()  # an engine's first kernel
"""


def test_a_taken_cache_lock_prints_no_advice_to_clean_the_cache(tmp_path):
    """Another process holding Taichi's offline-cache lock: plain Taichi prints "Lock ...
    failed. Please run 'ti cache clean'" when it opens the cache; taichi_star's runtime opens
    it at log level ERROR and prints nothing (its own private cache: HOME in tmp_path)."""
    script = tmp_path / "probe.py"
    script.write_text(CACHE_PROBE)
    # the cache under HOME, even where the caller's environment names another cache folder
    environment = {**{name: value for name, value in os.environ.items()
                      if name != "TI_OFFLINE_CACHE_FILE_PATH"}, "HOME": str(tmp_path)}

    def run(mode):
        return subprocess.run([sys.executable, str(script), mode], env=environment,
                              capture_output=True, text=True, timeout=120)
    run("populate")
    caches = list(tmp_path.glob(".cache/taichi/ticache/*.tcb"))
    assert caches, "the probe did not write an offline cache"
    (caches[0].parent / "ticache.lock").touch()
    plain = run("taichi")
    assert "ticache.lock failed" in plain.stdout + plain.stderr
    ours = run("taichi_star")
    assert ours.returncode == 0, ours.stderr
    assert "ticache.lock" not in ours.stdout + ours.stderr


LOG_PROBE = """
from taichi._logging import is_logging_effective
from taichi_star.runtime import Runtime
Runtime.current().ensure("cpu")
print("info", is_logging_effective("info"), "warn", is_logging_effective("warn"))
"""


@pytest.mark.parametrize("level, effective", [("warn", "info False warn True"),
                                              ("info", "info True warn True")])
def test_taichis_log_level_is_the_users_and_starting_taichi_says_nothing_of_it(tmp_path, level,
                                                                              effective):
    """TI_LOG_LEVEL set: starting Taichi wrote "Environment variable TI_LOG_LEVEL=warn
    overridden by ti.init argument" to stderr, and the level after it was always "warn" (the
    runtime's own); now nothing is written and the user's level holds."""
    script = tmp_path / "probe.py"
    script.write_text(LOG_PROBE)
    run = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                         timeout=120, env={**os.environ, "TI_LOG_LEVEL": level})
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == effective
    assert "overridden" not in run.stderr, run.stderr


@pytest.mark.parametrize("value, level", [(None, "warn"), ("", "warn"), ("error", "error"),
                                          ("trace", "trace"), ("off", "off")])
def test_the_runtimes_log_level_is_ti_log_level_else_warn(monkeypatch, value, level):
    if value is None:
        monkeypatch.delenv("TI_LOG_LEVEL", raising=False)
    else:
        monkeypatch.setenv("TI_LOG_LEVEL", value)
    assert runtime.taichi_log_level() == level
    assert runtime.Runtime().log_level == level


def test_a_process_that_exits_leaves_its_kernels_in_the_offline_cache(tmp_path):
    """A process that ran kernels through the runtime and exits without `ti.reset` writes them
    to the offline cache (at 10e264a it wrote nothing: Taichi's program was never finalized at
    exit, and every process compiled every engine again)."""
    script = tmp_path / "probe.py"
    script.write_text(CACHE_PROBE)
    cache = tmp_path / "cache"
    environment = {**os.environ, "TI_OFFLINE_CACHE_FILE_PATH": str(cache)}
    run = subprocess.run([sys.executable, str(script), "taichi_star"], env=environment,
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert list(cache.glob("*.tic")), "no kernel in the offline cache after the process exited"


ARCH_PROBE = """
import taichi as ti
from taichi import _logging
ti.set_logging_level("info")
from taichi_star.runtime import available_archs
print(available_archs())
print(_logging.is_logging_effective("info"), _logging.is_logging_effective("debug"))
"""


def test_probing_the_archs_prints_nothing_and_keeps_the_logging_level():
    # a machine without CUDA: Taichi's probe logs "libcuda.so lib not found" (a warning, from
    # C++, so only a separate process sees it on its standard error) before the CLI's one-line
    # error; with CUDA there is nothing to log and the test checks the level alone
    probe = subprocess.run([sys.executable, "-c", ARCH_PROBE], capture_output=True, text=True,
                           timeout=120, check=True)
    archs_line, level_line = probe.stdout.strip().splitlines()[-2:]
    assert archs_line.startswith("['cpu'")
    assert level_line == "True False"  # "info" as set before the probe, not the probe's ERROR
    assert not [line for line in probe.stderr.splitlines() if line.startswith("[W")]


def test_taichi_star_imports_without_home_and_says_what_it_set():
    """Taichi's import aborted the process when HOME was not set (a core dump under cron,
    `env -i` or a systemd unit: an audit, 2026-12); the package sets it first, in one line."""
    environment = {key: value for key, value in os.environ.items() if key != "HOME"}
    run = subprocess.run([sys.executable, "-c",
                          "import taichi_star, os; print(os.environ['HOME'])"],
                         capture_output=True, text=True, env=environment, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    home = run.stdout.strip().splitlines()[-1]
    assert run.stderr.strip().splitlines()[-1] == (f"taichi_star: HOME was not set (Taichi needs "
                                                   f"it); set to {home}")


def test_an_exit_that_cannot_write_the_kernel_cache_says_so_in_one_line():
    """An offline cache folder Taichi cannot write (a read-only HOME) gave a traceback at every
    exit, after the run's results were written (an audit, 2026-12): one line, exit code 0."""
    import subprocess
    import sys

    code = ("import taichi as ti\nfrom taichi_star import runtime\n"
            "def refuse():\n    raise RuntimeError('filesystem error: cannot create directories')\n"
            "ti.reset = refuse\nruntime._quiet_exit()\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stderr.strip().splitlines()[-1] == (
        "taichi_star: Taichi's offline cache was not written (filesystem error: cannot create "
        "directories): the next process compiles its kernels again; TI_OFFLINE_CACHE_FILE_PATH "
        "names a writable folder")


def test_a_read_only_cache_folder_is_noted_only_where_it_exists_and_cannot_be_written(
        tmp_path, monkeypatch):
    """Taichi loads no kernel from an offline cache folder it cannot lock (a read-only mount:
    it fails to make the lock file), and the runtime silences the lock message, so a filled
    read-only cache was used by no run and said by none. Tests run as root in CI, where a
    chmod does not stop writing: the folder's writability is os.access's answer, patched."""
    unwritable = {str(tmp_path / "read-only")}
    real_access = os.access
    monkeypatch.setattr(runtime.os, "access", lambda path, mode: (
        False if mode == os.W_OK and str(path) in unwritable else real_access(path, mode)))
    (tmp_path / "read-only").mkdir()
    (tmp_path / "writable").mkdir()
    note = runtime.read_only_cache_note(str(tmp_path / "read-only"))
    assert note.startswith(f"Taichi's offline cache folder {tmp_path / 'read-only'} cannot be "
                           f"written")
    assert "Set TI_OFFLINE_CACHE_FILE_PATH to a writable folder" in note
    assert runtime.read_only_cache_note(str(tmp_path / "writable")) is None
    # a folder not made yet: Taichi makes it at exit (or says it could not, `_quiet_exit`)
    assert runtime.read_only_cache_note(str(tmp_path / "missing")) is None


READ_ONLY_CACHE_PROBE = """
import os, sys, warnings
folder = sys.argv[1]
real_access = os.access
os.access = lambda path, mode: (False if mode == os.W_OK and sys.argv[2] == "read-only"
                                and str(path) == folder else real_access(path, mode))
from taichi_star.runtime import Runtime
warnings.simplefilter(sys.argv[3])
try:
    Runtime.current().ensure("cpu")
except RuntimeWarning:  # raised as an error: the next start must still be taichi_star's own
    print("raised", file=sys.stderr)
warnings.simplefilter("always")
# Taichi starts again at the next ensure, opening the cache again, with one thread
Runtime.current().configure(cpu_threads=1)
Runtime.current().ensure("cpu")
from taichi.lang import impl
print("threads", impl.current_cfg().cpu_max_num_threads)
"""


@pytest.mark.parametrize("mode, warnings_as", [("read-only", "always"), ("writable", "always"),
                                               ("read-only", "error")])
def test_a_process_says_once_that_its_cache_folder_cannot_be_written(tmp_path, mode,
                                                                   warnings_as):
    """The note comes at the first start of Taichi in the process, a warning pointing at the
    caller's line, and not again when Taichi starts again (a `configure`); a writable cache
    folder gets none. Raised as an error by a user's filter, it leaves Taichi's start
    recorded: the next start is not taken for a user's program (it was, and every later call
    was refused: a review, 2026-12)."""
    script = tmp_path / "probe.py"
    script.write_text(READ_ONLY_CACHE_PROBE)
    cache = tmp_path / "cache"
    cache.mkdir()
    environment = {**os.environ, "TI_OFFLINE_CACHE_FILE_PATH": str(cache)}
    run = subprocess.run([sys.executable, str(script), str(cache), mode, warnings_as],
                         env=environment, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    # and what every start does (a mutation audit, 2026-12): the configured threads, Taichi's
    # "[Taichi] Starting on arch=x64" kept from the output, and a restart by taichi_star itself
    # not taken for a user's Taichi program
    assert run.stdout.strip().splitlines()[-1] == "threads 1"
    assert "Starting on arch" not in run.stdout
    assert "already started outside" not in run.stderr
    notes = [line for line in run.stderr.splitlines() if "offline cache folder" in line]
    if mode == "writable":
        assert notes == []
    elif warnings_as == "error":
        assert run.stderr.splitlines().count("raised") == 1 and notes == []
    else:
        assert len(notes) == 1
        assert notes[0].startswith(f"{script}:10: RuntimeWarning: Taichi's offline cache folder "
                                   f"{cache} cannot be written")


@pytest.mark.parametrize("threads", [0, -1, 2.5, "4", True, runtime.MAX_CPU_THREADS + 1])
def test_cpu_threads_are_a_whole_number_from_one(threads):
    """0 made the first simulation kill the process with SIGFPE; -1, 2.5 and "4" failed inside
    Taichi in its words; True counted as one thread (a mutation audit, 2026-12)."""
    with pytest.raises(ValueError, match=rf"^cpu_threads must be an integer in \[1, "
                                         rf"{runtime.MAX_CPU_THREADS}\], got "):
        runtime.Runtime().configure(cpu_threads=threads)


def test_cpu_threads_take_numpy_integers_and_none_for_every_core():
    settings = runtime.Runtime()
    settings.configure(cpu_threads=np.int64(runtime.MAX_CPU_THREADS))
    assert settings.cpu_threads == runtime.MAX_CPU_THREADS and type(settings.cpu_threads) is int
    settings.configure()
    assert settings.cpu_threads is None


@pytest.mark.parametrize("block_dim, instance_minor, message", [
    (1000, True, "block_dim must be a power of two in [1, 1024], got 1000"),
    (2048, True, "block_dim must be a power of two in [1, 1024], got 2048"),
    (True, True, "block_dim must be a power of two in [1, 1024], got True"),
    (32.0, True, "block_dim must be a power of two in [1, 1024], got 32.0"),
    ("32", True, "block_dim must be a power of two in [1, 1024], got '32'"),
    (64, "no", "instance_minor must be True or False, got 'no'")])
def test_gpu_settings_are_refused_naming_the_argument(block_dim, instance_minor, message):
    """A bool or a float block size was taken as a number, a text one a TypeError, and
    instance_minor="no" switched the layout on (a mutation audit, 2026-12)."""
    with pytest.raises(ValueError) as error:
        runtime.Runtime().configure_gpu(block_dim, instance_minor)
    assert str(error.value) == message


@pytest.mark.parametrize("block_dim", [1, 1024])
def test_gpu_settings_take_the_ends_of_the_range(block_dim):
    settings = runtime.Runtime()
    settings.configure_gpu(np.int64(block_dim), np.bool_(False))
    assert (settings.gpu_block_dim, settings.gpu_instance_minor) == (block_dim, False)


def test_the_calls_held_one_at_a_time_keep_their_names_signatures_and_docstrings():
    """`one_call_at_a_time` wraps simulate and every Simulator method that uses Taichi: without
    functools.wraps, help(), the API reference and IDEs would show the wrapper's (a mutation
    audit, 2026-12)."""
    import inspect

    import taichi_star as ts

    assert ts.simulate.__name__ == "simulate" and "duration_s" in inspect.signature(
        ts.simulate).parameters
    assert ts.Simulator.advance.__name__ == "advance"
    assert ts.Simulator.advance.__doc__ == ts.Simulator.advance.__wrapped__.__doc__
    assert ts.Simulator.advance.__doc__.strip()
