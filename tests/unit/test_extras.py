"""Optional dependencies: the core modules import none of them, and a missing one raises an
ImportError naming the extra that installs it."""

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from taichi_star.extras import require

REPO = Path(__file__).resolve().parents[2]

OPTIONAL_PACKAGES = ("gymnasium", "matplotlib", "PIL", "cma", "SALib", "scipy", "xarray",
                     "netCDF4", "imageio_ffmpeg", "dask", "distributed", "stable_baselines3")
"""Top-level packages of the extras (pyproject.toml [project.optional-dependencies])."""


def test_core_modules_import_no_optional_package():
    """What `simulate`, `Simulator` and `run_batch` need loads none of the extras' packages (run
    in a fresh interpreter: this one has imported them for other tests)."""
    script = textwrap.dedent(f"""
        import sys
        import taichi_star, taichi_star.batch, taichi_star.output, taichi_star.experiment
        loaded = sorted({{name.split(".")[0] for name in sys.modules}} & set({OPTIONAL_PACKAGES!r}))
        print(",".join(loaded))
    """)
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         cwd=REPO, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.strip() == ""


def test_require_returns_an_installed_module():
    import json

    assert require("json", "io") is json


def test_require_names_the_extra_of_a_missing_package():
    with pytest.raises(ImportError, match=r'pip install "taichi_star\[studies\]"') as error:
        require("taichi_star_no_such_package.sub", "studies")
    assert "taichi_star_no_such_package.sub is not installed" in str(error.value)


def test_require_passes_on_a_missing_import_inside_an_installed_package(tmp_path, monkeypatch):
    """An installed package that fails to import one of ITS dependencies is not reported as the
    extra missing: the original error, naming the real culprit, propagates."""
    (tmp_path / "installed_but_broken.py").write_text("import taichi_star_absent_dependency\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(ModuleNotFoundError) as error:
        require("installed_but_broken", "io")
    assert error.value.name == "taichi_star_absent_dependency"
