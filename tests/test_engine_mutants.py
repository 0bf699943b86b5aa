"""tools/engine_mutants.py's mutants against the code as it is: each one's text found exactly
once in its file, and each one's tests existing, so that the committed table
(results/mutation/engine_mutants.csv) can be made again (five texts had moved with the code
unnoticed until the tool refused them, 2026-12)."""

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def engine_mutants(tool):
    return tool("engine_mutants")


def test_every_mutants_text_is_found_once_and_changes_it(engine_mutants):
    for ident, path, original, mutated, tests, _ in engine_mutants.MUTANTS:
        assert (REPO / path).read_text().count(original) == 1, ident
        assert mutated != original, ident


def test_every_named_test_exists(engine_mutants):
    for ident, _, _, _, tests, _ in engine_mutants.MUTANTS:
        for test in tests:
            module, _, name = test.partition("::")
            assert f"def {name}(" in (REPO / module).read_text(), (ident, test)
