"""Drive robots to goal points by choosing a gait every actuation cycle from a primitive table.

The model: the k-th cycle in a row of gait g moves the centroid by its body-frame step s_g,k
(turned into the world by the heading θ at the cycle's start) and turns the body by its mean
turn ω_g: p' = p + R(θ)·s_g,k, θ' = θ + ω_g (`PrimitiveModel.predict`). A robot that stops
firing after k cycles in a row of gait g glides on to rest at p + R(θ)·γ_g,k (body frame at
the stop; 0 when the primitives hold no glides). The robot builds up momentum over its first
cycles, so both depend on the streak k: s_g,k is the step of the per-cycle measurement's cycle
k - 1 from rest while k is within the cycles measured, the steady mean step after (paper
preset, A1+A3: 15.1, 19.6, 20.2, 20.3 mm in its first four cycles, steady 20.1); γ_g,k is the
glide after k firings from rest (`primitives.measure_glides`), the longest measured streak's
beyond (A1+A3: 22.8 mm after one firing, 25.2 after five, over 4 cycles of coasting). A
gait fired after a different one whose steady step points within
ALIGNED_DEG continues the streak (the robot keeps the momentum it built that way: on the
paper preset's 150-mm goal the closed loop missed by 5.3 mm when a switch restarted the
streak); any other starts a new streak of 1 (the momentum points elsewhere, and the k = 1
values are measured from the nearest state, rest). The choice
(`PrimitiveModel.choose`) plans for the glide with a two-cycle lookahead on the rest
positions: fire nothing once the robot would come to rest within the tolerance if it stopped
now (given the gait it fired last and its streak); else the gait after which it would come to
rest within it, if one does (the closest such); else the first gait of the pair of cycles
whose rest position is closest to the goal.

Two controllers run in one Simulator (`drive`): open loop plans every cycle from the model at
the start and fires that plan blindly; closed loop re-plans each cycle from the simulated
position and heading and stops firing once its predicted rest is within the tolerance. After
the last controller stops the batch coasts `settle_cycles` more cycles, and a goal is judged
by where the robot comes to rest: `settle_cycles` cycles after its own controller stopped, the
horizon over which the glides are measured. (Under the paper preset's quadratic drag a coasting
robot slows down as 1/t and creeps on for many cycles, ~1 mm per cycle after 7; judging every
robot at the end of the batch would credit an early stopper with a longer glide than the
model's.)
"""

from __future__ import annotations

import math
from typing import Optional, Sequence

import numpy as np
import pandas as pd

from .checks import check_finite, check_flag, is_finite_real, is_whole, shown, warn_user
from .gait import NO_GAIT, Gait
from .metrics import MAX_GOAL_MM, rotate
from .params import SolverConfig, StarParams
from .primitives import GLIDE_CYCLES, glide_columns, streak_step_columns
from .runtime import check_arch
from .simulator import Simulator
from .timegrid import check_work, whole_steps

# the public names (docs/api.md), those the studies use among them (tests/test_layering.py)
__all__ = ["PrimitiveModel", "drive", "check_drive", "default_goals", "closed_loop_gain",
           "judged_at_rest", "path_frames", "SETTLE_CYCLES", "MAX_DEFAULT_GOALS", "PLAN_COLUMNS",
           "CYCLE_COLUMNS"]

MODES = ("open", "closed")

PLAN_COLUMNS = ["goal", "goal_x_mm", "goal_y_mm", "goal_distance_mm", "mode", "reached",
                "cycles_to_goal", "cycles_fired", "final_error_mm", "end_error_mm", "run_cycles",
                "status"]
"""Columns of `drive`'s summary: reached (at rest within the tolerance: end_error_mm ≤
tolerance_mm, the instance ok); cycles_to_goal (the cycle at which its controller stopped
firing, for a goal reached; NaN otherwise); cycles_fired (cycles with a firing);
final_error_mm (distance to the goal when the controller stopped, the robot still gliding);
end_error_mm (distance to the goal at rest: `settle_cycles` cycles after its controller
stopped, after run_cycles cycles in all); status of the instance."""

CYCLE_COLUMNS = ["goal", "mode", "cycle", "gait", "x_mm", "y_mm", "heading_deg",
                 "distance_mm", "predicted_x_mm", "predicted_y_mm"]
"""Columns of `drive`'s per-cycle table: the state at the start of cycle `cycle` (so cycle
c's row holds the result of the c cycles before), the gait fired in it ("none" after the
controller stopped) and the position the model's cycle steps predicted for this boundary
(open loop: from the start; closed loop: from the previous boundary): a cycle of "none"
moves nothing there, so after a stop they leave out the glide, which the plans allow for."""


ALIGNED_DEG = 45.0
"""A gait fired after another whose steady step points within this angle (deg), the angle
itself included, continues its momentum streak (`PrimitiveModel.next_streak`)."""
ALIGNED_SLACK = 1e-9
"""Relative slack of the alignment test: two gaits the robot's symmetry puts exactly
ALIGNED_DEG apart (3,072 ordered pairs of the 255 gaits) measure that angle to the rounding of
their steps (~1e-11 relative), and the rounding's sign decided whether the streak went on (half
of the pairs each way, mirror images unlike; an audit, 2026-12): within this slack they are
aligned."""


class PrimitiveModel:
    """The gaits a planner may fire, with their mean per-cycle body-frame step (mm) and turn
    (deg), plus "none" (no step, no turn).

    gaits: G names; steps_mm: (G, 2); turns_deg: (G,); glides_mm: (K, G, 2) the body-frame
    glide after the last of k = 1..K consecutive firings of a gait until rest, or (G, 2) for
    one glide whatever the streak (K = 1), or None (no glide); streak_steps_mm: (S, G, 2) the
    step of the k-th consecutive firing from rest, k = 1..S (the robot speeds up over its
    first cycles), the steady step after (None: S = 0). Attributes: gaits (G' names, "none"
    first), steps_mm (G', 2), streak_steps_mm (S + 1, G', 2), turns_rad (G',), glides_mm
    (K, G', 2), masks (G', 8), glide_cycles (the cycles of coasting the glides span, where
    the table says: `drive` judges its robots as many cycles after their controllers stop;
    None otherwise)."""

    def __init__(self, gaits: Sequence[str], steps_mm, turns_deg, glides_mm=None,
                 streak_steps_mm=None, glide_cycles: Optional[int] = None):
        if isinstance(gaits, str) or not hasattr(gaits, "__iter__"):
            raise ValueError(f"gaits must be a sequence of gait texts, got {gaits!r}")
        arrays = {}
        for name, values in (("steps_mm", steps_mm), ("turns_deg", turns_deg),
                             ("glides_mm", glides_mm), ("streak_steps_mm", streak_steps_mm)):
            try:  # NumPy's "could not convert string to float" named no argument
                arrays[name] = None if values is None else np.asarray(values, dtype=np.float64)
            except (TypeError, ValueError):
                raise ValueError(f"{name} must hold numbers (mm or deg), got {values!r}") from None
        steps, turns = arrays["steps_mm"], arrays["turns_deg"]
        streak_steps = (np.zeros((0, *steps.shape)) if streak_steps_mm is None
                        else arrays["streak_steps_mm"])
        names = [Gait.parse(g).name for g in gaits]
        repeated = sorted({name for name in names if names.count(name) > 1})
        if repeated:
            raise ValueError(f"gaits must name each gait once, got {', '.join(repeated)} more "
                             f"than once")
        if not [name for name in names if name != NO_GAIT]:
            raise ValueError(f"gaits must name at least one gait other than {NO_GAIT!r} (from "
                             f"a primitive table: its rows of status ok), got {names}")
        glides = np.zeros_like(steps) if glides_mm is None else arrays["glides_mm"]
        if glides.ndim == 2:
            glides = glides[None]
        if steps.shape != (len(names), 2) or turns.shape != (len(names),) \
                or glides.shape[1:] != steps.shape or not len(glides) \
                or streak_steps.shape[1:] != steps.shape:
            raise ValueError(f"steps_mm must be ({len(names)}, 2), glides_mm (K >= 1, "
                             f"{len(names)}, 2) or ({len(names)}, 2), streak_steps_mm (S, "
                             f"{len(names)}, 2) and turns_deg ({len(names)},), got "
                             f"{steps.shape}, {glides.shape}, {streak_steps.shape} and "
                             f"{turns.shape}")
        if not (np.isfinite(steps).all() and np.isfinite(turns).all()
                and np.isfinite(glides).all() and np.isfinite(streak_steps).all()):
            raise ValueError("steps_mm, turns_deg, glides_mm and streak_steps_mm must be "
                             "finite")
        keep = [i for i, name in enumerate(names) if name != NO_GAIT]
        self.gaits = [NO_GAIT] + [names[i] for i in keep]
        self.steps_mm = np.vstack([np.zeros((1, 2)), steps[keep]])
        # the steps of streaks 1..S, then the steady step for every longer streak
        self.streak_steps_mm = np.concatenate(
            [np.zeros((len(streak_steps) + 1, 1, 2)),
             np.concatenate([streak_steps[:, keep], steps[None, keep]])], axis=1)
        self.glides_mm = np.concatenate([np.zeros((len(glides), 1, 2)), glides[:, keep]],
                                        axis=1)
        self.turns_rad = np.radians(np.concatenate([[0.0], turns[keep]]))
        self.masks = np.stack([Gait.parse(g).mask.astype(bool) for g in self.gaits])
        if glide_cycles is not None and (not is_whole(glide_cycles) or glide_cycles < 1):
            raise ValueError(f"glide_cycles must be None or an integer >= 1, got "
                             f"{glide_cycles!r}")
        self.glide_cycles = None if glide_cycles is None else int(glide_cycles)

    @classmethod
    def from_table(cls, table: pd.DataFrame, expect_glides: bool = True) -> "PrimitiveModel":
        """From a primitive table (`taichi_star.primitives`): its ok gaits' step_x_mm,
        step_y_mm and turn_deg, the steps of the k-th firing in a row from rest in the columns
        `primitives.streak_step_columns(k)` and the glides after k = 1, 2, ... firings in
        the columns `primitives.glide_columns(k)` where it has them (none: steady steps, no
        glide, and, with `expect_glides`, a RuntimeWarning: the robot glides on after its last
        firing, and a plan without glides overshoots its goals). ValueError for a
        table with the single glide_x_mm/glide_y_mm of earlier versions (measured after
        several firings only): measure it again, for a table without the columns it reads,
        for a cell of them that is no number, for a kept gait's that is not finite, and for
        gaits that are none or listed twice (all before the warning). A gait whose status is
        not ok, and an ok gait without a finite step_x_mm or turn_deg, is left out, with a
        RuntimeWarning naming it (the failed ones were left out silently: an audit, 2026-12).
        """
        if not isinstance(table, pd.DataFrame):  # a path had failed on its .columns
            raise ValueError(f"table must be a pandas DataFrame (pandas.read_csv of a "
                             f"primitives CSV), got {type(table).__name__}")
        missing = [column for column in ("gait", "status", "step_x_mm", "step_y_mm", "turn_deg")
                   if column not in table.columns]
        if missing:
            raise ValueError(f"table: not a primitive table (taichi_star.primitives): no column "
                             f"{missing[0]!r}")
        check_flag("expect_glides", expect_glides)
        streaks = 0
        while set(glide_columns(streaks + 1)) <= set(table.columns):
            streaks += 1
        if not streaks and "glide_x_mm" in table.columns:
            raise ValueError("the primitive table has one glide per gait (glide_x_mm), not one "
                             "per streak of firings (glide1_x_mm, ...): measure it again")
        stepped = 0
        while set(streak_step_columns(stepped + 1)) <= set(table.columns):
            stepped += 1
        read = ["step_x_mm", "step_y_mm", "turn_deg",
                *(c for k in range(1, stepped + 1) for c in streak_step_columns(k)),
                *(c for k in range(1, streaks + 1) for c in glide_columns(k))]
        numbers = table[read].apply(pd.to_numeric, errors="coerce")
        # the gaits measured with a steady step and turn; a failed gait's numbers may be
        # missing, and so the steady ones of too short a measurement (such gaits are left out)
        kept = ((table["status"] == "ok") & np.isfinite(numbers["step_x_mm"])
                & np.isfinite(numbers["turn_deg"])).to_numpy()
        # a cell that is no number (a TypeError from NumPy had come through), or a kept gait's
        # number that is not finite, named by its column and gait (the constructor's refusal
        # names neither)
        for column in read:
            text = (numbers[column].isna() & table[column].notna()).to_numpy()
            lost = ~np.isfinite(numbers[column].to_numpy()) & kept
            for wrong, what in ((text, "not a number"), (lost, "not a finite number (status ok)")):
                if wrong.any():
                    row = table[wrong].iloc[0]
                    value = row[column]
                    quoted = repr(value) if isinstance(value, str) else value  # a text quoted
                    raise ValueError(f"table: {column} of gait {row['gait']} is {quoted}, "
                                     f"{what}")
        usable = numbers[kept]
        model = cls(list(table["gait"][kept]), usable[["step_x_mm", "step_y_mm"]].to_numpy(),
                    usable["turn_deg"].to_numpy(),
                    np.stack([usable[list(glide_columns(k))].to_numpy()
                              for k in range(1, streaks + 1)]) if streaks else None,
                    np.stack([usable[list(streak_step_columns(k))].to_numpy()
                              for k in range(1, stepped + 1)]) if stepped else None,
                    _glide_cycles(table[kept]) if streaks else None)
        # left out, as the docstring says, but not without a word (audits, 2026-12: the ok
        # gaits without a step, then the failed ones), once the table is known to be usable
        failed = (table["status"] != "ok").to_numpy()
        if failed.any():
            statuses = sorted(set(map(str, table["status"][failed])))
            warn_user(f"the primitive table's gaits {_some_gaits(table['gait'][failed])} "
                      f"({failed.sum()} of status {', '.join(statuses)}) failed their "
                      f"measurement: left out of the model")
        dropped = ((table["status"] == "ok").to_numpy() & ~kept)
        if dropped.any():
            warn_user(f"the primitive table's gaits {_some_gaits(table['gait'][dropped])} "
                      f"({dropped.sum()} of status ok) have no finite step_x_mm or turn_deg (a "
                      f"measurement too short for a steady step): left out of the model")
        if not streaks and expect_glides:
            # measure_primitives' default measures none: a plan from such a table put the
            # robot on its goals when it stopped firing and it glided on, missing every goal
            # by ~25 mm without a word (an audit, 2026-12); warned of once the table is known
            # to be one the planner can use
            warn_user(f"the primitive table has no glides from one firing "
                      f"({', '.join(glide_columns(1))}; they are read from one up): plans "
                      f"from it ignore the glide after the last firing and overshoot their "
                      f"goals; measure them (measure_primitives(..., glide_cycles="
                      f"{GLIDE_CYCLES}), the primitives study's --glide-cycles) or pass "
                      f"expect_glides=False to plan without them")
        return model

    def check_settle(self, settle_cycles: int):
        """A RuntimeWarning when `drive` would judge its robots `settle_cycles` after their
        controllers stop while the table's glides span another number of coasting cycles: a
        coasting robot still moves (A1+A3 about 3 mm in its fifth cycle), so the judge and the
        model's rest would be at different times (an audit, 2026-12: judged at 12 cycles
        instead of 4, the same plans missed goals they reach)."""
        if self.glide_cycles is not None and settle_cycles != self.glide_cycles:
            warn_user(f"settle_cycles = {settle_cycles} judges the robots {settle_cycles} "
                      f"cycles after their controllers stop, while the table's glides span "
                      f"{self.glide_cycles}: a coasting robot still moves, so the robots are "
                      f"judged off the model's rest; give settle_cycles={self.glide_cycles}")

    def step(self, gait: np.ndarray, streak: Optional[np.ndarray] = None) -> np.ndarray:
        """(..., 2) body-frame steps (mm) of gait indices `gait` (...) fired as the streak-th
        cycle in a row (...; None, or beyond the streaks measured: the steady step)."""
        if streak is None:
            return self.steps_mm[gait]
        fired = np.clip(np.asarray(streak), 1, len(self.streak_steps_mm)) - 1
        return self.streak_steps_mm[fired, gait]

    def predict(self, position_mm: np.ndarray, heading_rad: np.ndarray, choice: np.ndarray,
                streak: Optional[np.ndarray] = None):
        """The model's (position (B, 2) mm, heading (B,) rad) after one cycle of gait index
        `choice` (B,) from position (B, 2) and heading (B,), that cycle being the streak-th
        (B,; None: steady) in a row of that gait (`step`)."""
        return (position_mm + rotate(self.step(choice, streak), heading_rad),
                heading_rad + self.turns_rad[choice])

    def next_streak(self, last, streak, choice):
        """How many cycles in a row of momentum gait index `choice` will have built after
        firing it, having fired gait index `last` in each of the `streak` cycles before
        (arrays broadcast): 0 for "none" (index 0); streak + 1 for the same gait or for one
        whose steady step points within ALIGNED_DEG of the last's, that angle included
        (`ALIGNED_SLACK`; the robot keeps the
        momentum it built the same way); 1 otherwise (it starts again as from rest)."""
        choice, last = np.asarray(choice), np.asarray(last)
        before, after = self.steps_mm[last], self.steps_mm[choice]
        dot = (before * after).sum(axis=-1)
        bound = math.cos(math.radians(ALIGNED_DEG)) * (1.0 - ALIGNED_SLACK)
        # a step of zero points nowhere: aligned with nothing (dot > 0)
        aligned = (dot > 0.0) & (dot >= bound * np.hypot(*np.moveaxis(before, -1, 0))
                                 * np.hypot(*np.moveaxis(after, -1, 0)))
        carries = (choice == last) | ((last != 0) & aligned)
        return np.where(choice == 0, 0, np.where(carries, np.asarray(streak) + 1, 1))

    def glide(self, gait: np.ndarray, streak: np.ndarray) -> np.ndarray:
        """(..., 2) body-frame glides (mm) after firing gait indices `gait` (...) `streak`
        (...) cycles in a row (below 1 counts as 1, above K as K; "none" does not glide)."""
        fired = np.clip(np.asarray(streak), 1, len(self.glides_mm)) - 1
        return self.glides_mm[fired, gait]

    def rest(self, position_mm: np.ndarray, heading_rad: np.ndarray, last: np.ndarray,
             streak: Optional[np.ndarray] = None):
        """Where robots at position (B, 2) mm with heading (B,) rad come to rest (mm) if they
        stop firing now, having fired gait index `last` (B,) in each of the `streak` (B,;
        None: 1) cycles before."""
        streak = np.ones(len(last), dtype=np.int64) if streak is None else streak
        return position_mm + rotate(self.glide(last, streak), heading_rad)

    def choose(self, position_mm: np.ndarray, heading_rad: np.ndarray, goal_mm: np.ndarray,
               tolerance_mm: float, last: Optional[np.ndarray] = None,
               streak: Optional[np.ndarray] = None) -> np.ndarray:
        """(B,) gait indices (0 = "none") for robots at position (B, 2) mm with heading (B,)
        rad and goals (B, 2) mm, having fired gait index `last` (B,) in each of the `streak`
        (B,) cycles before (None: nothing, resp. 1); see the module docstring. ValueError
        naming the argument for shapes, values or indices it cannot plan with."""
        position_mm = _finite_rows(position_mm, "position_mm")
        count = len(position_mm)
        heading_rad = _finite_rows(heading_rad, "heading_rad", count, ())
        goal_mm = _checked_goals(goal_mm, "goal_mm", count)
        check_finite("tolerance_mm", tolerance_mm, 0, unit=" mm")
        last = np.zeros(count, dtype=np.int64) if last is None else self._indices(last, count)
        streak = (np.ones(count, dtype=np.int64) if streak is None
                  else _counts(streak, "streak", count))
        choice = np.zeros(len(position_mm), dtype=np.int64)
        stop_rest = self.rest(position_mm, heading_rad, last, streak)
        gaits = np.arange(len(self.gaits))
        for b in range(len(position_mm)):
            to_goal = goal_mm[b] - position_mm[b]
            if math.hypot(*(goal_mm[b] - stop_rest[b])) <= tolerance_mm:
                continue
            # rest positions relative to now: after one cycle of gait g, (G, 2); after g then h,
            # (G, G, 2); "none" first means stopping now
            turned = heading_rad[b] + self.turns_rad
            streak_first = self.next_streak(last[b], streak[b], gaits)  # (G,)
            first = rotate(self.step(gaits, streak_first), heading_rad[b])
            rest_first = first + rotate(self.glide(gaits, streak_first), turned)
            rest_first[0] = stop_rest[b] - position_mm[b]
            after_first = np.hypot(*(to_goal - rest_first).T)
            if after_first.min() <= tolerance_mm:
                choice[b] = int(np.argmin(after_first))
                continue
            streak_second = self.next_streak(gaits[:, None], streak_first[:, None],
                                             gaits[None])
            second = rotate(self.step(gaits[None], streak_second), turned[:, None])
            glide = rotate(self.glide(gaits[None], streak_second),
                           turned[:, None] + self.turns_rad[None])
            rest_second = first[:, None, :] + second + glide
            rest_second[:, 0] = rest_first
            rest_second[0, :] = rest_first[0]
            after_second = np.hypot(*np.moveaxis(to_goal - rest_second, -1, 0))
            choice[b] = int(np.unravel_index(np.argmin(after_second), after_second.shape)[0])
        return choice

    def plan(self, goal_mm: np.ndarray, tolerance_mm: float, max_cycles: int) -> np.ndarray:
        """Open-loop plans from the start (origin, heading 0, at rest): (B, max_cycles) gait
        indices, 0 once the model says the robot will come to rest within the tolerance.
        ValueError naming the argument for goals that are not a finite (B, 2) array within
        MAX_GOAL_MM, a tolerance not > 0 or max_cycles not an integer >= 1 (a NaN goal planned
        "stop", a (2,) goal two goals; an audit, 2026-12)."""
        goal_mm = _checked_goals(goal_mm, "goal_mm")
        check_finite("tolerance_mm", tolerance_mm, 0, unit=" mm")
        if not is_whole(max_cycles) or max_cycles < 1:
            raise ValueError(f"max_cycles must be an integer >= 1, got {max_cycles!r}")
        max_cycles = int(max_cycles)
        count = len(goal_mm)
        position, heading = np.zeros((count, 2)), np.zeros(count)
        plans = np.zeros((count, max_cycles), dtype=np.int64)
        last = np.zeros(count, dtype=np.int64)
        streak = np.zeros(count, dtype=np.int64)
        done = np.zeros(count, dtype=bool)
        for cycle in range(max_cycles):
            choice = np.where(done, 0, self.choose(position, heading, goal_mm, tolerance_mm,
                                                   last, streak))
            done |= choice == 0  # a plan that stops firing lets the robot come to rest
            plans[:, cycle] = choice
            streak = self.next_streak(last, streak, choice)
            position, heading = self.predict(position, heading, choice, streak)
            last = choice
        return plans


    def _indices(self, last, count: int) -> np.ndarray:
        """`last` as (count,) gait indices of this model; ValueError naming it otherwise (-1
        read the last gait, 999 an IndexError)."""
        indices = _counts(last, "last", count)
        if (indices >= len(self.gaits)).any():
            raise ValueError(f"last must hold gait indices in [0, {len(self.gaits) - 1}] (0 = "
                             f"{NO_GAIT!r}), got {int(indices.max())}")
        return indices


def _some_gaits(gaits) -> str:
    """The first five of some gaits, comma-separated, "..." after them if there are more."""
    names = [str(gait) for gait in gaits]
    return ", ".join(names[:5]) + (" ..." if len(names) > 5 else "")


def _glide_cycles(table: pd.DataFrame) -> Optional[int]:
    """The coasting cycles a primitive table's glides span (its glide_cycles column), where
    it has one value for every gait; None otherwise."""
    if "glide_cycles" not in table.columns:
        return None
    values = pd.to_numeric(table["glide_cycles"], errors="coerce").dropna().unique()
    return int(values[0]) if len(values) == 1 and values[0] >= 1 and values[0] % 1 == 0 \
        else None


def _finite_rows(values, name: str, count: Optional[int] = None, row=(2,)) -> np.ndarray:
    """`values` as a finite float array of shape (count, *row) (any count when None);
    ValueError naming `name` otherwise."""
    try:
        array = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):  # texts, ragged rows
        array = np.empty(0)
    shape = "(" + ", ".join(map(str, ("B" if count is None else count, *row))) + ")"
    if array.ndim != 1 + len(row) or array.shape[1:] != tuple(row) or not len(array) \
            or (count is not None and len(array) != count) or not np.isfinite(array).all():
        raise ValueError(f"{name} must be a finite array of shape {shape}, got "
                         f"{values!r}")
    return array


def _checked_goals(goals, name: str, count: Optional[int] = None) -> np.ndarray:
    """`_finite_rows` of (B, 2) goals (mm) within MAX_GOAL_MM of the start (a rounding over
    it within)."""
    goals = _finite_rows(goals, name, count)
    if (np.hypot(goals[:, 0], goals[:, 1]) > MAX_GOAL_MM * (1 + 1e-12)).any():
        raise ValueError(f"{name} must be within {MAX_GOAL_MM:g} mm (metrics.MAX_GOAL_MM) of "
                         f"the start, got {goals.tolist()!r}")
    return goals


def _counts(values, name: str, count: int) -> np.ndarray:
    """`values` as (count,) integers >= 0; ValueError naming `name` otherwise."""
    array = np.asarray(values)
    if array.shape != (count,) or array.dtype.kind not in "iu" or (array < 0).any():
        raise ValueError(f"{name} must be ({count},) integers >= 0, got {values!r}")
    return array.astype(np.int64)


MAX_DEFAULT_GOALS = 360
"""The most goals `default_goals` sets around the robot: one per degree (10**10 asked for
160 GB)."""


def default_goals(distance_mm: float = 50.0, count: int = 8,
                  far_mm: Optional[float] = 150.0) -> np.ndarray:
    """(count [+1], 2) goals, mm: `count` at distance_mm in directions 0, 360/count, ... deg,
    then one far_mm straight behind the robot (-x), unless far_mm is None. ValueError naming
    count unless it is an integer from 0 (1 without far_mm: some goal) to `MAX_DEFAULT_GOALS`,
    distance_mm unless a number in (0, MAX_GOAL_MM] mm, far_mm unless None or one."""
    lowest = 1 if far_mm is None else 0
    if not is_whole(count) or not lowest <= count <= MAX_DEFAULT_GOALS:
        rule = ("far_mm is None: no goal otherwise" if far_mm is None
                else ">= 1 when far_mm is None")
        raise ValueError(f"count must be an integer from {lowest} to {MAX_DEFAULT_GOALS} "
                         f"(MAX_DEFAULT_GOALS; {rule}), got {count!r}")
    for name, value in (("distance_mm", distance_mm), ("far_mm", far_mm)):
        if name == "far_mm" and value is None:
            continue
        if not (is_finite_real(value) and 0 < value <= MAX_GOAL_MM):
            raise ValueError(f"{name} must be a number in (0, {MAX_GOAL_MM:g}] mm"
                             f"{' or None' if name == 'far_mm' else ''}, got {shown(value)}")
    angles = np.radians(np.arange(count) * 360.0 / count)
    goals = distance_mm * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    return goals if far_mm is None else np.vstack([goals, [[-far_mm, 0.0]]])


SETTLE_CYCLES = 4
"""Cycles without firing after the last controller stops, for the robots to come to rest (they
glide for several cycles after their last firing; the primitives' glide is measured over as
many, `primitives.GLIDE_CYCLES`)."""


PATH_FRAMES = 10
"""Path records per cycle where the cycle's steps allow (`path_frames`)."""


def path_frames(period: float, dt: float) -> int:
    """Path records per cycle: the most, up to PATH_FRAMES, that split the cycle into whole
    steps (3.15 s at 2 ms, 1,575 steps, was refused for 10 frames, naming the library's
    frames_per_cycle: an audit, 2026-12; it takes 9); PATH_FRAMES where the period is not
    whole steps (`check_drive` refuses that, naming the period). What the control studies
    record (plan, rl)."""
    steps = whole_steps(period, dt)
    if steps is None:
        return PATH_FRAMES
    return next(frames for frames in range(PATH_FRAMES, 0, -1) if steps % frames == 0)


def check_drive(goals_mm, params: StarParams, solver: SolverConfig, tolerance_mm: float = 5.0,
                max_cycles: int = 25, frames_per_cycle: int = 10,
                settle_cycles: int = SETTLE_CYCLES) -> np.ndarray:
    """The goals as a (G, 2) float array, or ValueError naming the argument unless `drive`
    can run with these: finite goals, max_cycles an integer >= 1, settle_cycles an integer
    >= 0, tolerance_mm > 0 and below every goal's distance, frames_per_cycle an integer >= 1,
    the period and period / frames_per_cycle whole numbers of steps, and max_cycles +
    settle_cycles periods within the step counter (`timegrid.check_work`).
    No compute: a command line checks its input with this before starting."""
    # a rounding over the bound is within it: default_goals(1000, 5) puts one 1.1e-13 mm past;
    # a goal at 1e308 mm ran every plan, then its plot failed on a NaN (an audit)
    goals = _checked_goals(goals_mm, "goals_mm")
    if not isinstance(params, StarParams):
        raise ValueError(f"params must be a StarParams, got {type(params).__name__}")
    if not isinstance(solver, SolverConfig):
        raise ValueError(f"solver must be a SolverConfig, got {type(solver).__name__}")
    if not is_whole(max_cycles) or max_cycles < 1:
        raise ValueError(f"max_cycles must be an integer >= 1, got {max_cycles!r}")
    if not is_whole(settle_cycles) or settle_cycles < 0:
        raise ValueError(f"settle_cycles must be an integer >= 0, got {settle_cycles!r}")
    check_finite("tolerance_mm", tolerance_mm, 0, unit=" mm")
    distances = np.hypot(goals[:, 0], goals[:, 1])
    if (distances <= tolerance_mm).any():
        # reached before the robot moves: a plan of nothing, counted as a success
        near = int(np.flatnonzero(distances <= tolerance_mm)[0])
        raise ValueError(f"tolerance_mm = {tolerance_mm:g} mm reaches goal {near} "
                         f"({distances[near]:g} mm from the start) before the robot moves: "
                         f"give goals farther than the tolerance")
    if not is_whole(frames_per_cycle) or frames_per_cycle < 1:
        raise ValueError(f"frames_per_cycle must be an integer >= 1, got {frames_per_cycle!r}")
    period = params.period
    # the whole run, every controller to max_cycles and the coast after: refused (with its
    # estimate) before the plans, (G, max_cycles) per mode, or the Simulator are made
    step, step_name = (solver.dt_max, "dt_max") if solver.adaptive else (solver.dt, "dt")
    check_work(f"max_cycles + settle_cycles = {max_cycles + settle_cycles} cycles of "
               f"{period:g} s at {step_name} = {step:g} s",
               (max_cycles + settle_cycles) * period / step, len(goals) * len(MODES),
               nodes=params.n_nodes)
    if whole_steps(period, solver.dt) is None or \
            whole_steps(period / frames_per_cycle, solver.dt) is None:
        raise ValueError(f"period / frames_per_cycle must be a whole number of steps (dt = "
                         f"{solver.dt} s), got period {period!r} and {frames_per_cycle!r} frames")
    return goals


def drive(model: PrimitiveModel, goals_mm, params: StarParams = StarParams(),
          solver: SolverConfig = SolverConfig(), tolerance_mm: float = 5.0,
          max_cycles: int = 25, frames_per_cycle: int = 10, arch: str = "cpu",
          progress: bool = False, settle_cycles: int = SETTLE_CYCLES):
    """Drive one robot per (goal, mode) in one Simulator, a gait per actuation cycle of
    `params.period`, until every controller has stopped or max_cycles have run, then let the
    robots coast `settle_cycles` cycles to rest; a goal is reached if the robot comes to rest
    (settle_cycles after its own controller stopped) within tolerance_mm of it.

    goals_mm: (G, 2) goal points relative to the start (the robot starts at rest, heading 0).
    Returns (summary, cycles, path): `PLAN_COLUMNS`, `CYCLE_COLUMNS` and the centroid path
    (goal, mode, t_s, controlled (False once the controller has stopped), x_mm, y_mm)
    recorded frames_per_cycle times per cycle. ValueError for
    bad arguments (`check_drive`)."""
    if not isinstance(model, PrimitiveModel):
        raise ValueError(f"model must be a PrimitiveModel (PrimitiveModel.from_table), got "
                         f"{type(model).__name__}")
    goals = check_drive(goals_mm, params, solver, tolerance_mm, max_cycles, frames_per_cycle,
                        settle_cycles)
    check_flag("progress", progress)
    model.check_settle(settle_cycles)
    check_arch(arch)
    period = params.period
    goal_index = np.repeat(np.arange(len(goals)), len(MODES))
    modes = np.tile(MODES, len(goals))
    closed = modes == "closed"
    target = goals[goal_index]
    plans = model.plan(target, tolerance_mm, max_cycles)
    open_predicted = np.zeros((len(target), 2))
    open_heading = np.zeros(len(target))

    simulator = Simulator([params.replace(gait=NO_GAIT)] * len(target), solver, arch=arch)
    stopped = np.zeros(len(target), dtype=bool)
    stop_cycle = np.full(len(target), max_cycles)
    final_error = np.full(len(target), np.nan)
    fired = np.zeros(len(target), dtype=np.int64)
    last = np.zeros(len(target), dtype=np.int64)
    streak = np.zeros(len(target), dtype=np.int64)
    predicted = np.zeros((len(target), 2))
    cycle_rows, paths = [], []
    boundaries = []  # (B, 2) centroid positions (mm) at every cycle boundary
    for cycle in range(max_cycles + 1):
        state = simulator.state()
        position = state[["centroid_x_mm", "centroid_y_mm"]].to_numpy()
        boundaries.append(position)
        heading = np.radians(state["heading_deg"].to_numpy())
        distance = np.hypot(*(target - position).T)
        if cycle == max_cycles:
            choice = np.zeros(len(target), dtype=np.int64)
        else:
            choice = np.where(closed, model.choose(position, heading, target, tolerance_mm,
                                                   last, streak), plans[:, cycle])
        # a controller stops when it chooses nothing (closed loop: within the tolerance; open
        # loop: its plan is done) or the budget is spent; its error is taken then
        stopping = ~stopped & ((choice == 0) | (cycle == max_cycles) | ~simulator.ok)
        final_error[stopping] = distance[stopping]
        stop_cycle[stopping] = cycle
        stopped |= stopping
        choice[stopped] = 0
        cycle_rows.append(pd.DataFrame({
            "goal": goal_index, "mode": modes, "cycle": cycle,
            "gait": np.asarray(model.gaits)[choice], "x_mm": position[:, 0],
            "y_mm": position[:, 1], "heading_deg": np.degrees(heading),
            "distance_mm": distance, "predicted_x_mm": predicted[:, 0],
            "predicted_y_mm": predicted[:, 1]}))
        if stopped.all():
            break
        fired += choice != 0
        last, streak = choice, model.next_streak(last, streak, choice)
        closed_next, _ = model.predict(position, heading, choice, streak)
        open_predicted, open_heading = model.predict(open_predicted, open_heading, choice,
                                                     streak)
        predicted = np.where(closed[:, None], closed_next, open_predicted)
        simulator.fire(model.masks[choice])
        frames = simulator.advance(period, record_interval_s=period / frames_per_cycle,
                                   progress=progress)
        paths.append(frames[["instance", "t_s", "centroid_x_mm", "centroid_y_mm"]])
    for _ in range(settle_cycles):  # the robots glide on to rest, no controller firing
        frames = simulator.advance(period, record_interval_s=period / frames_per_cycle,
                                   progress=progress)
        paths.append(frames[["instance", "t_s", "centroid_x_mm", "centroid_y_mm"]])
        state = simulator.state()
        boundaries.append(state[["centroid_x_mm", "centroid_y_mm"]].to_numpy())
    summary = judged_at_rest(target, goal_index, modes, boundaries, stop_cycle, settle_cycles,
                             state["status"].to_numpy(), tolerance_mm, fired, final_error)
    start = pd.DataFrame({"instance": np.arange(len(target)), "t_s": 0.0, "centroid_x_mm": 0.0,
                          "centroid_y_mm": 0.0})
    path = pd.concat([start, *paths], ignore_index=True)
    instance = path["instance"].to_numpy(dtype=int)
    times = path["t_s"].to_numpy(dtype=float)
    path = pd.DataFrame({"goal": goal_index[instance], "mode": modes[instance], "t_s": times,
                         "controlled": times <= stop_cycle[instance] * period + solver.dt / 2,
                         "x_mm": path["centroid_x_mm"].to_numpy(dtype=float),
                         "y_mm": path["centroid_y_mm"].to_numpy(dtype=float)})
    path = path.sort_values(["goal", "mode", "t_s"], kind="stable").reset_index(drop=True)
    return summary, pd.concat(cycle_rows, ignore_index=True)[CYCLE_COLUMNS], path


def judged_at_rest(goals: np.ndarray, goal, mode, boundaries: Sequence[np.ndarray],
                   stop_cycle: np.ndarray, settle_cycles: int, status: np.ndarray,
                   tolerance_mm: float, fired: np.ndarray, final_error: np.ndarray
                   ) -> pd.DataFrame:
    """`PLAN_COLUMNS`, one row per driven robot, as every controller here is judged (`drive`,
    `lookahead.lookahead_drive`, `envs.drive_policy`): each robot where it is settle_cycles
    periods after its own controller stopped (stop_cycle), the horizon of the measured glides
    (a robot under quadratic drag slows down as 1/t and never quite stops), reached within
    tolerance_mm of its goal with its instance ok.

    goals: (R, 2) mm, one per robot; goal, mode: each robot's goal number and controller (R,)
    or one for all; boundaries: the robots' (R, 2) positions, mm, at every period boundary
    from the start; status (R,); fired: periods each fired (R,); final_error: mm from the goal
    when its controller stopped (R,)."""
    run_cycles = stop_cycle + settle_cycles
    rest = np.stack(boundaries)[run_cycles, np.arange(len(goals))]
    end_error = np.hypot(*(goals - rest).T)
    reached = (end_error <= tolerance_mm) & (status == "ok")
    return pd.DataFrame({
        "goal": goal, "goal_x_mm": goals[:, 0], "goal_y_mm": goals[:, 1],
        "goal_distance_mm": np.hypot(*goals.T), "mode": mode,
        "reached": reached, "cycles_to_goal": np.where(reached, stop_cycle, np.nan),
        "cycles_fired": fired, "final_error_mm": final_error, "end_error_mm": end_error,
        "run_cycles": run_cycles, "status": status})[PLAN_COLUMNS]


def closed_loop_gain(summary: pd.DataFrame) -> dict:
    """Open against closed loop over a `drive` summary: goals reached, mean and largest final
    error (mm), mean error at the end of the run (mm), mean cycles to the goal over the goals
    both reached."""
    needed = ("goal", "mode", "reached", "final_error_mm", "end_error_mm", "cycles_to_goal")
    if not isinstance(summary, pd.DataFrame) or not set(needed) <= set(summary.columns):
        raise ValueError(f"summary must be drive's summary (a DataFrame with columns "
                         f"{', '.join(needed)}), got {type(summary).__name__}")
    result = {}
    for mode in MODES:
        part = summary[summary["mode"] == mode]
        result[f"{mode}_reached"] = int(part["reached"].sum())
        result[f"{mode}_mean_error_mm"] = float(part["final_error_mm"].mean())
        result[f"{mode}_max_error_mm"] = float(part["final_error_mm"].max())
        result[f"{mode}_mean_end_error_mm"] = float(part["end_error_mm"].mean())
    both = summary.groupby("goal")["reached"].transform("all")
    cycles = summary[both].groupby("mode")["cycles_to_goal"].mean()
    for mode in MODES:
        result[f"{mode}_mean_cycles_both_reached"] = float(cycles.get(mode, math.nan))
    result["goals"] = int(summary["goal"].nunique())
    return result
