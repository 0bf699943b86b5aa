"""The time grid of fixed steps: which times are a whole number of steps, how many steps a
duration is, how many records fit, and the limits on a run's step count.

With fixed steps every time the engine reaches is step·dt, so a record, a cycle start or a
firing time must be a whole number of steps; `whole_steps` decides that, within one tolerance
(`STEP_TOLERANCE`) for the whole package. A record interval that is not one is refused (a
ValueError naming it); `nearest_interval` and `interval_for_count` give one that is.
"""

from __future__ import annotations

import math
import os
from typing import Optional, Sequence, Tuple

import numpy as np
from .checks import is_finite_real, is_real, is_whole, shown, warn_user

# the public names (docs/api.md), those the studies use among them (tests/test_layering.py)
__all__ = ["nearest_interval", "interval_for_count", "whole_steps", "steps_in", "STEP_TOLERANCE",
           "MAX_STEPS_PER_INSTANCE", "REFUSE_ROBOT_STEPS", "refuse_robot_steps", "check_work",
           "PAPER_NODES", "step_work", "weighted_nodes", "warn_long_work", "LongWorkWarning",
           "SteadySpeedWarning"]

STEP_TOLERANCE = 1e-9
"""Relative tolerance within which a time is taken to be a whole number of steps (and a
duration a whole number of record intervals): far above the rounding of a time built from
decimal inputs (~1e-16 relative), far below any real difference of a step."""

MOST_OFF_GRID_STEPS = 1e-3
"""... and at most this share of one step, whatever the count: past 5·10⁸ steps the relative
tolerance alone took a time half a step off the grid, or more, for a whole number of steps (an
audit, 2026-12); a float's rounding of 2³¹ steps is ~5·10⁻⁷ of one."""

STEPS_PER_LAUNCH = 50
"""Steps fused into one kernel launch: enough to hide launch cost, few enough for a live
progress bar."""

MAX_STEPS_PER_INSTANCE = 2 ** 31 - 1
"""Most time steps one instance may take, counted from t = 0. The engine's step counters
(steps_done, failure_step) are int32, and a run this long (2.1e9 steps: 25 days of simulated
time at the paper's 1 ms) is never what was meant: a fixed-step run of more (duration / dt) is
refused before any compute instead of running for days or overflowing, as is an adaptive one
whose fewest steps (duration / dt_max) are more; an adaptive instance that reaches it stops
with status step_limit."""

WARN_ROBOT_STEPS = 1e10
"""A run of more robot-steps (time steps × instances) than this starts with a RuntimeWarning
giving its estimated duration: about 2.3 days at `ESTIMATE_ROBOT_STEPS_PER_S`."""
ESTIMATE_ROBOT_STEPS_PER_S = 5e4
"""The rate the warning's estimate assumes: the plain `simulate` call of the paper preset at
B = 512 measured 51,000 and 90,000 robot-steps/s on two 2-core machines; the slower one."""
FASTEST_ROBOT_STEPS_PER_S = 3.6e6
"""The fastest rate measured on any machine, rounded up: one H100, the paper preset in f32
with the chord Jacobian at B = 65,536, 3,442,872 robot-steps/s (results/bench_gpu.csv; 3,564,046
in a run cut off before its table, results/bench_gpu_cutoff.log). tests/unit/test_timegrid.py
keeps it at least every rate in results/."""
FASTEST_CPU_CORE_ROBOT_STEPS_PER_S = 2.5e5
"""The fastest rate per CPU core measured, with room: 113,623 robot-steps/s a core (the plain
call with the lagged Jacobian at B = 512 on a 2-core Intel Xeon,
results/bench_lagged/e67d242/bench.csv), a little over twice that for faster cores and f32.
tests/unit/test_timegrid.py keeps it at least every CPU row's rate per core in results/."""
PAPER_NODES = 193
"""Nodes of the paper's robot (n_arc 18, n_limb 6: `StarParams.node_count`), whose steps the
rates above count."""


def step_work(nodes: Optional[float] = None) -> float:
    """The work of one time step of a robot of `nodes` nodes, in steps of the paper's robot
    (PAPER_NODES; None: that robot, 1.0): proportional to the nodes, as the engine's assembly,
    banded factorisation and solve are. Measured (results/bench_meshes/bench.csv, section
    "mesh", B = 64, f64), a step costs 0.20 to 0.27 µs per node from 65 to 3,249 nodes, within
    21 % of their median (tests/unit/test_timegrid.py keeps every row within 25 %).
    The rates and bounds above count the paper robot's steps: a fine mesh (n_arc = 1000: 8,049
    nodes, 42 times the work) was estimated and bounded as the paper robot (an audit, 2026-12).
    A batch of several meshes gives its nodes as `weighted_nodes` does. ValueError naming
    nodes unless a finite number >= 1 or None."""
    if nodes is None:
        return 1.0
    if not is_finite_real(nodes) or nodes < 1:
        raise ValueError(f"nodes must be a finite number >= 1 (a robot's nodes) or None, got "
                         f"{shown(nodes)}")
    return float(nodes) / PAPER_NODES


def weighted_nodes(parts: Sequence[Tuple[float, float]]) -> Optional[float]:
    """The nodes of a batch whose parts are (robot-steps, nodes) pairs: their mean weighted by
    the robot-steps, which gives the batch's work (`step_work`); exactly the nodes where every
    part has the same (no rounding of the paper robot's); None for no work."""
    total = sum(steps for steps, _ in parts)
    if not total:
        return None
    if len({nodes for _, nodes in parts}) == 1:
        return parts[0][1]
    return sum(steps * nodes for steps, nodes in parts) / total


def _mesh_words(nodes: Optional[float]) -> str:
    """What an estimate says of a mesh other than the paper robot's ("" for that one)."""
    work = step_work(nodes)
    if work == 1.0:
        return ""
    return (f" of robots of {nodes:,.0f} nodes{'' if float(nodes).is_integer() else ' on average'}"
            f" (a step {work:.3g} times the work of one of the paper robot's {PAPER_NODES})")


REFUSE_DAYS = 30
REFUSE_ROBOT_STEPS = FASTEST_ROBOT_STEPS_PER_S * REFUSE_DAYS * 86400.0
"""A call of more robot-steps (9.3e12) is refused before any compute on any machine, with its
estimate: even the fastest machine measured would need more than REFUSE_DAYS for it (a 2-core
CPU over four years). A call on the CPU is held to its cores' bound (`refuse_robot_steps`).
One call runs on one machine; `run_batch` only warns about its whole batch, whose chunks may
run on many (each chunk is held to its machine's bound where it runs)."""


def usable_cores() -> int:
    """The CPU cores this process may run on (its affinity where the system says, else every
    core the machine has)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def refusal_rate(arch: Optional[str] = None) -> Tuple[float, str]:
    """(robot-steps/s, what it is): the rate no run on `arch` has been measured above. On
    "cpu" FASTEST_CPU_CORE_ROBOT_STEPS_PER_S times this machine's `usable_cores`, at most
    FASTEST_ROBOT_STEPS_PER_S; on a GPU
    arch, or None (a machine not known: a study's or a batch's work, which may be spread),
    FASTEST_ROBOT_STEPS_PER_S."""
    if isinstance(arch, str) and arch == "cpu":  # not yet checked: an array compares per item
        cores = usable_cores()
        # never above any machine's bound (15 cores and more were: a review, 2026-12)
        return (min(FASTEST_CPU_CORE_ROBOT_STEPS_PER_S * cores, FASTEST_ROBOT_STEPS_PER_S),
                f"this machine's {cores} CPU core{'' if cores == 1 else 's'} at "
                f"{FASTEST_CPU_CORE_ROBOT_STEPS_PER_S:.3g} each, above the fastest measured "
                f"per core")
    return FASTEST_ROBOT_STEPS_PER_S, "the fastest measured, one H100 in f32"


def refuse_robot_steps(arch: Optional[str] = None) -> float:
    """The most robot-steps a call on `arch` may ask for (`refusal_rate` × REFUSE_DAYS):
    REFUSE_ROBOT_STEPS for a GPU arch or None, 1.3e12 for "cpu" on 2 cores."""
    # REFUSE_ROBOT_STEPS itself for a GPU arch or None: the one constant that bound is read from
    return min(refusal_rate(arch)[0] * REFUSE_DAYS * 86400.0, REFUSE_ROBOT_STEPS)


def on_grid(times_s, interval_s: float) -> np.ndarray:
    """Whether each time (s, array) is a whole number of `interval_s` (s), within
    STEP_TOLERANCE of the count (relative, at least one step) and within MOST_OFF_GRID_STEPS of
    one interval."""
    ratio = np.asarray(times_s) / interval_s
    tolerance = np.minimum(STEP_TOLERANCE * np.maximum(1.0, np.abs(ratio)), MOST_OFF_GRID_STEPS)
    return np.abs(ratio - np.round(ratio)) <= tolerance


def whole_steps(time_s: float, dt: float) -> Optional[int]:
    """time_s / dt as an integer if it is one (`on_grid`), else None. ValueError naming dt
    (a finite number > 0 s) or time_s (a finite number of s; `_steps_of`)."""
    steps = _steps_of("time_s", time_s, dt, positive=False)
    return int(round(steps)) if on_grid(time_s, dt) else None


def step_counts(times_s: np.ndarray, dt: float) -> np.ndarray:
    """(n,) whole steps in each time (s, (n,)); 0 where a time is not a whole number of
    steps."""
    ratio = np.asarray(times_s) / dt
    return np.where(on_grid(times_s, dt), np.round(ratio), 0)


def steps_in(duration_s: float, dt: float) -> int:
    """The steps a fixed-step run of duration_s (s) takes at steps of dt (s): the duration
    rounded to whole steps. ValueError naming dt (a finite number > 0 s) or duration_s (a
    finite number of s; `_steps_of`)."""
    return int(round(_steps_of("duration_s", duration_s, dt, positive=False)))


def multiples_within(duration_s: float, interval_s: float) -> int:
    """How many whole intervals fit in duration_s (one that ends within STEP_TOLERANCE after
    it counts: a duration of exactly n intervals gives n, whatever the rounding)."""
    return int(math.floor(duration_s / interval_s * (1 + STEP_TOLERANCE)))


def check_steps(name: str, time_s: float, dt: float) -> int:
    """The whole steps in time_s (s); ValueError naming `name` unless they are at least one
    and time_s is on the grid of dt (s)."""
    steps = whole_steps(time_s, dt)
    if not steps or steps < 1:
        nearest = (f" (nearest valid: {nearest_interval(time_s, dt)!r} s)"
                   if _positive_number(time_s) else "")
        raise ValueError(f"{name} must be a whole number of steps (dt = {dt} s), got "
                         f"{time_s!r}{nearest}")
    return steps


def check_duration(duration_s: float, dt: float) -> int:
    """`steps_in(duration_s, dt)`; ValueError naming duration_s unless it is at least one. A
    duration off the grid of dt (`on_grid`) is rounded to whole steps, and a RuntimeWarning
    (kind "off_grid_duration") says so with the time simulated: repeated, the rounding adds
    up (ten `Simulator.advance(0.0015)` at 1-ms steps advance 0.02 s, an audit)."""
    steps = steps_in(duration_s, dt)
    if steps < 1:
        raise ValueError(f"duration_s must be at least one step (dt = {dt} s), got "
                         f"{duration_s!r}")
    warn_off_grid(duration_s, dt)
    return steps


def warn_off_grid(duration_s: float, dt: float, subject: Optional[str] = None,
                  advice: str = "timegrid.nearest_interval gives a duration on the grid") -> bool:
    """`check_duration`'s RuntimeWarning (kind "off_grid_duration") where duration_s (s) is
    not a whole number of steps of dt (s), naming it as `subject` (default "duration_s = ...
    s") with `advice`; whether it warned."""
    if on_grid(duration_s, dt):
        return False
    steps = steps_in(duration_s, dt)
    warn_user(f"{subject or f'duration_s = {duration_s!r} s'} is not a whole number of steps "
              f"(dt = {dt:g} s): {steps} steps, {steps * dt!r} s, are simulated ({advice})",
              kind="off_grid_duration")
    return True


def nearest_interval(interval_s: float, dt: float) -> float:
    """The record interval (s) nearest interval_s that is a whole number of steps of dt (s),
    at least one step: what `simulate` and `Simulator.advance` accept as record_interval_s
    with fixed steps. ValueError naming interval_s or dt unless each is a finite number
    > 0 s."""
    # a Python float whatever dt's type (a NumPy float32 dt gave a float32 interval)
    return float(max(1, round(_steps_of("interval_s", interval_s, dt))) * dt)


def _positive_number(value) -> bool:
    """Whether `value` is a finite real number > 0 (NumPy's included) as a float, not a bool."""
    return is_finite_real(value) and float(value) > 0


def _steps_of(name: str, time_s, dt, positive: bool = True) -> float:
    """time_s / dt, the steps of dt (s) in the time `name` gives (s), as a float; ValueError
    naming `name` or dt unless each is a finite number > 0 s (with `positive` False, time_s
    any finite number: NaN and a step of 0 had given `steps_in` and `whole_steps` a bare
    ValueError or a ZeroDivisionError, an audit, 2026-12), and `name` where the quotient
    passes a float's range."""
    if positive and not _positive_number(time_s):
        raise ValueError(f"{name} must be a finite number > 0 s, got {shown(time_s)}")
    if not positive and not is_finite_real(time_s):
        raise ValueError(f"{name} must be a finite number of s, got {shown(time_s)}")
    if not _positive_number(dt):
        raise ValueError(f"dt must be a finite number > 0 s, got {shown(dt)}")
    steps = float(time_s) / float(dt)
    if not math.isfinite(steps):
        raise ValueError(f"{name} = {shown(time_s)} s is {steps} steps of dt = {shown(dt)} s")
    return steps


def interval_for_count(duration_s: float, count: int, dt: float) -> float:
    """A record interval (s, a whole number of steps of dt, at least one) giving `count` to
    2·count − 1 records after the start over duration_s (s) when the run has at least `count`
    steps (one per step when it has fewer). ValueError naming count (an integer >= 1),
    duration_s or dt (each a finite number > 0 s)."""
    if not is_whole(count) or count < 1:
        raise ValueError(f"count must be an integer >= 1, got {count!r}")
    # a Python float whatever the types of dt and count (np.int64 gave a NumPy float)
    return float(max(1, round(_steps_of("duration_s", duration_s, dt)) // count) * dt)


def check_work(name: str, steps: float, batch: Optional[int] = None,
               arch: Optional[str] = None, nodes: Optional[float] = None):
    """ValueError when `steps` (time steps per instance, a float estimate: it may be inf),
    rounded to whole steps as the drivers round a duration, is over MAX_STEPS_PER_INSTANCE;
    `name` says which arguments gave it (e.g. "duration_s = 1e9 s at dt = 0.001 s"), the
    message the estimate (times `batch`, the number of instances, if given) and the limit.
    A RuntimeWarning with the estimated wall time when steps × batch is over WARN_ROBOT_STEPS;
    ValueError with it past `refuse_robot_steps(arch)` (work no machine of `arch` measured
    finishes in REFUSE_DAYS; `arch` None: no machine at all). `nodes`: the robots' nodes (None:
    the paper robot's), whose steps weigh `step_work(nodes)` of the paper robot's in both
    bounds and the estimates. ValueError naming `steps` (a real number >= 0), `batch` (an
    integer >= 1) or `nodes` (`step_work`) otherwise."""
    # steps != steps: NaN, named as steps (it was named as `name`'s count; an audit, 2026-12),
    # without a conversion that 10**400 would overflow
    if not is_real(steps) or steps != steps or steps < 0:
        raise ValueError(f"steps must be a real number >= 0 (time steps per instance), got "
                         f"{shown(steps)}")
    try:
        steps = float(steps)
    except OverflowError:  # 10**400 steps: too many
        steps = math.inf
    if batch is not None and (not is_whole(batch)
                              or batch < 1):
        raise ValueError(f"batch must be an integer >= 1 (instances) or None, got {batch!r}")
    work = step_work(nodes)
    if not (math.isfinite(steps) and round(steps) <= MAX_STEPS_PER_INSTANCE):
        total = "" if batch is None else \
            f" ({steps * batch:.3g} robot-steps for {batch} instance{'' if batch == 1 else 's'})"
        raise ValueError(f"{name} is {steps:.3g} time steps per instance{total}; the limit is "
                         f"{MAX_STEPS_PER_INSTANCE} steps per instance (the int32 step counter)")
    robot_steps = round(steps) * (batch or 1)
    rate, rated = refusal_rate(arch)
    limit = refuse_robot_steps(arch)
    # a CPU call was held to the H100's bound, so that work of years on this machine started
    # with a warning only (an audit, 2026-12)
    if robot_steps * work > limit:
        days = robot_steps * work / rate / 86400
        years = robot_steps * work / ESTIMATE_ROBOT_STEPS_PER_S / (365.25 * 86400)
        elsewhere = ("on a GPU (arch=\"gpu\"), " if limit < REFUSE_ROBOT_STEPS else "") + \
            "or a run_batch spread over several machines"
        mesh = _mesh_words(nodes)
        raise ValueError(f"{name} is {robot_steps:.3g} robot-steps{mesh}: about {days:.3g} days "
                         f"even at {rate / work:.3g} robot-steps/s ({rated}"
                         f"{'; divided by the work of a step' if mesh else ''}) and "
                         f"{years:.3g} years on a 2-core CPU; the limit is {limit / work:.3g} "
                         f"robot-steps a call ({REFUSE_DAYS} days at that rate): run fewer "
                         f"instances or a shorter duration, {elsewhere}")
    warn_long_work(name, robot_steps, nodes)


class LongWorkWarning(RuntimeWarning):
    """A run estimated to take long (past WARN_ROBOT_STEPS robot-steps), with its hours: a
    category of its own, so that a script that means a long run can silence it alone
    (`warnings.simplefilter("ignore", LongWorkWarning)`) and a caller that told the estimate
    itself (a study, before it builds its instances) need not hear it twice."""


class SteadySpeedWarning(RuntimeWarning):
    """A run's steady speeds (steady_speed_mm_s, steady_signed_speed_mm_s) are NaN or leave out
    its last cycle because of the time grid: a period off the fixed-step grid, an adaptive run
    a hair short of whole periods (`simulation.off_grid_periods`, `cycles_cut_short`). A
    category of its own, so that a caller that does not read them can silence it alone
    (`warnings.simplefilter("ignore", SteadySpeedWarning)`, as the studies whose tables do not
    report them do)."""


def warn_long_work(name: str, robot_steps: float, nodes: Optional[float] = None):
    """A LongWorkWarning with the estimated wall time when `robot_steps` (steps × instances,
    a real number >= 0) of robots of `nodes` nodes (None: the paper robot's; `step_work`) are
    over WARN_ROBOT_STEPS of the paper robot's work; `name` says which arguments gave them. Of
    kind "long_work" (a caller that tells a whole batch's hours keeps its parts' to itself:
    `told_by_caller`)."""
    work = step_work(nodes)
    if robot_steps * work > WARN_ROBOT_STEPS:
        hours = robot_steps * work / ESTIMATE_ROBOT_STEPS_PER_S / 3600
        mesh = _mesh_words(nodes)
        rate = f"{ESTIMATE_ROBOT_STEPS_PER_S / work:.3g}" if mesh else \
            f"{ESTIMATE_ROBOT_STEPS_PER_S:g}"
        warn_user(f"{name} is {robot_steps:.3g} robot-steps{mesh}: about {hours:.3g} h at "
                  f"{rate} robot-steps/s (on a 2-core CPU; a GPU or "
                  f"more cores run faster)", LongWorkWarning, kind="long_work")
