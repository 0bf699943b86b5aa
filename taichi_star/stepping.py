"""Adaptive step-size control: where an instance's next step ends, whether a converged step
is kept, and the size of the step after it from the local error estimate
(`integrators.Integrator.local_error`). The engine's `adaptive_instance` applies them to each
instance; they read nothing but their arguments (times and sizes in s, errors and tolerance in
m)."""

import taichi as ti


@ti.func
def step_end(start, proposed, target, firing, firing_step, slack):
    """The end of a step of the `proposed` size from `start` towards `target` (the next stop,
    or with `firing` = 1 the next firing): exactly on it when the step would pass it, and
    never a sliver under a quarter step before it (the rest is split in two instead), so that
    a rejected step always shrinks. A firing makes the forcing jump within the step that ends
    on it: that step is at most `firing_step` long (dt, as a run's first step), so the steps
    before it end firing_step short of it (or halfway there). `slack` (s; where steps are
    held, the larger of `HELD_STEP_SLACK` of dt_min and the time's `roundings`, else 0) is how
    far these comparisons look past the times' rounding: a step that ends within it of its
    limit ends on it."""
    limit = target
    if firing == 1 and target - start > firing_step + slack:
        limit = ti.max(target - firing_step, start + 0.5 * (target - start))
    end = start + proposed
    if end >= limit - slack:
        end = limit
    elif limit - end < 0.25 * proposed:
        end = start + 0.5 * (limit - start)
    return end


HELD_STEP_SLACK = 1e-6
"""`step_end`'s slack as a share of dt_min where steps are held (dt_min = dt_max): every step is
then dt long, and a stop or firing on the dt grid lies a few roundings of the time away from
where the steps' sum lands, which split the last step before it into halves below dt_min (an
audit: 0.399 to 0.4 s, and past 1 s the approach to every stop; 2,020 steps for 2,000). The
times' roundings grow with the sum (1,000 steps at 2 s: ~4e-13 s); 1e-6 of the step is far
beyond them and changes a step's length by a share the motion does not see."""

SLIVER_ROUNDINGS = 64
"""A step that lands on a stop within this many roundings of the time (relative to
max(|t|, 1 s)) after its start is a sliver (`is_sliver`): stops that should coincide but were
reached by different sums (6 × 0.05 = 0.30000000000000004 against a cycle start at 0.3) lie a
few roundings apart; 64 allows for sums of many terms (1.4e-14 s in f64 below 1 s)..."""
SLIVER_LEAST_OF_DT_MIN = 1e-4
"""... and at least this share of dt_min (1e-10 s at the default 1e-6 s): a stop reached by a
longer sum (a controller that adds its steps up to a firing time: 1,000 additions of 1 ms put
it ~1e-13 s off a record) lies further than 64 roundings away, and the solved step of 2e-14 s
left a velocity 1.5 % off 5 ms later (an audit). Crossing 1e-10 s by the clock alone leaves
the positions ~1e-11 m short at 0.1 m/s, a tenth of Newton's default tolerance, where solving
it costs ~3e-5 of the velocities to rounding..."""
SLIVER_MOST_OF_DT_MIN = 0.5
"""... but never more than this share of dt_min: in f32, 64 roundings are 7.6e-6 s below 1 s
and 1.1e-3 s at 140 s, longer than the steps that the controller takes (dt_min 1e-6 s) or that
records every 5e-6 s ask for, and such runs, taking every step for a sliver, stood still while
reporting ok (an audit, before this bound)."""


@ti.func
def roundings(limit, t):
    """`limit` (a count of roundings times the precision's epsilon) as seconds at time t (s):
    relative to max(|t|, 1 s)."""
    return limit * ti.max(ti.abs(t), 1.0)


@ti.func
def is_sliver(start, end, target, limit, least, most):
    """Whether the step from start to end (s) is a rounding's sliver: it lands on its target
    (a stop) at most min(max(limit · max(|end|, 1 s), least), most) after start (limit:
    `SLIVER_ROUNDINGS` roundings of the precision; least and most: `SLIVER_LEAST_OF_DT_MIN` and
    `SLIVER_MOST_OF_DT_MIN` of dt_min, s). Solved, such a step divides the positions' rounding
    by h: a 5.6e-17-s step after a firing set the centroid's velocity from −5.2 to −2.7 mm/s
    (3.5 % off the displacement 0.05 s later), so the clock crosses it alone."""
    return end == target and end - start <= ti.min(ti.max(roundings(limit, end), least), most)


@ti.func
def at_smallest(h, proposed, dt_min):
    """Whether a step cannot shrink further: its size as set (`proposed`, which a rejection
    clamps at dt_min) or as taken (h = end − start, shorter when cut to land on a stop) is at
    most dt_min. The size as set decides where rounding puts the size as taken a hair above
    it: (0.2 + 1e-6) − 0.2 = 1.000000000001e-06, and a step redone at that size was redone
    forever."""
    return ti.min(h, proposed) <= dt_min


@ti.func
def accepts(error, tol, h, proposed, dt_min):
    """Whether a converged step of size h (s) with local error estimate `error` (m) is kept:
    when the error is within tol, or when the step cannot shrink further (`at_smallest`: its
    error is kept rather than the step redone at the same size forever)."""
    return error <= tol or at_smallest(h, proposed, dt_min)


@ti.func
def size_factor(tol, error):
    """0.9·√(tol/error), at least 0.2: the factor on a step's size that brings its error
    (∝ h² for the first-order estimate) to 0.81 of the tolerance."""
    return ti.max(0.2, 0.9 * ti.sqrt(tol / error))


@ti.func
def accepted_size(h, proposed, error, tol, firing, dt_min, dt_max):
    """The size of the step after an accepted one of size h (proposed: the size it had before
    it was cut to land on a stop; `firing`: 1 if it ended on a firing): grown or shrunk by
    `size_factor` within [0.2, 2] and [dt_min, dt_max]."""
    growth = 2.0
    if error > 0.0:
        growth = ti.min(2.0, size_factor(tol, error))
    # a step cut short to land on a stop says little about the size that fits, unless the
    # forcing jumped at its end (a firing)
    basis = h
    if h < proposed and growth >= 1.0 and firing == 0:
        basis = proposed
    return ti.min(dt_max, ti.max(dt_min, basis * growth))


@ti.func
def rejected_size(h, error, tol, dt_min):
    """The size of the retry of a converged step of size h rejected for its error (> tol):
    shrunk by `size_factor`, at least dt_min."""
    return ti.max(dt_min, h * size_factor(tol, error))
