"""The actuators' curvature profile (taichi_star.actuation.CurvatureProfile) on the host: the
paper's Eq. 5 written out from its published constants, the switch between its branches, the
closures of a cycle, its validation and its text."""

import math
import sys

import numpy as np
import pytest

from taichi_star.actuation import SWITCH_SNAP, CurvatureProfile, snapped_to_switch

PERIOD = 3.15  # s, the paper's cycle


def test_the_default_profile_is_eq_5_with_the_papers_constants():
    """K̄(τ) = c1/(1 + exp(−c2(τ − c3))) + c4: the heating constants (−89.827, 62.724, 0.061,
    104.040) before t0 = 0.163 s, the cooling ones (94.777, 2.507, 1.019, 4.445) from it on;
    a scalar τ gives a float, an array an array."""
    profile = CurvatureProfile()
    heating_at_0 = -89.827 / (1.0 + math.exp(-62.724 * (0.0 - 0.061))) + 104.040
    heating_at_01 = -89.827 / (1.0 + math.exp(-62.724 * (0.1 - 0.061))) + 104.040
    cooling_at_1 = 94.777 / (1.0 + math.exp(-2.507 * (1.0 - 1.019))) + 4.445
    # 1e-14 relative: one exp and three roundings in either evaluation
    assert profile.curvature(0.0) == pytest.approx(heating_at_0, rel=1e-14)
    assert type(profile.curvature(0.0)) is float
    assert profile.rest_curvature == pytest.approx(heating_at_0, rel=1e-14)
    np.testing.assert_allclose(profile.curvature(np.array([0.1, 1.0])),
                               [heating_at_01, cooling_at_1], rtol=1e-14)
    assert profile.as_array().tolist() == [-89.827, 62.724, 0.061, 104.040,
                                           94.777, 2.507, 1.019, 4.445, 0.163]


def test_the_switch_time_belongs_to_the_cooling_branch():
    """τ < t0 heats, τ = t0 already cools: at t0 the cooling formula, one ulp before it the
    heating one; the branches miss each other there by `switch_jump`."""
    profile = CurvatureProfile()
    t0 = profile.switch_time
    cooling = 94.777 / (1.0 + math.exp(-2.507 * (t0 - 1.019))) + 4.445
    heating = -89.827 / (1.0 + math.exp(-62.724 * (t0 - 0.061))) + 104.040
    # 1e-14: as above; the branches differ by 6.4e-3 1/m, 1e11 times more than that
    assert profile.curvature(t0) == pytest.approx(cooling, rel=1e-14)
    assert profile.curvature(np.nextafter(t0, 0.0)) == pytest.approx(heating, rel=1e-14)
    assert profile.switch_jump == pytest.approx(cooling - heating, rel=1e-9)
    assert abs(cooling - heating) > 1e-3


def _last_within(t0, window, direction):
    """The float furthest from t0 towards `direction` whose computed |τ − t0| is ≤ window."""
    tau = t0 + direction * window
    while abs(tau - t0) > window:
        tau = np.nextafter(tau, t0)
    while abs(np.nextafter(tau, direction * np.inf) - t0) <= window:
        tau = np.nextafter(tau, direction * np.inf)
    return float(tau)


@pytest.mark.parametrize("time_s, window", [(0.5, SWITCH_SNAP), (-1.0, SWITCH_SNAP),
                                             (40.0, 40.0 * SWITCH_SNAP)])
def test_a_time_since_firing_within_the_snap_of_the_switch_is_the_switch(time_s, window):
    """|τ − t0| ≤ SWITCH_SNAP·max(|t|, 1 s) is t0, on either side: the last float within the
    window snaps (≤, not <), the next one out is τ unchanged. Below |t| = 1 s the window is
    that of 1 s, above it grows with |t| (a step's τ is a difference of times of size t)."""
    t0 = CurvatureProfile().switch_time
    for direction in (-1.0, 1.0):
        edge = _last_within(t0, window, direction)
        assert edge != t0
        assert snapped_to_switch(edge, t0, time_s) == t0
        outside = float(np.nextafter(edge, direction * np.inf))
        assert snapped_to_switch(outside, t0, time_s) == outside
    assert snapped_to_switch(0.1, t0, time_s) == 0.1


def test_a_time_since_firing_exactly_the_window_from_the_switch_is_the_switch():
    """The bound itself: a τ whose distance d from t0 is exactly SWITCH_SNAP·t at the time t
    = d/SWITCH_SNAP snaps (≤), and the same τ at the float just before that t (a window one
    rounding narrower) does not. τ is searched from t0 + 1e-12 outwards for such a d."""
    t0 = CurvatureProfile().switch_time
    tau = _last_within(t0, SWITCH_SNAP, 1.0)
    while True:
        tau = float(np.nextafter(tau, np.inf))
        time_s = (tau - t0) / SWITCH_SNAP
        if SWITCH_SNAP * time_s == tau - t0:
            break
    assert time_s > 1.0  # the window grows with the time here, not held at that of 1 s
    assert snapped_to_switch(tau, t0, time_s) == t0
    assert snapped_to_switch(tau, t0, float(np.nextafter(time_s, 0.0))) == tau


def test_the_ramp_closure_meets_the_next_cycles_start_and_the_jump_is_the_fit():
    """The "ramp" closure adds (K̄(0) − K̄(T))·τ/T: K̄(0) at τ = 0, and at τ = T K̄(T) + the
    gap = K̄(0), where the next cycle starts; "jump" is the fit itself, which steps by the gap
    there."""
    profile = CurvatureProfile()
    rest = profile.rest_curvature
    end = 94.777 / (1.0 + math.exp(-2.507 * (PERIOD - 1.019))) + 4.445
    # 1e-14 relative: as above
    assert profile.closure_gap(PERIOD) == pytest.approx(rest - end, rel=1e-14)
    assert profile.cycle_curvature(0.0, PERIOD, "ramp") == rest
    assert profile.cycle_curvature(PERIOD, PERIOD, "ramp") == pytest.approx(rest, rel=1e-14)
    taus = np.array([0.05, 1.0, 2.0])
    np.testing.assert_allclose(profile.cycle_curvature(taus, PERIOD, "ramp"),
                               profile.curvature(taus) + (rest - end) * taus / PERIOD, rtol=1e-14)
    np.testing.assert_array_equal(profile.cycle_curvature(taus, PERIOD, "jump"),
                                  profile.curvature(taus))
    assert profile.cycle_curvature(PERIOD, PERIOD, "jump") == pytest.approx(end, rel=1e-14)
    with pytest.raises(ValueError, match=r"^closure must be one of \['jump', 'ramp'\], got "
                                         r"'smooth'$"):
        profile.cycle_curvature(0.0, PERIOD, "smooth")


@pytest.mark.parametrize("changes, message", [
    (dict(heating=(1.0, 2.0, 3.0)), r"CurvatureProfile.heating must be 4 finite numbers, got "
                                    r"\(1.0, 2.0, 3.0\)"),
    (dict(cooling=(94.777, math.nan, 1.019, 4.445)), r"CurvatureProfile.cooling must be 4 finite"),
    (dict(switch_time=0.0), r"CurvatureProfile.switch_time must be a finite number > 0 s, got "
                            r"0.0$"),
    (dict(switch_time=math.inf), r"CurvatureProfile.switch_time must be a finite number > 0 s, "
                                 r"got inf$"),
    # c2 = 0: K̄ = c1/2 + c4 everywhere, here exactly 0 (an arc at rest must bend)
    (dict(heating=(-1.0, 0.0, 0.0, 0.5)), r"CurvatureProfile: K̄\(0\) must be > 0 1/m \(the rest "
                                          r"arc\), got 0.0"),
])
def test_a_profile_outside_its_ranges_is_refused_naming_the_constant(changes, message):
    with pytest.raises(ValueError, match="^" + message):
        CurvatureProfile(**changes)


def test_a_profile_at_the_open_ends_of_its_ranges_is_accepted():
    """The smallest positive normal switch time and the smallest positive rest curvature are
    allowed (both ranges are open at 0 only; a subnormal constant is refused as StarParams'
    fields are, tests/unit/test_params.py)."""
    assert CurvatureProfile(switch_time=sys.float_info.min).switch_time == sys.float_info.min
    barely_bent = CurvatureProfile(heating=(-1.0, 0.0, 0.0, 0.5 + 2 ** -40))
    assert barely_bent.rest_curvature == 2 ** -40


def test_the_text_of_a_profile_reads_back_to_the_last_bit_and_nothing_else_does():
    profile = CurvatureProfile(heating=(-89.5, 62.724, 0.1 + 0.2, 104.04), switch_time=1 / 3)
    assert CurvatureProfile.from_text(profile.to_text()) == profile
    for text in ("CurvatureProfile((1, 2, 3, 4))", "Profile(switch_time=0.1)",
                 "CurvatureProfile(switch_time=-1)", "CurvatureProfile(heating=(1, 2, 3, 4)"):
        with pytest.raises(ValueError, match=r"^actuator_profile: .* is not a profile's text"):
            CurvatureProfile.from_text(text)


@pytest.mark.parametrize("switch_time", [np.float32(0.15), np.float64(0.15), 1])
def test_a_numpy_or_integer_switch_time_is_stored_as_a_python_float(switch_time):
    # as every number field of the parameters: NumPy scalars accepted, the value a float
    profile = CurvatureProfile(switch_time=switch_time)
    assert type(profile.switch_time) is float and profile.switch_time == float(switch_time)


@pytest.mark.parametrize("field, value", [
    ("switch_time", True), ("switch_time", "0.1"), ("heating", (True, 1.0, 1.0, 1.0)),
    ("heating", "1234"), ("cooling", 5.0), ("cooling", (1.0, 2.0, 3.0, np.bool_(True))),
    # past a float's range: an OverflowError of float() and math.isfinite (an audit, 2026-12)
    ("switch_time", 10**400), ("switch_time", -10**400), ("heating", (10**400, 1.0, 1.0, 1.0))])
def test_bools_text_and_non_sequences_are_refused_naming_the_field(field, value):
    with pytest.raises(ValueError, match=rf"CurvatureProfile\.{field} must be "):
        CurvatureProfile(**{field: value})


# Found by a mutation audit of the actuation (2026-12-07): each test below kills a change of
# the code that the suite let live.


def test_the_switch_snap_is_one_part_in_1e12_of_the_time():
    """The documented window, 1e-12 × max(|t|, 1 s): τ 5e-12 s from t0 at t = 0.5 s is
    read as it comes (a window of 1e-11 read it as t0, on the cooling branch)."""
    assert SWITCH_SNAP == 1e-12
    t0 = CurvatureProfile().switch_time
    for tau in (t0 - 5e-12, t0 + 5e-12):
        assert snapped_to_switch(tau, t0, 0.5) == tau
    assert snapped_to_switch(t0 + 5e-12, t0, 6.0) == t0  # the window of |t| = 6 s


@pytest.mark.parametrize("field", ["heating", "cooling"])
def test_five_constants_for_a_branch_are_refused_naming_the_field(field):
    """Five numbers are refused as three are (the 5-tuple passed the length check and
    failed later with NumPy's "too many values to unpack")."""
    with pytest.raises(ValueError, match=rf"^CurvatureProfile\.{field} must be 4 finite numbers"):
        CurvatureProfile(**{field: (1.0, 2.0, 3.0, 4.0, 5.0)})


def test_a_negative_zero_constant_is_stored_as_plus_zero():
    """-0.0 is stored as +0.0 (StarParams' rule): the two profiles have the same text,
    which result tables store, and the same bits."""
    plus = CurvatureProfile(heating=(-89.827, 62.724, 0.0, 104.04))
    minus = CurvatureProfile(heating=(-89.827, 62.724, -0.0, 104.04))
    assert minus.to_text() == plus.to_text()
    assert np.array_equal(np.signbit(minus.as_array()), np.signbit(plus.as_array()))
