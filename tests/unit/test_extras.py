"""Optional dependencies: the core modules import none of them, and a missing one raises an
ImportError naming the extra that installs it."""

import re
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from taichi_star.extras import first_missing, require

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


def test_first_missing_names_the_first_absent_module_without_importing_it():
    assert first_missing(["json", "os"], "io") == ""
    message = first_missing(["json", "taichi_star_no_such_package", "another_absent"], "studies")
    assert message.startswith("taichi_star_no_such_package is not installed")
    assert 'pip install "taichi_star[studies]"' in message


def test_a_study_without_its_extra_stops_before_compute_with_one_line(monkeypatch, capsys):
    """The CLI's rule for bad setups: one line on stderr naming the extra, exit code 2, nothing
    run (the missing package is faked: this environment has the whole extra)."""
    from studies import __main__ as launcher

    monkeypatch.setattr(launcher, "STUDIES_EXTRA", ("json", "taichi_star_no_such_package"))
    assert launcher.main(["fig4c", "--quick"]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1
    assert "taichi_star_no_such_package is not installed" in error
    assert 'pip install "taichi_star[studies]"' in error


def test_the_launcher_checks_exactly_the_studies_extra():
    tomllib = pytest.importorskip("tomllib")  # Python 3.11 and later
    from studies import __main__ as launcher

    extras = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    import_names = {"pillow": "PIL"}  # distribution name → the module it installs, where they differ
    names = [re.split(r"[<>=!~\[ ;]", requirement)[0] for requirement in extras["studies"]]
    assert {import_names.get(name.lower(), name) for name in names} == set(launcher.STUDIES_EXTRA)


@pytest.mark.parametrize("argv0, name", [("/venv/bin/taichi-star", "taichi-star"),
                                         ("/repo/studies/__main__.py", "python -m studies")])
def test_the_studies_call_themselves_as_the_user_called_them(monkeypatch, capsys, argv0, name):
    from studies import __main__ as launcher

    monkeypatch.setattr(sys, "argv", [argv0])
    assert launcher.main(["no_such_study"]) == 2
    assert capsys.readouterr().err.startswith(f"{name}: error: unknown study 'no_such_study'")
    assert launcher.usage().startswith(f"usage: {name} <name>")


def test_the_studies_install_inside_taichi_star_with_their_data_and_command():
    """pyproject installs the checkout's studies/ as taichi_star.studies (no top-level
    `studies` in site-packages), with the candidate table, and the command points there."""
    import tomllib

    project = tomllib.loads((REPO / "pyproject.toml").read_text())
    setuptools = project["tool"]["setuptools"]
    assert "studies" not in setuptools["packages"]
    assert setuptools["package-dir"] == {"taichi_star.studies": "studies"}
    assert project["project"]["scripts"]["taichi-star"] == "taichi_star.studies.__main__:main"
    for name in setuptools["package-data"]["taichi_star.studies"]:
        assert (REPO / "studies" / name).exists(), name
    # every package with an __init__.py is listed (a new subpackage must be added), and the
    # data folders (package data, listed so that setuptools does not warn about them)
    found = {".".join(p.parent.relative_to(REPO).parts)
             for p in (REPO / "taichi_star").rglob("__init__.py")}
    data = {"taichi_star.data", "taichi_star.data.experiment"}
    assert found | data | {"taichi_star.studies"} == set(setuptools["packages"])
