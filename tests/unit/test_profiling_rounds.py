"""profiling.interleaved_rounds with fake calls and a fake clock: the order of the warm-ups and
the rounds, the times it reports (exact values of the fake clock, no real timing), the results
it returns and its argument checks."""

import pytest

from taichi_star import profiling


class FakeMachine:
    """Calls that log their label and advance a fake clock (`time.perf_counter` in profiling)
    by their own durations (s), one per time the call is made, in order; each returns (label,
    how many times it has run)."""

    def __init__(self, monkeypatch, durations):
        self.now = 0.0
        self.log = []
        self.durations = {label: list(times) for label, times in durations.items()}
        self.runs = {label: 0 for label in durations}
        monkeypatch.setattr(profiling.time, "perf_counter", lambda: self.now)

    def call(self, label):
        def made():
            self.log.append(label)
            self.now += self.durations[label].pop(0)
            self.runs[label] += 1
            return label, self.runs[label]
        return made


# The durations are binary fractions (multiples of 1/8 s, sums below 2^5 s): the fake clock's
# sums and differences are exact in floating point, so the times are compared with ==.

def test_warm_ups_first_then_every_call_once_per_round_in_order(monkeypatch):
    machine = FakeMachine(monkeypatch, {"warm a": [8.0], "a": [1.5, 2.25],
                                        "b": [0.5, 0.375, 0.125], "c": [4.0, 3.0, 3.5]})

    def progress(round_index, index, seconds):
        machine.log.append(("progress", round_index, index, seconds))

    results, times, warmup_times = profiling.interleaved_rounds(
        [machine.call("a"), machine.call("b"), machine.call("c")], 2,
        [machine.call("warm a"), machine.call("b"), None],
        before_rounds=lambda: machine.log.append("before rounds"), progress=progress)
    # a's own warm-up, b's (here the call itself given as its warm-up), c warmed by its call
    # (None); then the rounds, each call once per round in order, reported as it ends
    assert machine.log == [
        "warm a", "b", "c", "before rounds",
        "a", ("progress", 0, 0, 1.5), "b", ("progress", 0, 1, 0.375),
        "c", ("progress", 0, 2, 3.0),
        "a", ("progress", 1, 0, 2.25), "b", ("progress", 1, 1, 0.125),
        "c", ("progress", 1, 2, 3.5)]
    assert machine.runs == {"warm a": 1, "a": 2, "b": 3, "c": 3}
    # the warm-ups' times apart from the rounds'; one row of times per round, a column per call
    assert warmup_times.tolist() == [8.0, 0.5, 4.0]
    assert times.shape == (2, 3)
    assert times.tolist() == [[1.5, 0.375, 3.0], [2.25, 0.125, 3.5]]
    # the results of the last round's calls, not the warm-ups' nor the first round's
    assert results == [("a", 2), ("b", 3), ("c", 3)]


def test_without_warm_ups_each_call_warms_itself(monkeypatch):
    machine = FakeMachine(monkeypatch, {"a": [5.0, 1.0, 0.75, 1.25], "b": [6.0, 2.0, 2.5, 1.5]})
    results, times, warmup_times = profiling.interleaved_rounds(
        (machine.call("a"), machine.call("b")), 3)
    assert machine.log == ["a", "b"] * 4
    assert warmup_times.tolist() == [5.0, 6.0]
    assert times.tolist() == [[1.0, 2.0], [0.75, 2.5], [1.25, 1.5]]
    # each call's best of the rounds, as the studies keep it
    assert times.min(axis=0).tolist() == [0.75, 1.5]
    assert results == [("a", 4), ("b", 4)]


@pytest.mark.parametrize("calls, rounds, warmups, message", [
    ([], 2, None, "calls must hold at least one call"),
    (["a"], 0, None, "rounds must be an integer >= 1, got 0"),
    (["a"], 1.0, None, "rounds must be an integer >= 1, got 1.0"),
    (["a"], True, None, "rounds must be an integer >= 1, got True"),
    (["a", "b"], 1, ["a"], r"warmups must have one entry per call \(2, .*\), got 1"),
    (["a"], 1, [], r"warmups must have one entry per call \(1, .*\), got 0"),
])
def test_bad_arguments_are_refused_before_any_call(monkeypatch, calls, rounds, warmups,
                                                   message):
    machine = FakeMachine(monkeypatch, {"a": [1.0], "b": [1.0]})
    with pytest.raises(ValueError, match=message):
        profiling.interleaved_rounds([machine.call(label) for label in calls], rounds,
                                     None if warmups is None else
                                     [machine.call(label) for label in warmups])
    assert machine.log == []
