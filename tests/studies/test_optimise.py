"""studies.optimise: independent L-BFGS-B searches, batched. Each search must take exactly the
path scipy takes for it alone (its own line search), every round must hold every search still
running and no other, and a failing evaluation must end every search and reach the caller."""

import threading

import numpy as np
import pytest
from scipy.optimize import minimize

from studies.optimise import minimise_lbfgsb_batched

# three separable problems of different scale and curvature: a search on one of them alone
# backtracks at other moments than the others, which a shared line search would couple
CENTRES = np.array([[0.3, -0.2], [2.0, 1.0], [-1.5, 0.5]])
SCALES = np.array([[1.0, 30.0], [0.1, 1.0], [5.0, 5.0]])
STARTS = np.array([[1.0, 1.0], [-1.0, -1.0], [0.9, -0.8]])
BOUNDS = [(-1.0, 1.0), (-1.0, 1.0)]  # the second and third minima lie partly outside


def value_and_gradient(index, point):
    offset = point - CENTRES[index]
    # a quartic term so that the curvature changes along the path (more than one line search)
    value = float(np.sum(SCALES[index] * offset ** 2) + np.sum(offset ** 4))
    return value, 2.0 * SCALES[index] * offset + 4.0 * offset ** 3


def test_each_search_takes_its_own_path_and_rounds_hold_the_running_searches():
    rounds = []

    def evaluate(indices, points):
        assert threading.current_thread() is threading.main_thread()
        rounds.append(list(indices))
        pairs = [value_and_gradient(index, point) for index, point in zip(indices, points)]
        return np.array([v for v, _ in pairs]), np.array([g for _, g in pairs])

    results = minimise_lbfgsb_batched(evaluate, STARTS, BOUNDS, max_iterations=50,
                                      max_evaluations=60)
    for index, result in enumerate(results):
        alone = minimize(lambda x, index=index: value_and_gradient(index, x), STARTS[index],
                         jac=True, method="L-BFGS-B", bounds=BOUNDS,
                         options={"maxiter": 50, "maxfun": 60})
        # the same floating-point operations in the same order: equal to the last bit
        np.testing.assert_array_equal(result.x, alone.x)
        assert result.nfev == alone.nfev and result.fun == alone.fun
        # and every search appears in exactly its own number of rounds, the first ones
        assert sum(index in members for members in rounds) == alone.nfev
        assert all(index in members for members in rounds[:alone.nfev])
    # a search that has stopped is in no later round: the rounds shrink, never grow
    sizes = [len(members) for members in rounds]
    assert sizes == sorted(sizes, reverse=True) and sizes[0] == 3 and sizes[-1] >= 1
    assert len(set(r.nfev for r in results)) > 1  # the searches did stop at different times
    # the bounded minima: the second search ends on its upper bound in x (centre at 2.0),
    # exactly (L-BFGS-B projects its points onto the bounds)
    assert results[1].x[0] == 1.0


def test_a_failing_evaluation_ends_every_search_and_reaches_the_caller():
    calls = []

    def evaluate(indices, points):
        calls.append(list(indices))
        if len(calls) == 2:
            raise RuntimeError("the batch failed")
        pairs = [value_and_gradient(index, point) for index, point in zip(indices, points)]
        return np.array([v for v, _ in pairs]), np.array([g for _, g in pairs])

    before = threading.active_count()
    with pytest.raises(RuntimeError, match="the batch failed"):
        minimise_lbfgsb_batched(evaluate, STARTS, BOUNDS, max_iterations=50, max_evaluations=60)
    assert len(calls) == 2
    assert threading.active_count() == before  # every search's thread has ended


def recording_searches(monkeypatch, starts, fail_at_call=None):
    """Patch scipy's minimize, as the searches call it, to record how the search from each of
    `starts` ends ("finished", or the name of the exception that ended it); with fail_at_call,
    the third search's objective raises ValueError("search 2 broke") at that call (scipy's
    call of it, in its thread) instead of asking for its point."""
    ended = {}

    def recording_minimize(fun, x0, *args, **kwargs):
        index = next(i for i, start in enumerate(starts) if np.array_equal(start, x0))
        if index == 2 and fail_at_call is not None:
            calls = []

            def failing(point, ask=fun):
                calls.append(point)
                if len(calls) == fail_at_call:
                    raise ValueError("search 2 broke")
                return ask(point)
            fun = failing
        try:
            result = minimize(fun, x0, *args, **kwargs)
        except BaseException as error:
            ended[index] = type(error).__name__
            raise
        ended[index] = "finished"
        return result

    monkeypatch.setattr("scipy.optimize.minimize", recording_minimize)
    return ended


def test_a_failing_search_ends_the_others_and_reaches_the_caller(monkeypatch):
    """A search whose scipy call raises in its thread (here: a start of three values against
    two bounds, refused before it asks for a point) ends the round trip of the others."""
    evaluated = []

    def evaluate(indices, points):
        evaluated.append(list(indices))
        pairs = [value_and_gradient(index, point) for index, point in zip(indices, points)]
        return np.array([v for v, _ in pairs]), np.array([g for _, g in pairs])

    starts = [STARTS[0], STARTS[1], np.array([0.9, -0.8, 0.0])]
    ended = recording_searches(monkeypatch, starts)
    before = threading.active_count()
    with pytest.raises(ValueError, match=r"number of bounds is not compatible with the length"):
        minimise_lbfgsb_batched(evaluate, starts, BOUNDS, max_iterations=50, max_evaluations=60)
    assert threading.active_count() == before
    # the first round waits for every search still running, and the third never asks: its
    # failure ends the others (waiting for their first point) before any evaluation
    assert evaluated == []
    assert ended == {0: "SearchAborted", 1: "SearchAborted", 2: "ValueError"}


def test_a_search_failing_midway_ends_the_others_and_reaches_the_caller(monkeypatch):
    """The third search fails at its fourth objective call, after three rounds: no round
    follows, the first search (still running: 11 evaluations alone) is ended, the second had
    stopped on its own after two."""
    evaluated = []

    def evaluate(indices, points):
        evaluated.append(list(indices))
        pairs = [value_and_gradient(index, point) for index, point in zip(indices, points)]
        return np.array([v for v, _ in pairs]), np.array([g for _, g in pairs])

    ended = recording_searches(monkeypatch, STARTS, fail_at_call=4)
    before = threading.active_count()
    with pytest.raises(ValueError, match="search 2 broke"):
        minimise_lbfgsb_batched(evaluate, STARTS, BOUNDS, max_iterations=50, max_evaluations=60)
    assert threading.active_count() == before
    assert evaluated == [[0, 1, 2], [0, 1, 2], [0, 2]]
    assert ended == {0: "SearchAborted", 1: "finished", 2: "ValueError"}


def test_a_search_stops_at_its_evaluation_budget_with_its_best_point():
    """scipy's L-BFGS-B checks `maxfun` between iterations only and finishes a line search
    past it (shown below on the same problems); each batched search asks for
    `max_evaluations` points at most and reports its best point and why it stopped."""
    overshoot = 0
    for budget in range(1, 7):
        made = {index: [] for index in range(len(STARTS))}

        def evaluate(indices, points):
            pairs = []
            for index, point in zip(indices, points):
                made[index].append(point)
                pairs.append(value_and_gradient(index, point))
            return np.array([v for v, _ in pairs]), np.array([g for _, g in pairs])

        results = minimise_lbfgsb_batched(evaluate, STARTS, BOUNDS, max_iterations=budget,
                                          max_evaluations=budget)
        for index, result in enumerate(results):
            alone = minimize(lambda x, index=index: value_and_gradient(index, x), STARTS[index],
                             jac=True, method="L-BFGS-B", bounds=BOUNDS,
                             options={"maxiter": budget, "maxfun": budget})
            overshoot += alone.nfev > budget
            assert len(made[index]) == result.nfev == min(alone.nfev, budget)
            values = [value_and_gradient(index, point)[0] for point in made[index]]
            if alone.nfev > budget:  # stopped here: its best point so far
                assert result.message == (f"stopped after max_evaluations ({budget}) "
                                          f"evaluations") and not result.success
                assert result.fun == min(values)
                np.testing.assert_array_equal(result.x, made[index][int(np.argmin(values))])
            else:  # scipy stopped first: its own result, the same as alone
                np.testing.assert_array_equal(result.x, alone.x)
    assert overshoot >= 3  # what the budget is for
