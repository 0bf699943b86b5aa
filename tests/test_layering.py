"""The layers declared in pyproject.toml ([tool.importlinter]) hold: studies use only the public
API of taichi_star, taichi_star never imports studies, no study imports another, no import
cycles between sibling modules."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent


def test_import_contracts_are_kept():
    command = shutil.which("lint-imports") or str(Path(sys.executable).with_name("lint-imports"))
    if not Path(command).exists():
        pytest.fail("lint-imports not found: pip install -e '.[test]' installs import-linter")
    run = subprocess.run([command, "--no-cache"], cwd=REPO, capture_output=True, text=True,
                         env=dict(os.environ, PYTHONPATH=str(REPO)))
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-2000:]
    assert "BROKEN" not in run.stdout


def test_every_study_is_in_the_independence_contract():
    """The contract lists the studies by name: a study added without it could import another."""
    from studies import study_names

    tomllib = pytest.importorskip("tomllib")     # Python ≥ 3.11

    contracts = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["importlinter"][
        "contracts"]
    (independent,) = [c for c in contracts if c["name"] == "no study imports another study"]
    assert sorted(independent["modules"]) == [f"studies.{name}" for name in study_names()]
