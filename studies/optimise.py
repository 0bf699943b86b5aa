"""Several independent L-BFGS-B searches whose evaluations share one batched simulation.

A study that starts a gradient search from several points wants each search to be its own (its
own line search and curvature pairs: a start whose line search backtracks must not shorten the
steps of another) and every evaluation batched (one `simulate` call for all the points asked at
once, the engine's strength). scipy's L-BFGS-B asks for one point at a time and waits for its
value, so `minimise_lbfgsb_batched` runs one search per start in a thread of its own, where only
scipy runs, and gathers the points the searches ask for into one call of the study's batch
evaluation on the calling thread (Taichi's kernels stay on it). A search that has stopped drops
out of the later batches. Each search takes exactly the path it would take alone: scipy is
deterministic and sees only its own values and gradients.
"""

from __future__ import annotations

import threading
from typing import Callable, List, Sequence, Tuple

import numpy as np


class EvaluationsSpent(Exception):
    """Raised in `minimise_lbfgsb` when a search asks for a point beyond its budget."""


class SearchAborted(Exception):
    """Raised inside a search's thread when the batch evaluation failed on the calling thread
    (the search then ends, and the evaluation's own error is raised to the caller)."""


def minimise_lbfgsb(objective: Callable[[np.ndarray], Tuple[float, np.ndarray]], start,
                    bounds: Sequence[Tuple[float, float]], max_iterations: int,
                    max_evaluations: int, budget: str = "max_evaluations"):
    """scipy's L-BFGS-B from `start` (D,) within `bounds` on `objective(point)` -> (value,
    gradient (D,)), asking for `max_evaluations` points at most: scipy checks its `maxfun` only
    between iterations and finishes a line search past it (7 points for 4). Returns scipy's
    `OptimizeResult`, or for a search stopped at the budget one of its best point (x, fun,
    jac), nfev and the message "stopped after `budget` (N) evaluations" (`budget`: the name its
    caller's user gives the cap)."""
    from scipy.optimize import OptimizeResult, minimize
    made, best = [0], {}

    def counted(point):
        if made[0] == max_evaluations:
            raise EvaluationsSpent
        made[0] += 1
        value, gradient = objective(point)
        if not best or value < best["fun"]:
            best.update(x=np.array(point, dtype=float), fun=value, jac=gradient)
        return value, gradient
    try:
        return minimize(counted, np.asarray(start, dtype=float), jac=True, method="L-BFGS-B",
                        bounds=list(bounds),
                        options={"maxiter": max_iterations, "maxfun": max_evaluations})
    except EvaluationsSpent:
        return OptimizeResult(**best, nfev=made[0], success=False,
                              message=f"stopped after {budget} ({max_evaluations}) evaluations")


def minimise_lbfgsb_batched(
        evaluate_batch: Callable[[List[int], np.ndarray], Tuple[np.ndarray, np.ndarray]],
        starts: Sequence[np.ndarray], bounds: Sequence[Tuple[float, float]],
        max_iterations: int, max_evaluations: int) -> list:
    """Minimise from every start (S points of D values) with its own L-BFGS-B (scipy; `bounds`
    (D pairs), `max_iterations` and `max_evaluations` per search).

    `evaluate_batch(indices, points)` gets the indices of the searches that ask for a point now
    (ascending) and those points (K, D), and returns their values (K,) and gradients (K, D). It
    is called on the calling thread only, once per round, every round holding every search that
    has not stopped. A search asks for `max_evaluations` points at most (`minimise_lbfgsb`).
    Returns the `OptimizeResult` of every search, in the starts' order. An exception raised by
    `evaluate_batch` ends every search and is raised here."""
    condition = threading.Condition()
    asked: dict = {}
    answers: dict = {}
    running = set(range(len(starts)))
    results: list = [None] * len(starts)
    failures: list = []
    aborted = threading.Event()

    def search(index: int):
        def objective(point):
            with condition:
                asked[index] = np.array(point, dtype=float)
                condition.notify_all()
                while index not in answers and not aborted.is_set():
                    condition.wait()
                if aborted.is_set():
                    raise SearchAborted
                return answers.pop(index)
        try:
            results[index] = minimise_lbfgsb(objective, starts[index], bounds, max_iterations,
                                             max_evaluations)
        except SearchAborted:
            pass
        except BaseException as error:  # any: raised again on the calling thread
            failures.append(error)
        finally:
            with condition:
                running.discard(index)
                condition.notify_all()

    threads = [threading.Thread(target=search, args=(index,), daemon=True,
                                name=f"lbfgsb-search-{index}") for index in range(len(starts))]
    for thread in threads:
        thread.start()
    try:
        while True:
            with condition:
                # a round starts when every search still running has asked for its point
                while running and len(asked) < len(running) and not failures:
                    condition.wait()
                if failures or not running:
                    break
                indices = sorted(asked)
                points = np.array([asked.pop(index) for index in indices])
            values, gradients = evaluate_batch(indices, points)
            with condition:
                for row, index in enumerate(indices):
                    answers[index] = (float(values[row]),
                                      np.array(gradients[row], dtype=float))
                condition.notify_all()
    finally:
        # searches still waiting for an answer (the evaluation or another search failed) end;
        # after a normal finish none is left
        aborted.set()
        with condition:
            condition.notify_all()
        for thread in threads:
            thread.join()
    if failures:
        raise failures[0]
    return results
