"""Motion primitives: what one actuation cycle of each gait does to the robot, in its own frame.

A primitive is the steady per-cycle displacement of the centroid in the body frame (the world
frame turned by the heading at the cycle's start; x along the rest direction of A1's
bisector) and the rotation of the body per cycle, with their spread over cycles. When the eight
actuators are alike (every per-actuator field, e.g. `actuator_gains`, has one value:
`actuators_equal`), the octagon's 16 symmetries map gaits onto gaits (255 gaits in 29
classes), so only one gait per class is simulated; an image gait's per-cycle displacement is
the representative's turned by the symmetry's rotation (after mirroring across the x axis for
a reflection, which also reverses the body's rotation). When they differ (the "identified"
preset's per-actuator gains) a gait and its images are different robots, and all 255 gaits are
simulated, each its own source (`gait_sources`).

    table, cycles = measure_primitives(StarParams.preset("paper"), cycles=5, first_cycle=1)
    table.loc[table.gait == "A1+A2+A8", ["step_x_mm", "step_y_mm", "turn_deg"]]
"""

from __future__ import annotations

import math
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
import pandas as pd

from .checks import check_flag, is_whole
from .gait import N_ACTUATORS, NO_GAIT, Gait, symmetry_classes
from .metrics import rotate, wrap_degrees
from .params import PER_ACTUATOR_FIELDS, SolverConfig, StarParams
from .simulation import simulate
from .simulator import Simulator
from .timegrid import check_work, on_grid, whole_steps

# the public names (docs/api.md), those the studies use among them (tests/test_layering.py)
__all__ = ["measure_primitives", "measure_glides", "check_measurement", "PRIMITIVE_COLUMNS",
           "CYCLE_COLUMNS", "GLIDE_COLUMNS", "GLIDE_CYCLES", "actuators_equal", "gait_sources",
           "GaitSources", "simulated_gaits", "primitives_from_sources", "glides_from_sources",
           "class_symmetries", "transform_vectors", "transform_direction",
           "transform_rotation", "sort_gaits", "cycle_displacements", "expand_cycles",
           "summarise_cycles"]

GaitSources = Dict[str, Tuple[str, int, bool, int]]
"""gait -> (source, rotation, reflect, class size): the gait whose simulation a gait's steps are
read from and the symmetry mapping them onto it (`gait_sources`)."""

CYCLE_COLUMNS = ["gait", "class_representative", "symmetry_rotation", "reflected", "cycle",
                 "dx_body_mm", "dy_body_mm", "rotation_deg", "status"]
"""Columns of the per-cycle table: cycle k (0-based) runs from k·T to (k+1)·T; dx/dy_body_mm
is the centroid's displacement over it in the body frame at k·T; rotation_deg the heading
change over it (counter-clockwise)."""

PRIMITIVE_COLUMNS = ["gait", "class_representative", "class_size", "symmetry_rotation",
                     "reflected", "n_actuators", "step_x_mm", "step_y_mm", "step_x_std_mm",
                     "step_y_std_mm", "step_mm", "direction_deg", "turn_deg", "turn_std_deg",
                     "first_cycle", "cycles", "period_s", "dt_s", "status"]
"""Columns of the primitive table (one row per gait): class_representative, the gait simulated
whose cycles this gait's are read from, mapped by the symmetry (symmetry_rotation, reflected);
class_size, how many gaits that simulation stands for (`gait_sources`: with equal actuators
the symmetry class, 1 to 16 gaits; with differing ones every gait is simulated and is its own
representative, rotation 0, not reflected, class size 1); step_x/step_y_mm, the mean body-frame
displacement per cycle over cycles first_cycle..cycles-1 (0-based; the default 1..4 is the
paper's "cycles 2-5"), and its sample standard deviation (*_std_mm); step_mm its length and
direction_deg its direction in the body frame (NaN below ZERO_STEP_MM); turn_deg the mean
rotation per cycle and turn_std_deg its sample standard deviation; status the step run's, or
where that is ok and the table has glides, the first failed glide run's (its glides are NaN:
the planner leaves the gait out)."""

GLIDE_COLUMNS = ["gait", "glide_fire_cycles", "glide_x_mm", "glide_y_mm", "glide_mm",
                 "glide_turn_deg", "glide_cycles", "status"]
"""Columns of the glide table (one row per gait and number of firings): glide_x/glide_y_mm,
the centroid's displacement from the end of the last firing cycle over the glide_cycles cycles
after it, in the body frame at that moment, the robot having fired the gait at the start of
each of glide_fire_cycles cycles from rest (it builds up momentum over the first cycles, so the
glide grows with them); glide_mm its length; glide_turn_deg the rotation over the glide;
status the robot's (a failed one's glide is NaN)."""
GLIDE_CYCLES = 4
"""Cycles of coasting over which a glide is measured (the planner lets robots settle as
long)."""


def glide_columns(fired: int) -> Tuple[str, str]:
    """The primitive table's columns (x, y; mm, body frame) of the glide after `fired`
    consecutive firings of the gait from rest (see `measure_primitives`)."""
    return f"glide{fired}_x_mm", f"glide{fired}_y_mm"


def streak_step_columns(fired: int) -> Tuple[str, str]:
    """The primitive table's columns (x, y; mm, body frame) of the step of the fired-th
    consecutive firing of the gait from rest (cycle fired - 1 of the measurement)."""
    return f"step{fired}_x_mm", f"step{fired}_y_mm"


def _widen(table: pd.DataFrame, by: str, values: Tuple[str, str], names) -> Dict[str, pd.Series]:
    """A long table's two columns `values` (x, y) as columns of one row per gait: for each
    value k of column `by`, the pair `names(k)` (a column name each, in order of k)."""
    wide = table.pivot(index="gait", columns=by, values=list(values))
    columns = {}
    for key in sorted(table[by].unique()):
        for value, name in zip(values, names(int(key))):
            columns[name] = wide[(value, key)]
    return columns


def widen_steps(cycles: pd.DataFrame) -> pd.DataFrame:
    """A per-cycle table (`CYCLE_COLUMNS`) as one row per gait: gait, then
    `streak_step_columns(k)` for k = 1, 2, ... (cycle k - 1)."""
    columns = _widen(cycles, "cycle", ("dx_body_mm", "dy_body_mm"),
                     lambda cycle: streak_step_columns(cycle + 1))
    return pd.DataFrame(columns).rename_axis("gait").reset_index()


def widen_glides(glides: pd.DataFrame) -> pd.DataFrame:
    """A glide table (`GLIDE_COLUMNS`) as one row per gait: gait, then `glide_columns(k)` for
    k = 1, 2, ... firings, then glide_cycles."""
    columns = _widen(glides, "glide_fire_cycles", ("glide_x_mm", "glide_y_mm"), glide_columns)
    columns["glide_cycles"] = glides.groupby("gait")["glide_cycles"].first()
    return pd.DataFrame(columns).rename_axis("gait").reset_index()


ZERO_STEP_MM = 1e-6
"""Below this mean step (mm per cycle; the symmetric gaits' round-off is ~1e-10) a gait does
not move and has no direction."""


def actuators_equal(base: StarParams) -> bool:
    """Whether every per-actuator field of `base` (`params.PER_ACTUATOR_FIELDS`, e.g.
    actuator_gains, actuator_delays) holds one value for all eight actuators, exactly: then the
    octagon's symmetries map the robot firing a gait onto the robots firing its images.
    ValueError naming base unless it is a StarParams."""
    if not isinstance(base, StarParams):
        raise ValueError(f"base must be a StarParams, got {type(base).__name__}")
    return all(len(set(getattr(base, name))) == 1 for name in PER_ACTUATOR_FIELDS)


def gait_sources(symmetric: bool) -> GaitSources:
    """For every one of the 255 gaits: (source, rotation, reflect, class size), the gait whose
    simulation it is read from and the symmetry that maps the source's cycles onto it.
    symmetric: one source per symmetry class (`class_symmetries`); otherwise every gait is
    simulated, its own source: (gait, 0, False, 1). ValueError unless `symmetric` is a bool
    ("no" read as True: an audit, 2026-12)."""
    if check_flag("symmetric", symmetric):
        return class_symmetries()
    return {gait: (gait, 0, False, 1) for _, members in symmetry_classes() for gait in members}


def simulated_gaits(sources: GaitSources) -> List[str]:
    """The distinct sources of a `gait_sources` map, in order of first appearance (with the
    symmetry: the 29 representatives in `symmetry_classes` order)."""
    return list(dict.fromkeys(source for source, _, _, _ in sources.values()))


def class_symmetries() -> GaitSources:
    """For every one of the 255 gaits: (representative, rotation, reflect, class size) with
    representative.transform(rotation, reflect) == gait (the first such symmetry in the order
    rotation 0..7 without, then with, reflection)."""
    mapping = {}
    for representative, members in symmetry_classes():
        gait = Gait.parse(representative)
        for reflect in (False, True):
            for rotation in range(N_ACTUATORS):
                image = gait.transform(rotation, reflect).name
                mapping.setdefault(image, (representative, rotation, reflect, len(members)))
    return mapping


def transform_vectors(vectors: np.ndarray, rotation: int, reflect: bool) -> np.ndarray:
    """(..., 2) body-frame vectors under the symmetry of `Gait.transform`: mirrored across the
    x axis (y -> -y) when `reflect`, then turned by rotation·45°."""
    _check_symmetry(rotation, reflect)
    mirrored = vectors * np.array([1.0, -1.0]) if reflect else vectors
    return rotate(mirrored, math.radians(45.0 * rotation))


def transform_direction(direction_deg: float, rotation: int, reflect: bool) -> float:
    """Image of a direction (degrees from +x) under the symmetry of `Gait.transform`, in
    (-180, 180]: the angle of `transform_vectors`'s image of its unit vector. Computed on the
    angle, not through cos and sin, so that a direction on a 45° multiple stays exact (through
    them, 20 rows of the gaits study's gaits.csv changed in their tenth digit: a direction 0
    read -2.8e-14)."""
    _check_symmetry(rotation, reflect)
    angle = (-direction_deg if reflect else direction_deg) + 45.0 * rotation
    return float(wrap_degrees(angle, include_180=True))


def _check_symmetry(rotation, reflect):
    """ValueError naming the argument unless `rotation` is a whole number of 45° turns and
    `reflect` True or False, as `Gait.transform` takes them (a rotation of 1.5 gave a direction
    no symmetry gives, and reflect="no" reflected; an audit, 2026-12)."""
    if not is_whole(rotation):
        raise ValueError(f"rotation must be an integer (turns of 45°), got {rotation!r}")
    check_flag("reflect", reflect)


def transform_rotation(rotation_deg, reflect: bool):
    """Image of a body rotation (counter-clockwise, degrees; a number or an array of them)
    under the symmetry of `Gait.transform`: a rotation of the gait leaves it unchanged, a
    reflection reverses it."""
    check_flag("reflect", reflect)
    return -rotation_deg if reflect else rotation_deg


def _step_direction(step_mm) -> float:
    """Direction (degrees from +x, in (-180, 180]) of a body-frame step (2,) mm; NaN below
    ZERO_STEP_MM. A side component within 1e-9 of the step's length is the rounding of a gait
    symmetric about the x axis (its mirror image is itself) and counts as 0, so that such a
    gait's direction is 0 or 180, never -180 (five gaits along -x read -180 or 180 by the
    sign of their rounding; an audit, 2026-12)."""
    x, y = float(step_mm[0]), float(step_mm[1])
    length = math.hypot(x, y)
    if length < ZERO_STEP_MM:
        return math.nan
    side = 0.0 if abs(y) <= 1e-9 * length else y
    return float(wrap_degrees(math.degrees(math.atan2(side, x)), include_180=True))


def cycle_displacements(trajectory: pd.DataFrame, period: float) -> pd.DataFrame:
    """Per-cycle body-frame displacement and rotation of every instance from a trajectory
    recorded at every cycle boundary (columns instance, t_s, x_mm, y_mm, heading_deg). Returns
    instance, cycle, dx_body_mm, dy_body_mm, rotation_deg (NaN after a failure). ValueError
    naming the instance and the boundary where one is missing between the first and the last
    (two cycles were read as one: an audit, 2026-12)."""
    rows = []
    for instance, part in trajectory.groupby("instance", sort=True):
        part = part.sort_values("t_s")
        cycle_of = np.rint(part["t_s"].to_numpy() / period).astype(int)
        on_boundary = on_grid(part["t_s"].to_numpy(), period)
        part, cycle_of = part[on_boundary], cycle_of[on_boundary]
        gaps = np.flatnonzero(np.diff(cycle_of) != 1)
        if gaps.size:
            # a boundary recorded twice was said to have no record after it (a mutation
            # audit, 2026-12)
            at = cycle_of[gaps[0]] * period
            what = (f"two records at the cycle boundary t = {at:g} s"
                    if cycle_of[gaps[0] + 1] == cycle_of[gaps[0]]
                    else f"no record at the cycle boundary after t = {at:g} s")
            raise ValueError(f"trajectory: instance {instance} has {what} (records at every "
                             f"boundary, each once, are needed: record_interval_s = period or "
                             f"a divisor of it)")
        xy = part[["x_mm", "y_mm"]].to_numpy()
        heading = np.radians(part["heading_deg"].to_numpy())
        # the displacement in the frame the body had when the cycle began
        body = rotate(np.diff(xy, axis=0), -heading[:-1])
        rows.append(pd.DataFrame({
            "instance": instance, "cycle": cycle_of[:-1], "dx_body_mm": body[:, 0],
            "dy_body_mm": body[:, 1],
            "rotation_deg": wrap_degrees(np.degrees(np.diff(heading)))}))
    return pd.concat(rows, ignore_index=True)


def expand_cycles(representatives: pd.DataFrame,
                  sources: Optional[GaitSources] = None
                  ) -> pd.DataFrame:
    """The per-cycle table (CYCLE_COLUMNS) of all 255 gaits from that of the simulated gaits
    (columns gait, cycle, dx_body_mm, dy_body_mm, rotation_deg, status), each gait read from
    its source in `sources` (`gait_sources`; None: the 29 class representatives,
    `class_symmetries`). ValueError naming a source gait the table lacks (a raw KeyError
    before: an audit, 2026-12)."""
    sources = class_symmetries() if sources is None else sources
    by_gait = {gait: part for gait, part in representatives.groupby("gait", sort=False)}
    missing = [source for source in simulated_gaits(sources) if source not in by_gait]
    if missing:
        raise ValueError(f"representatives: no rows of gait {missing[0]} ({len(missing)} "
                         f"source gait(s) missing), whose cycles other gaits are read from")
    parts = []
    for gait, (representative, rotation, reflect, _) in sources.items():
        source = by_gait[representative]
        step = transform_vectors(source[["dx_body_mm", "dy_body_mm"]].to_numpy(), rotation,
                                 reflect)
        turn = source["rotation_deg"].to_numpy()
        parts.append(pd.DataFrame({
            "gait": gait, "class_representative": representative, "symmetry_rotation": rotation,
            "reflected": reflect, "cycle": source["cycle"].to_numpy(),
            "dx_body_mm": step[:, 0], "dy_body_mm": step[:, 1],
            "rotation_deg": transform_rotation(turn, reflect),
            "status": source["status"].to_numpy()}))
    return sort_gaits(pd.concat(parts, ignore_index=True), extra=["cycle"])[CYCLE_COLUMNS]


def sort_gaits(table: pd.DataFrame, extra: Sequence[str] = ()) -> pd.DataFrame:
    """Rows sorted by (number of actuators, actuator bits) of their gait, then `extra`."""
    key = table["gait"].map(lambda g: len(Gait.parse(g).actuators) * 256 + Gait.parse(g).bits)
    return (table.assign(_key=key).sort_values(["_key", *extra], kind="stable")
            .drop(columns="_key").reset_index(drop=True))


def summarise_cycles(cycles: pd.DataFrame, first_cycle: int,
                     sources: Optional[GaitSources] = None
                     ) -> pd.DataFrame:
    """The primitive table (PRIMITIVE_COLUMNS but the run's period_s/dt_s) from a per-cycle
    table: mean and sample standard deviation over cycles >= first_cycle; class_size from
    `sources` (`gait_sources`; None: the symmetry classes, `class_symmetries`). ValueError
    unless first_cycle is an integer from 0 to the table's last cycle (-3 was taken, 9 of a
    five-cycle table a raw KeyError: an audit, 2026-12)."""
    last = int(cycles["cycle"].max()) if len(cycles) else -1
    if not is_whole(first_cycle) or not 0 <= first_cycle <= last:
        raise ValueError(f"first_cycle must be an integer in [0, {last}] (the table's cycles), "
                         f"got {first_cycle!r}")
    sources = class_symmetries() if sources is None else sources
    sizes = {gait: size for gait, (_, _, _, size) in sources.items()}
    steady = cycles[cycles["cycle"] >= first_cycle]
    rows = []
    for gait, part in steady.groupby("gait", sort=False):
        step = part[["dx_body_mm", "dy_body_mm"]].to_numpy()
        turn = part["rotation_deg"].to_numpy()
        mean = step.mean(axis=0)
        length = float(np.hypot(*mean))
        first = part.iloc[0]
        rows.append({
            "gait": gait, "class_representative": first["class_representative"],
            "class_size": sizes[gait], "symmetry_rotation": first["symmetry_rotation"],
            "reflected": first["reflected"], "n_actuators": len(Gait.parse(gait).actuators),
            "step_x_mm": mean[0], "step_y_mm": mean[1],
            "step_x_std_mm": step[:, 0].std(ddof=1) if len(step) > 1 else math.nan,
            "step_y_std_mm": step[:, 1].std(ddof=1) if len(step) > 1 else math.nan,
            "step_mm": length,
            "direction_deg": _step_direction(mean),
            "turn_deg": turn.mean(),
            "turn_std_deg": turn.std(ddof=1) if len(turn) > 1 else math.nan,
            "first_cycle": first_cycle, "cycles": int(cycles["cycle"].max()) + 1,
            "status": first["status"]})
    return sort_gaits(pd.DataFrame(rows))


def check_measurement(base: StarParams, solver: SolverConfig, cycles: int, first_cycle: int,
                      cycles_name: str = "cycles"):
    """ValueError naming the argument unless `measure_primitives` can run with these: cycles
    (called `cycles_name` by the caller) an integer >= 1, first_cycle in [0, cycles - 1], the
    period a whole number of steps. No compute: a command line checks its input with this
    before starting."""
    if not isinstance(base, StarParams):
        raise ValueError(f"base must be a StarParams, got {type(base).__name__}")
    if not isinstance(solver, SolverConfig):
        raise ValueError(f"solver must be a SolverConfig, got {type(solver).__name__}")
    if not is_whole(cycles) or cycles < 1:
        raise ValueError(f"{cycles_name} must be an integer >= 1, got {cycles!r}")
    if not is_whole(first_cycle) or not 0 <= first_cycle < cycles:
        raise ValueError(f"first_cycle must be an integer in [0, {cycles - 1}], got "
                         f"{first_cycle!r}")
    if whole_steps(base.period, solver.dt) is None:
        raise ValueError(f"period must be a whole number of steps (dt = {solver.dt} s) to "
                         f"record every cycle boundary, got {base.period!r}")


def check_glides(base: StarParams, solver: SolverConfig, fire_cycles: int, glide_cycles: int,
                 lowest: int = 1, fire_name: str = "fire_cycles"):
    """ValueError naming glide_cycles unless it is an integer >= `lowest`, or naming the run
    (with its estimate, `timegrid.check_work`) when fire_cycles + glide_cycles periods of
    `base` would pass the step counter; before the glides' Simulator is built (arguments
    otherwise as `check_measurement` checks them)."""
    if not is_whole(glide_cycles) or glide_cycles < lowest:
        raise ValueError(f"glide_cycles must be an integer >= {lowest}, got {glide_cycles!r}")
    step, step_name = (solver.dt_max, "dt_max") if solver.adaptive else (solver.dt, "dt")
    check_work(f"{fire_name} + glide_cycles = {fire_cycles + glide_cycles} cycles of "
               f"{base.period:g} s at {step_name} = {step:g} s",
               (fire_cycles + glide_cycles) * base.period / step)


def measure_primitives(base: StarParams = StarParams(), solver: SolverConfig = SolverConfig(),
                       cycles: int = 5, first_cycle: int = 1, arch: str = "cpu",
                       progress: bool = False, glide_cycles: int = 0
                       ) -> Tuple[pd.DataFrame, pd.DataFrame]:
    """Simulate one gait per symmetry class (29 robots, one batch) for `cycles` actuation
    cycles from rest and return (primitive table, per-cycle table), both over all 255 gaits.
    When the actuators differ (`actuators_equal` False, e.g. `StarParams.preset("identified")`)
    all 255 gaits are simulated instead (255 robots, one batch), each its own class
    representative (`gait_sources`).
    base: the robot (its gait is replaced); the period
    must be a whole number of solver steps; statistics over cycles first_cycle..cycles-1
    (0-based). The primitive table also holds the step of each cycle k - 1 (the k-th firing
    in a row from rest) in the columns `streak_step_columns(k)`. With glide_cycles > 0 it
    holds each gait's glides after k = 1..cycles consecutive firings from rest
    (`measure_glides`), in the columns `glide_columns(k)`, and glide_cycles. ValueError for
    bad arguments (`check_measurement`)."""
    check_measurement(base, solver, cycles, first_cycle)
    check_glides(base, solver, cycles, glide_cycles, lowest=0, fire_name="cycles")
    return primitives_from_sources(base, solver, gait_sources(actuators_equal(base)), cycles,
                                   first_cycle, arch, progress, glide_cycles)


def primitives_from_sources(base: StarParams, solver: SolverConfig,
                            sources: GaitSources, cycles: int,
                            first_cycle: int, arch: str = "cpu", progress: bool = False,
                            glide_cycles: int = 0) -> Tuple[pd.DataFrame, pd.DataFrame]:
    """`measure_primitives` (arguments as it checks them) of the gaits in `sources` (a
    `gait_sources` map, or part of one): every distinct source simulated in one batch, each
    gait read from its source through its symmetry. Tables over the gaits of `sources`."""
    representatives = simulated_gaits(sources)
    result = simulate([base.replace(gait=g) for g in representatives], cycles * base.period,
                      solver, arch=arch, record_interval_s=base.period, progress=progress)
    per_cycle = cycle_displacements(result.trajectory, base.period)
    per_cycle["gait"] = np.asarray(representatives)[per_cycle["instance"].to_numpy()]
    per_cycle["status"] = result.summary["status"].to_numpy()[per_cycle["instance"].to_numpy()]
    expanded = expand_cycles(per_cycle, sources)
    table = summarise_cycles(expanded, first_cycle, sources)
    table["period_s"] = base.period
    table["dt_s"] = solver.dt
    table = table[PRIMITIVE_COLUMNS].merge(widen_steps(expanded), on="gait", how="left",
                                           validate="one_to_one")
    if glide_cycles:
        glides = glides_from_sources(base, solver, sources, cycles, glide_cycles, arch,
                                     progress)
        table = table.merge(widen_glides(glides), on="gait", how="left",
                            validate="one_to_one")
        # a gait whose glide run failed has NaN glides: its status says so (every row said
        # "ok" beside them, an audit), and the planner leaves it out
        failed = glides[glides["status"] != "ok"].groupby("gait")["status"].first().to_dict()
        stepped_ok = table["status"] == "ok"
        table.loc[stepped_ok, "status"] = [failed.get(gait, "ok")
                                           for gait in table.loc[stepped_ok, "gait"]]
    return table, expanded


def measure_glides(base: StarParams = StarParams(), solver: SolverConfig = SolverConfig(),
                   fire_cycles: int = 5, glide_cycles: int = GLIDE_CYCLES, arch: str = "cpu",
                   progress: bool = False) -> pd.DataFrame:
    """How far each gait's robot glides after its last firing, as a function of how many
    cycles in a row it fired: for every k = 1..fire_cycles one robot per symmetry class
    (29·fire_cycles robots, one Simulator; with differing actuators one per gait,
    255·fire_cycles, as in `measure_primitives`) fires its gait at the start of each of k
    cycles from rest, then coasts `glide_cycles` cycles. Returns the glide table
    (`GLIDE_COLUMNS`, k in glide_fire_cycles) over all 255 gaits and every k, image gaits by
    symmetry as for the steps. ValueError for bad arguments."""
    check_measurement(base, solver, fire_cycles, 0, "fire_cycles")
    check_glides(base, solver, fire_cycles, glide_cycles)
    check_flag("progress", progress)
    return glides_from_sources(base, solver, gait_sources(actuators_equal(base)), fire_cycles,
                               glide_cycles, arch, progress)


def glides_from_sources(base: StarParams, solver: SolverConfig,
                        sources: GaitSources, fire_cycles: int,
                        glide_cycles: int, arch: str = "cpu", progress: bool = False
                        ) -> pd.DataFrame:
    """`measure_glides` (arguments as it checks them) of the gaits in `sources` (a
    `gait_sources` map, or part of one): fire_cycles robots per distinct source in one
    Simulator, each gait read from its source through its symmetry. The glide table over the
    gaits of `sources`."""
    representatives = simulated_gaits(sources)
    count = len(representatives)
    # robot (k - 1)·count + i fires representative i in each of the first k cycles
    fired = np.repeat(np.arange(1, fire_cycles + 1), count)
    gaits = np.tile(np.asarray(representatives, dtype=object), fire_cycles)
    simulator = Simulator([base.replace(gait=NO_GAIT)] * len(gaits), solver, arch=arch)
    boundaries = []  # (x, y, heading) of every robot at the end of every cycle
    columns = ["centroid_x_mm", "centroid_y_mm", "heading_deg"]
    for cycle in range(fire_cycles + glide_cycles):
        if cycle < fire_cycles:
            simulator.fire(list(np.where(fired > cycle, gaits, NO_GAIT)))
        simulator.advance(base.period, progress=progress)
        boundaries.append(simulator.state()[columns].to_numpy())
    robots = np.arange(len(gaits))
    stop = np.stack(boundaries)[fired - 1, robots]
    end = np.stack(boundaries)[fired - 1 + glide_cycles, robots]
    body = rotate(end[:, :2] - stop[:, :2], -np.radians(stop[:, 2]))
    turn = wrap_degrees(end[:, 2] - stop[:, 2])
    ok = simulator.ok
    status = simulator.state()["status"].to_numpy()
    body[~ok], turn[~ok] = np.nan, np.nan
    index = {representative: i for i, representative in enumerate(representatives)}
    rows = []
    for gait, (representative, rotation, reflect, _) in sources.items():
        for k in range(1, fire_cycles + 1):
            source = (k - 1) * count + index[representative]
            glide = transform_vectors(body[source][None, :], rotation, reflect)[0]
            rows.append({"gait": gait, "glide_fire_cycles": k, "glide_x_mm": glide[0],
                         "glide_y_mm": glide[1], "glide_mm": float(np.hypot(*glide)),
                         "glide_turn_deg": transform_rotation(turn[source], reflect),
                         "glide_cycles": glide_cycles, "status": status[source]})
    return sort_gaits(pd.DataFrame(rows), extra=["glide_fire_cycles"])[GLIDE_COLUMNS]
