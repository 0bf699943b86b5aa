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


def test_the_tables_sidecar_quotes_the_command_and_stamps_the_table(engine_mutants, tmp_path):
    """An argument with a space stays one when the command is read back (it was joined with
    spaces: an audit, 2026-12); the sidecar records whether the checkout was dirty and the
    SHA-256 of the very bytes written."""
    import hashlib
    import json
    import shlex

    out = tmp_path / "mutants.csv"
    rows = [{"mutant": "m1", "what": "a b"}, {"mutant": "m2", "what": "c"}]
    argv = ["--only", "m1,m2", "--out", "a folder/mutants.csv"]
    engine_mutants.write_table(rows, out, argv)
    sidecar = json.loads(out.with_name("mutants.csv.json").read_text())
    assert shlex.split(sidecar["command"])[2:] == argv
    assert sidecar["git_dirty"] in (True, False) and sidecar["git_commit"]
    assert sidecar["table_sha256"] == hashlib.sha256(out.read_bytes()).hexdigest()
    assert sidecar["table_rows"] == 2
