"""Lookahead control with the full model: drive robots to goals by simulating, every actuation
period, what each candidate gait would do from the robot's own present.

Every period each controlled robot's state is copied into one robot per candidate
(`Simulator.copy_state`): the glide ("none") and the gaits. Each candidate fires its gait, swims
the period, then coasts `settle_cycles` periods, the horizon at which the planner judges a goal
(`planner.drive`); the glide, a stop now, is judged `settle_cycles` periods from now, a period
sooner. The robot stops firing once the glide comes to rest within the tolerance of its goal
(as the planner's closed loop plans for the glide), and otherwise takes the future of the
candidate that comes to rest nearest its goal (its state after the period, copied back), which
may be the glide too. No table of motion primitives: a candidate is the robot's own state
simulated, its momentum, turning and hot actuators included, so a goal between the gaits'
directions is approached by whatever sequence the model itself finds best, one firing at a
time. The price is 1 + settle_cycles periods of every candidate per decision: G goals and K
candidates make a batch of G·(1 + K) robots, and a run of many goals takes hours: with
`checkpoint` the run so far is written to a file after every decision, and a call with the same
arguments continues from it bit for bit.
"""

from __future__ import annotations

import io
import json
from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence

import numpy as np
import pandas as pd

from .checks import check_flag, warn_user
from .driver import robots_label
from .gait import N_ACTUATORS, NO_GAIT, Gait, all_gaits
from .params import SolverConfig, StarParams
from .planner import SETTLE_CYCLES, check_drive, judged_at_rest
from .provenance import code_version, file_path, write_atomic
from .runtime import check_arch
from .simulator import Simulator, SimulatorSnapshot
from .timegrid import check_work

__all__ = ["lookahead_drive", "check_lookahead", "compare_controllers", "every_gait",
           "LOOKAHEAD_MODE", "LOOKAHEAD_CYCLE_COLUMNS", "CONTROLLER_COLUMNS"]

LOOKAHEAD_MODE = "lookahead"
"""The `mode` of `lookahead_drive`'s rows (`planner.drive`'s are "open" and "closed")."""
LOOKAHEAD_CYCLE_COLUMNS = ["goal", "mode", "cycle", "gait", "x_mm", "y_mm", "heading_deg",
                           "distance_mm", "predicted_rest_x_mm", "predicted_rest_y_mm",
                           "predicted_rest_error_mm"]
"""Columns of `lookahead_drive`'s per-cycle table: the robot's state at the start of cycle
`cycle`, the gait chosen there ("none": the glide, and after the controller stopped) and where
the chosen candidate came to rest, `settle_cycles` periods after this period (mm from the
start; NaN after the stop), with its distance to the goal: the full model's own prediction."""


CONTROLLER_COLUMNS = ["mode", "goals", "reached", "mean_end_error_mm", "max_end_error_mm",
                      "mean_final_error_mm", "mean_cycles_fired", "mean_cycles_to_goal"]
"""Columns of `compare_controllers`: per controller (mode) the goals, how many it reached, the
mean and largest distance to the goal at rest (end_error_mm) and when it stopped firing
(final_error_mm), the cycles it fired, and the mean cycles to the goal over the goals that
every controller compared reached (NaN where there are none)."""


PATH_COLUMNS = ["goal", "mode", "t_s", "x_mm", "y_mm"]
"""Columns of the path rows a lookahead gathers per period (`controlled` is added at the end)."""
CHECKPOINT_FORMAT = 1
"""The layout of a checkpoint file (`_write_checkpoint`); another is refused by name."""


def every_gait() -> list:
    """The glide ("none") and the 255 gaits (`gait.all_gaits`): every candidate a lookahead
    can fire."""
    return [NO_GAIT] + all_gaits()


def _candidate_masks(gaits: Sequence[str]) -> tuple:
    """(names, (K, 8) bool) of the candidates: "none" first, then the other gaits in order;
    ValueError naming `gaits` for a text that is no gait, one given twice, or none at all."""
    if isinstance(gaits, (str, Gait)) or not all(isinstance(g, (str, Gait)) for g in gaits):
        raise ValueError(f"gaits must be a list of gaits such as ['A1+A3', 'A2'], got "
                         f"{gaits!r}")
    parsed = [Gait.parse(gait) for gait in gaits]
    names = [gait.name for gait in parsed]
    repeated = sorted({name for name in names if names.count(name) > 1})
    if repeated:
        raise ValueError(f"gaits names {repeated[0]} more than once")
    fired = [gait for gait in parsed if gait.name != NO_GAIT]
    if not fired:
        raise ValueError("gaits must hold at least one gait that fires an actuator")
    names = [NO_GAIT] + [gait.name for gait in fired]
    return names, np.stack([np.zeros(N_ACTUATORS, bool)] + [gait.mask.astype(bool)
                                                             for gait in fired])


def check_lookahead(goals_mm, params: StarParams = StarParams(),
                    solver: SolverConfig = SolverConfig(), tolerance_mm: float = 5.0,
                    max_cycles: int = 25, settle_cycles: int = SETTLE_CYCLES,
                    gaits: Optional[Sequence[str]] = None, frames_per_cycle: int = 10,
                    arch: str = "cpu", checkpoint=None):
    """(goals (G, 2), candidate names, candidate masks (K, 8)) of a `lookahead_drive` with
    these arguments, or ValueError naming the one it refuses (`planner.check_drive`'s, gaits,
    a checkpoint that is another lookahead's or none at all, or whose folder is missing), and
    for work that cannot finish (`timegrid.check_work` on the whole batch's steps: every
    decision simulates 1 + settle_cycles periods of G·(1 + K) robots). No compute: a command
    line checks its input with this before starting."""
    goals = check_drive(goals_mm, params, solver, tolerance_mm, max_cycles, frames_per_cycle,
                        settle_cycles)
    names, masks = _candidate_masks(every_gait() if gaits is None else gaits)
    check_arch(arch)
    if checkpoint is not None:
        _read_checkpoint(checkpoint, _definition(goals, params, solver, tolerance_mm,
                                                 max_cycles, settle_cycles, names,
                                                 frames_per_cycle, arch), header_only=True)
    step = solver.dt_max if solver.adaptive else solver.dt
    check_work(f"max_cycles = {max_cycles} decisions of {1 + settle_cycles} periods of "
               f"{params.period:g} s, then {settle_cycles} of coasting, at {step:g}-s steps",
               (max_cycles * (1 + settle_cycles) + settle_cycles) * params.period / step,
               len(goals) * (1 + len(masks)), arch, params.n_nodes)
    return goals, names, masks


def lookahead_drive(goals_mm, params: StarParams = StarParams(),
                    solver: SolverConfig = SolverConfig(), tolerance_mm: float = 5.0,
                    max_cycles: int = 25, settle_cycles: int = SETTLE_CYCLES,
                    gaits: Optional[Sequence[str]] = None, frames_per_cycle: int = 10,
                    arch: str = "cpu", progress: bool = False, checkpoint=None):
    """Drive one robot per goal by a one-firing lookahead over `gaits` (default `every_gait()`;
    the glide is always a candidate) with the full model (module docstring), in one Simulator of
    G·(1 + K) robots, until every controller has stopped or max_cycles have run, then coast
    `settle_cycles` cycles; a goal is reached, as `planner.drive` judges it, if the robot comes
    to rest (settle_cycles after its own controller stopped) within tolerance_mm of it.

    goals_mm: (G, 2) goal points relative to the start (the robot starts at rest, heading 0).
    Returns (summary, cycles, path) as `planner.drive`'s, mode `LOOKAHEAD_MODE`: summary
    `planner.PLAN_COLUMNS`, cycles `LOOKAHEAD_CYCLE_COLUMNS`, path (goal, mode, t_s,
    controlled, x_mm, y_mm) recorded frames_per_cycle times per cycle. ValueError for bad
    arguments or work that cannot finish (`check_lookahead`), before any compute.

    progress: one bar over the run's periods (the whole batch's: 1 + settle_cycles a
    decision), naming the decision and how many goals it still drives.
    checkpoint: the path of a file (.npz) the run so far is written to after every decision,
    whole or not at all (the robots' states, the candidates' included, about 31 kB a robot of
    the paper model, and the tables so far). Where it exists, the call continues from it,
    bit for bit as the run it belongs to would have gone on; one of another lookahead (other
    goals, parameters, solver or arguments) is refused naming what differs, one written by
    another version of the code continues with a RuntimeWarning naming both. The file stays
    after the run: remove it once the results are kept (a call with it again redoes only the
    last decision's coast)."""
    goals, names, masks = check_lookahead(goals_mm, params, solver, tolerance_mm, max_cycles,
                                          settle_cycles, gaits, frames_per_cycle, arch,
                                          checkpoint)
    check_flag("progress", progress)
    definition = saved = None
    if checkpoint is not None:
        definition = _definition(goals, params, solver, tolerance_mm, max_cycles,
                                 settle_cycles, names, frames_per_cycle, arch)
        saved = _read_checkpoint(checkpoint, definition)
    count, candidates = len(goals), len(masks)
    batch = count * (1 + candidates)
    period = params.period
    robots = np.arange(count)
    # robot g's candidates: rows count + g·K ... count + g·K + K − 1 (candidate 0: the glide)
    first = count + robots * candidates
    simulator = Simulator([params.replace(gait=NO_GAIT)] * batch, solver, arch=arch)
    commands = np.zeros((batch, N_ACTUATORS), dtype=bool)
    commands[count:] = np.tile(masks, (count, 1))
    stopped = np.zeros(count, dtype=bool)
    stop_cycle = np.full(count, max_cycles)
    final_error = np.full(count, np.nan)
    fired = np.zeros(count, dtype=np.int64)
    boundaries, cycle_rows, paths = [], [], []
    interval = period / frames_per_cycle
    first_cycle = 0 if saved is None else saved.next_cycle
    bar = _progress_bar(count, candidates, max_cycles, settle_cycles, first_cycle) \
        if progress else None

    def advance(periods: int, **records) -> pd.DataFrame:
        """The whole batch `periods` periods on (the run's bar moved by as many; no bar of
        its own, which a long advance of a large batch shows by default)."""
        frames = simulator.advance(periods * period, progress=False, **records)
        if bar is not None:
            bar.update(periods)
        return frames

    if saved is not None:  # the run so far, as the checkpoint holds it
        simulator.load(saved.snapshot)
        stopped, stop_cycle = saved.arrays["stopped"], saved.arrays["stop_cycle"]
        final_error, fired = saved.arrays["final_error"], saved.arrays["fired"]
        boundaries = list(saved.arrays["boundaries"])
        cycle_rows = [saved.table("cycles", LOOKAHEAD_CYCLE_COLUMNS)]
        paths = [saved.table("paths", PATH_COLUMNS)]
    for cycle in range(first_cycle, max_cycles + 1):
        state = simulator.state().iloc[:count]
        position = state[["centroid_x_mm", "centroid_y_mm"]].to_numpy()
        boundaries.append(position)
        distance = np.hypot(*(goals - position).T)
        running = state["status"].to_numpy() == "ok"
        controlled = ~stopped & running & (cycle < max_cycles)
        if bar is not None and controlled.any():
            bar.set_postfix_str(f"decision {cycle + 1}, driving {controlled.sum()} of {count}")
        choice = np.zeros(count, dtype=np.int64)
        rest = np.full((count, 2), np.nan)
        if controlled.any():
            # the period and the coast after it, every candidate from its robot's present
            for g in np.flatnonzero(controlled):
                simulator.copy_state(int(g), to=first[g] + np.arange(candidates))
            # the candidates of a stopped controller coast (their futures are not asked for)
            firing = np.zeros(batch, dtype=bool)
            firing[count:] = np.repeat(controlled, candidates)
            simulator.fire(commands & firing[:, None])
            frames = advance(1, record_interval_s=interval)
            after_period = simulator.save()
            # judged as a stop: a firing now comes to rest settle_cycles after the next cycle
            # starts, the glide (a stop now) settle_cycles after this one, a period sooner
            glide_rest = position
            if settle_cycles:
                if settle_cycles > 1:
                    advance(settle_cycles - 1)
                glide_rest = _positions(simulator)[count::candidates]
                advance(1)
            ends = simulator.state()
            at_rest = np.array(ends[["centroid_x_mm", "centroid_y_mm"]].to_numpy()[count:])
            at_rest = at_rest.reshape(count, candidates, 2)
            at_rest[:, 0] = glide_rest
            ok = (ends["status"].to_numpy()[count:] == "ok").reshape(count, candidates)
            misses = np.where(ok, np.hypot(*np.moveaxis(at_rest - goals[:, None], -1, 0)),
                              np.inf)
            # as the planner plans for the glide: no firing once coasting from now comes to
            # rest within the tolerance (a firing that would land nearer is not worth a cycle)
            best = np.where(misses[:, 0] <= tolerance_mm, 0, np.argmin(misses, axis=1))
            # back to the end of the period: every robot has coasted it, its candidates swum it
            simulator.load(after_period)
            choice[controlled] = best[controlled]
            rest[controlled] = at_rest[controlled, best[controlled]]
        # a controller stops when it chooses the glide, its robot fails or the budget is spent
        stopping = ~stopped & ((choice == 0) | ~running | (cycle == max_cycles))
        final_error[stopping] = distance[stopping]
        stop_cycle[stopping] = cycle
        stopped |= stopping
        cycle_rows.append(pd.DataFrame({
            "goal": robots, "mode": LOOKAHEAD_MODE, "cycle": cycle,
            "gait": np.asarray(names)[choice], "x_mm": position[:, 0], "y_mm": position[:, 1],
            "heading_deg": state["heading_deg"].to_numpy(), "distance_mm": distance,
            "predicted_rest_x_mm": rest[:, 0], "predicted_rest_y_mm": rest[:, 1],
            "predicted_rest_error_mm": np.hypot(*(goals - rest).T)}))
        if not controlled.any():
            break  # every controller has stopped (the rule above stops the rest now)
        # each robot's period: the chosen candidate's (its state copied back), or its own coast
        source = np.where(choice > 0, first + choice, robots)
        for g in np.flatnonzero(choice > 0):
            simulator.copy_state(int(source[g]), to=int(g))
        fired += choice > 0
        paths.append(_relabelled(frames, source))
        if checkpoint is not None:
            _write_checkpoint(checkpoint, definition, cycle + 1, simulator.save(), {
                "stopped": stopped, "stop_cycle": stop_cycle, "final_error": final_error,
                "fired": fired, "boundaries": np.stack(boundaries),
                **_columns("cycles", pd.concat(cycle_rows, ignore_index=True)),
                **_columns("paths", pd.concat(paths, ignore_index=True))})
    if bar is not None:  # the decisions the run did not need are not waited for
        bar.total = bar.n + settle_cycles
        bar.set_postfix_str("coasting to rest")
    for _ in range(settle_cycles):  # the robots coast on to rest, no controller firing
        frames = advance(1, record_interval_s=interval)
        paths.append(_relabelled(frames, robots))
        boundaries.append(simulator.state()[["centroid_x_mm", "centroid_y_mm"]]
                          .to_numpy()[:count])
    if bar is not None:
        bar.close()
    summary = judged_at_rest(goals, robots, LOOKAHEAD_MODE, boundaries, stop_cycle,
                             settle_cycles, simulator.state()["status"].to_numpy()[:count],
                             tolerance_mm, fired, final_error)
    start = pd.DataFrame({"goal": robots, "mode": LOOKAHEAD_MODE, "t_s": 0.0, "x_mm": 0.0,
                          "y_mm": 0.0})
    path = pd.concat([start, *paths], ignore_index=True)
    path["controlled"] = path["t_s"] <= (stop_cycle[path["goal"].to_numpy()] * period
                                         + solver.dt / 2)
    path = path.sort_values(["goal", "t_s"], kind="stable").reset_index(drop=True)
    return (summary, pd.concat(cycle_rows, ignore_index=True)[LOOKAHEAD_CYCLE_COLUMNS],
            path[["goal", "mode", "t_s", "controlled", "x_mm", "y_mm"]])


def _progress_bar(goals: int, candidates: int, max_cycles: int, settle_cycles: int,
                  first_cycle: int):
    """A tqdm bar over the run's periods, the whole batch's: 1 + settle_cycles a decision, at
    most max_cycles of them, then the coast to rest; a run whose controllers all stop sooner
    skips the rest (the time left it shows is the longest the run can take)."""
    from tqdm.auto import tqdm
    per_decision = 1 + settle_cycles
    return tqdm(total=max_cycles * per_decision + settle_cycles,
                initial=first_cycle * per_decision, unit="period",
                desc=f"lookahead, {robots_label(goals, 'goal')} x {candidates} candidates",
                bar_format="{l_bar}{bar}| {n}/{total} periods [{elapsed}<{remaining}{postfix}]")


def _definition(goals: np.ndarray, params: StarParams, solver: SolverConfig,
                tolerance_mm, max_cycles, settle_cycles, names: Sequence[str],
                frames_per_cycle, arch: str) -> Dict:
    """What a lookahead's result depends on, as JSON values read back (a checkpoint continues
    only a run of the same; floats by repr, to the last bit)."""
    return json.loads(json.dumps({
        "goals_mm": goals.tolist(), "params": repr(params), "solver": repr(solver),
        "tolerance_mm": float(tolerance_mm), "max_cycles": int(max_cycles),
        "settle_cycles": int(settle_cycles), "gaits": list(names),
        "frames_per_cycle": int(frames_per_cycle), "arch": arch}))


def _columns(prefix: str, table: pd.DataFrame) -> Dict[str, np.ndarray]:
    """A table's columns as checkpoint arrays "prefix:column" (text as NumPy text: no pickle)."""
    return {f"{prefix}:{name}": table[name].to_numpy(
        dtype=None if table[name].dtype.kind in "biuf" else str) for name in table.columns}


@dataclass(frozen=True)
class _Checkpoint:
    """A checkpoint read back: the cycle the run goes on at, the Simulator's state, the
    bookkeeping arrays (`_write_checkpoint`)."""

    next_cycle: int
    snapshot: Optional[SimulatorSnapshot]
    arrays: Dict[str, np.ndarray]

    def table(self, prefix: str, columns: List[str]) -> pd.DataFrame:
        return pd.DataFrame({name: self.arrays[f"{prefix}:{name}"] for name in columns})


def _write_checkpoint(path, definition: Dict, next_cycle: int, snapshot: SimulatorSnapshot,
                      arrays: Dict[str, np.ndarray]):
    """The run so far to `path`, whole or not at all (`provenance.write_atomic`): a JSON header
    (format, definition, the code's version, next cycle, the snapshot's header) and the
    snapshot's fields ("state:NAME") beside the bookkeeping arrays."""
    header = {"format": CHECKPOINT_FORMAT, "definition": definition, "code": code_version(),
              "next_cycle": next_cycle, "snapshot": snapshot.header()}
    archive = io.BytesIO()
    np.savez(archive, __lookahead__=np.array(json.dumps(header)), **arrays,
             **{f"state:{name}": field for name, field in snapshot.fields.items()})
    write_atomic(path, archive.getvalue(), failure=OSError)


def _read_checkpoint(checkpoint, definition: Dict, header_only: bool = False
                     ) -> Optional[_Checkpoint]:
    """The checkpoint at `checkpoint` for a lookahead of `definition`, None where no file is
    there (its folder must be); with header_only its arrays, state and code are not read.
    ValueError naming `checkpoint`: not a path, a folder, no such folder, not a lookahead's
    checkpoint (damaged, another file), another format or another lookahead (the first
    entries that differ). A checkpoint of another code version: RuntimeWarning naming both."""
    path = file_path(checkpoint, "path of the lookahead's checkpoint file (.npz)")
    if path.is_dir():
        raise ValueError(f"checkpoint {str(path)!r} is a folder: give the checkpoint's file, "
                         f"e.g. {str(path / 'lookahead.npz')!r}")
    if not path.exists():
        if not path.parent.is_dir():
            raise ValueError(f"checkpoint {str(path)!r}: its folder {str(path.parent)!r} does "
                             f"not exist")
        return None
    try:
        with np.load(path, allow_pickle=False) as archive:
            header = json.loads(str(archive["__lookahead__"]))
            arrays = {} if header_only else {name: archive[name] for name in archive.files
                                             if name != "__lookahead__"}
        next_cycle = int(header["next_cycle"])
        saved_format, saved, code = header["format"], dict(header["definition"]), header["code"]
        snapshot = None if header_only else SimulatorSnapshot.from_header(
            {name[len("state:"):]: field for name, field in arrays.items()
             if name.startswith("state:")}, header["snapshot"])
    except OSError as error:
        raise ValueError(f"checkpoint {str(path)!r}: cannot read it "
                         f"({error.strerror or error})") from None
    except Exception as error:  # noqa: BLE001 -- whatever a foreign file makes numpy raise
        raise ValueError(f"checkpoint {str(path)!r}: not a lookahead's checkpoint "
                         f"({type(error).__name__}; a damaged file, or another's)") from None
    if saved_format != CHECKPOINT_FORMAT:
        raise ValueError(f"checkpoint {str(path)!r}: format {saved_format!r}, this version "
                         f"reads {CHECKPOINT_FORMAT}")
    differing = [key for key in definition if saved.get(key) != definition[key]]
    if differing or set(saved) - set(definition):
        named = differing[0] if differing else sorted(set(saved) - set(definition))[0]
        raise ValueError(f"checkpoint {str(path)!r} belongs to another lookahead: {named} is "
                         f"{saved.get(named)!r} there, {definition.get(named)!r} here (remove "
                         f"it or give another file to start afresh)")
    count = len(definition["goals_mm"])
    shapes = {"stopped": (count,), "stop_cycle": (count,), "final_error": (count,),
              "fired": (count,), "boundaries": (next_cycle, count, 2)}
    missing = [] if header_only else [
        name for name in [*shapes, *(f"cycles:{column}" for column in LOOKAHEAD_CYCLE_COLUMNS),
                          *(f"paths:{column}" for column in PATH_COLUMNS)]
        if name not in arrays or name in shapes and arrays[name].shape != shapes[name]]
    if not 1 <= next_cycle <= definition["max_cycles"] or missing:
        raise ValueError(f"checkpoint {str(path)!r}: a damaged file (next cycle {next_cycle} "
                         f"of at most {definition['max_cycles']}"
                         f"{', ' + missing[0] + ' missing or misshapen' if missing else ''})")
    own = None if header_only else code_version()
    if own is not None and code != own:
        warn_user(f"checkpoint {str(path)!r} was written by another version of the code "
                  f"({code}); it goes on under this one ({own}), so the run is not one code's "
                  f"bit for bit")
    return _Checkpoint(next_cycle, snapshot, arrays)


def _relabelled(frames: pd.DataFrame, source: np.ndarray) -> pd.DataFrame:
    """The records of robots `source[g]` (a period's frames) as goal g's path rows."""
    goal_of = {int(row): g for g, row in enumerate(source)}
    kept = frames[frames["instance"].isin(goal_of)]
    return pd.DataFrame({"goal": kept["instance"].map(goal_of).to_numpy(),
                         "mode": LOOKAHEAD_MODE, "t_s": kept["t_s"].to_numpy(),
                         "x_mm": kept["centroid_x_mm"].to_numpy(),
                         "y_mm": kept["centroid_y_mm"].to_numpy()})


def compare_controllers(summary: pd.DataFrame) -> pd.DataFrame:
    """`CONTROLLER_COLUMNS`, one row per controller (mode, in order of appearance), from the
    summaries of `planner.drive` and `lookahead_drive` concatenated (the same goals).
    ValueError unless `summary` has their columns."""
    needed = ("goal", "mode", "reached", "end_error_mm", "final_error_mm", "cycles_fired",
              "cycles_to_goal")
    if not isinstance(summary, pd.DataFrame) or not set(needed) <= set(summary.columns):
        raise ValueError(f"summary must hold drive's or lookahead_drive's summaries (columns "
                         f"{', '.join(needed)}), got {type(summary).__name__}")
    every = summary.groupby("goal")["reached"].transform("all").to_numpy(dtype=bool)
    rows = []
    for mode, part in summary.groupby("mode", sort=False):
        both = part[every[summary["mode"].to_numpy() == mode]]
        rows.append({"mode": mode, "goals": len(part), "reached": int(part["reached"].sum()),
                     "mean_end_error_mm": part["end_error_mm"].mean(),
                     "max_end_error_mm": part["end_error_mm"].max(),
                     "mean_final_error_mm": part["final_error_mm"].mean(),
                     "mean_cycles_fired": part["cycles_fired"].mean(),
                     "mean_cycles_to_goal": both["cycles_to_goal"].mean()})
    return pd.DataFrame(rows, columns=CONTROLLER_COLUMNS)


def _positions(simulator: Simulator) -> np.ndarray:
    """(B, 2) every robot's centroid now, mm from its start."""
    return simulator.state()[["centroid_x_mm", "centroid_y_mm"]].to_numpy()
