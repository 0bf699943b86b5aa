"""Optional dependencies: the core modules import none of them, and a missing one raises an
ImportError naming the extra that installs it."""

import ast
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
"""Top-level packages of the extras (pyproject.toml [project.optional-dependencies]); pyarrow,
an extra too, is left out here because pandas imports it whenever it is installed: the test of
the main job below makes it absent instead."""


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


@pytest.mark.parametrize("study, module, extra", [("fig4c", "matplotlib", "plots"),
                                                   ("sweep", "pyarrow", "studies"),
                                                   ("env_bench", "gymnasium", "envs")])
def test_a_study_without_its_extra_stops_before_compute_with_one_line(monkeypatch, capsys,
                                                                       study, module, extra):
    """The CLI's rule for bad setups: one line on stderr naming the extra, exit code 2, nothing
    run (the missing package is faked: None in sys.modules makes it absent to `find_spec` and
    to `import`; this environment has every extra)."""
    from studies import __main__ as launcher

    monkeypatch.setitem(sys.modules, module, None)
    assert launcher.main([study, "--quick"]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1
    assert f"{module} is not installed" in error
    assert f'pip install "taichi_star[{extra}]"' in error


def test_the_list_of_studies_marks_those_whose_extra_is_missing(monkeypatch):
    """Listing the studies imports none of them: a study whose extra is absent is listed, with
    the extra it needs; the others are listed plainly."""
    from studies import __main__ as launcher

    monkeypatch.setitem(sys.modules, "gymnasium", None)
    listing = launcher.usage().splitlines()
    env_bench = next(line for line in listing if line.strip().startswith("env_bench "))
    fig4c = next(line for line in listing if line.strip().startswith("fig4c "))
    assert env_bench.endswith("(needs the 'envs' extra)")
    assert "needs" not in fig4c and "Fig. 4c/4b" in fig4c


def test_scaling_without_dask_asks_for_it_or_no_dask(monkeypatch, capsys):
    from studies import __main__ as launcher

    monkeypatch.setitem(sys.modules, "distributed", None)
    assert launcher.main(["scaling", "--quick"]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1
    assert 'pip install "taichi_star[dask]"' in error and "--no-dask" in error


def test_parquet_without_pyarrow_names_the_io_extra(monkeypatch, tmp_path):
    """pyarrow is an extra: every Parquet path (the run store, `parquet_bytes` behind
    `to_parquet` and the studies' tables, reading provenance) says to install `io`, before
    anything is written."""
    import pandas as pd

    from taichi_star.batch import RunStore
    from taichi_star.output import parquet_bytes, read_provenance

    for name in ("pyarrow", "pyarrow.parquet"):  # the cached modules too
        monkeypatch.setitem(sys.modules, name, None)
    expected = r'pyarrow(\.parquet)? is not installed.*pip install "taichi_star\[io\]"'
    with pytest.raises(ImportError, match=expected):
        parquet_bytes(pd.DataFrame({"x": [1.0]}), {})
    with pytest.raises(ImportError, match=expected):
        read_provenance(tmp_path / "table.parquet")
    with pytest.raises(ImportError, match=expected):
        RunStore(tmp_path / "run", {}).open([], resume=False)
    assert list(tmp_path.iterdir()) == []


def _extras_table():
    tomllib = pytest.importorskip("tomllib")  # Python 3.11 and later
    return tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["optional-dependencies"]


IMPORT_NAMES = {"pillow": "PIL", "imageio-ffmpeg": "imageio_ffmpeg", "dask": "distributed",
                "stable-baselines3": "stable_baselines3"}
"""Distribution name → the module the code imports from it, where they differ (dask is
installed as dask[distributed]; the code imports distributed)."""


def _expanded(extras, extra):
    """The requirements of `extra` with its self-references (taichi_star[a,b]) expanded."""
    names = set()
    for requirement in extras[extra]:
        name = re.split(r"[<>=!~\[ ;]", requirement)[0]
        if name == "taichi_star":
            for inner in re.search(r"\[(.*)\]", requirement).group(1).split(","):
                names |= _expanded(extras, inner.strip())
        else:
            names.add(name)
    return names


def test_the_extras_modules_match_pyproject():
    """taichi_star.extras.EXTRA_MODULES (what the code checks) lists exactly the modules each
    extra of pyproject.toml installs."""
    from taichi_star.extras import EXTRA_MODULES

    extras = _extras_table()
    for extra, modules in EXTRA_MODULES.items():
        installed = {IMPORT_NAMES.get(name, name) for name in _expanded(extras, extra)}
        assert installed == set(modules), extra


def test_all_is_every_extra_but_rl_and_test_adds_the_test_tools():
    extras = _extras_table()
    others = set(extras) - {"all", "test", "rl"}
    assert _expanded(extras, "all") == set().union(*(_expanded(extras, e) for e in others))
    assert _expanded(extras, "all") <= _expanded(extras, "test")
    assert "stable-baselines3" not in _expanded(extras, "test")  # torch: gigabytes
    # the tests' own needs beyond all: the reference's sparse solver and the tools
    assert {"scipy", "pytest", "hypothesis", "import-linter"} <= _expanded(extras, "test")


# ---- which optional modules each study needs, read from the sources (never imported)
LIBRARY_NEEDS = {"parquet_bytes": {"pyarrow"}, "to_parquet": {"pyarrow"},
                 "to_xarray": {"xarray"}, "to_netcdf": {"xarray", "netCDF4"},
                 "animate": {"matplotlib"}}  # GIF (pillow comes with matplotlib); MP4: video
"""Names of the library's API (a function or attribute used) that need an extra's modules."""
LIBRARY_KEYWORD_NEEDS = {"run_dir": {"pyarrow"}}  # run_batch's run store keeps Parquet chunks
LIBRARY_MODULE_NEEDS = {"taichi_star.envs": {"gymnasium"},
                        "taichi_star.batch.dask_cluster": {"distributed"}}
CORE_MODULES = {"taichi", "numpy", "pandas", "tqdm", "taichi_star", "studies"}
STUDIES = REPO / "studies"


def _guarded(node, parents):
    """Whether `node` sits in a try whose handlers catch ImportError (an optional import the
    code already handles)."""
    while node in parents:
        node, child = parents[node], node
        if isinstance(node, ast.Try) and child in node.body and any(
                isinstance(h.type, ast.Name) and h.type.id in ("ImportError", "ModuleNotFoundError")
                for h in node.handlers):
            return True
    return False


def _needs_and_names(tree):
    """(optional top-level modules imported or `require`d anywhere in `tree`, with the
    library's needs of the names it uses; the names it references)."""
    parents = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}
    needs, names = set(), set()
    for node in ast.walk(tree):
        modules = []
        if isinstance(node, ast.Import):
            modules = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0:
            modules = [node.module] + [f"{node.module}.{alias.name}" for alias in node.names]
        elif isinstance(node, ast.Call) and getattr(node.func, "id", None) == "require":
            modules = [node.args[0].value]
        if isinstance(node, ast.Call):
            for keyword in node.keywords:
                needs |= LIBRARY_KEYWORD_NEEDS.get(keyword.arg, set())
        if isinstance(node, ast.Name):
            names.add(node.id)
        if isinstance(node, ast.Attribute):
            names.add(node.attr)
        if modules and not _guarded(node, parents):
            for module in modules:
                top = module.split(".")[0]
                if top not in CORE_MODULES and top not in sys.stdlib_module_names:
                    needs.add(top)
                needs |= LIBRARY_MODULE_NEEDS.get(module, set())
    for name in names:
        needs |= LIBRARY_NEEDS.get(name, set())
    return needs, names


def _helper_needs():
    """Function or method name of the studies' helpers (cli, figures, identify, provenance) →
    the optional modules it needs, through the helpers it calls."""
    from studies import HELPERS

    direct, calls = {}, {}
    for helper in set(HELPERS) - {"__main__"}:  # the launcher: no study calls it
        tree = ast.parse((STUDIES / f"{helper}.py").read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                direct[node.name], calls[node.name] = _needs_and_names(node)
    needs = dict(direct)
    changed = True
    while changed:  # to a fixed point: a helper needs what the helpers it calls need
        changed = False
        for name in needs:
            grown = needs[name].union(*(needs[c] for c in calls[name] if c in needs and c != name))
            changed |= grown != needs[name]
            needs[name] = grown
    return needs


def test_every_study_declares_an_extra_that_covers_what_it_imports():
    """Read from the sources: each study's imports, `require`s, the library API it uses that
    needs an extra (run_dir, to_parquet, animate, taichi_star.envs) and the helpers it calls are
    covered by the extra it declares (EXTRA_OF_STUDY); `studies` covers them all but rl's (the
    rl extra: stable-baselines3 and torch, not in `all`). scaling's
    Dask clusters are checked by the study (it runs without them under --no-dask)."""
    if not hasattr(sys, "stdlib_module_names"):
        pytest.skip("needs Python 3.10's sys.stdlib_module_names")
    from studies import EXTRA_OF_STUDY, study_names
    from taichi_star.extras import EXTRA_MODULES

    assert set(EXTRA_OF_STUDY) == set(study_names())
    helpers = _helper_needs()
    checked_by_the_study = {"scaling": {"distributed"}}
    for study in study_names():
        tree = ast.parse((STUDIES / f"{study}.py").read_text(encoding="utf-8"))
        needs, names = _needs_and_names(tree)
        needs = needs.union(*(helpers[name] for name in names if name in helpers))
        needs -= checked_by_the_study.get(study, set())
        declared = EXTRA_OF_STUDY[study]
        covered = set(EXTRA_MODULES[declared]) if declared else set()
        assert needs <= covered, (study, needs - covered)
        # rl's stable-baselines3 and torch (gigabytes) are in no other extra, as in no "all"
        assert needs <= set(EXTRA_MODULES["studies"]) or declared == "rl", study
    assert EXTRA_OF_STUDY["fig4c"] == "plots"  # the main job stays light


def test_the_extras_check_of_the_studies_can_see_a_need():
    """The source reading above finds what it must: the Fig. 4c plots need matplotlib, sweep's
    run store pyarrow, calibrate's CMA-ES cma (else the test above would pass on nothing)."""
    if not hasattr(sys, "stdlib_module_names"):
        pytest.skip("needs Python 3.10's sys.stdlib_module_names")
    helpers = _helper_needs()
    assert helpers["run_fig4c"] == {"matplotlib"}
    assert helpers["minimise_cmaes"] == {"cma"}
    sweep, _ = _needs_and_names(ast.parse((STUDIES / "sweep.py").read_text(encoding="utf-8")))
    assert "pyarrow" in sweep


def test_the_main_job_imports_without_any_extra_but_plots():
    """In a fresh interpreter where every optional package but matplotlib is absent (None in
    sys.modules), the core and the fig4c study import, and the launcher accepts fig4c."""
    blocked = [name for name in OPTIONAL_PACKAGES if name != "matplotlib"] + ["pyarrow"]
    script = textwrap.dedent(f"""
        import sys
        for name in {blocked!r}:
            sys.modules[name] = None
        import taichi_star, taichi_star.batch, taichi_star.output, studies.fig4c
        from studies.__main__ import main
        sys.exit(main(["fig4c", "--help"]))
    """)
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         cwd=REPO, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "usage:" in run.stdout and "fig4c" in run.stdout


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
        assert list((REPO / "studies").glob(name)), name
    # every package with an __init__.py is listed (a new subpackage must be added), and the
    # data folders (package data, listed so that setuptools does not warn about them)
    found = {".".join(p.parent.relative_to(REPO).parts)
             for p in (REPO / "taichi_star").rglob("__init__.py")}
    data = {"taichi_star.data", "taichi_star.data.experiment"}
    assert found | data | {"taichi_star.studies"} == set(setuptools["packages"])


@pytest.mark.parametrize("package, folder, pattern", [
    # the candidate tables model_select's committed runs name (four of five were left out of
    # the wheel: an audit, 2026-12)
    ("taichi_star.studies", "studies", "*.csv"),
    ("taichi_star", "taichi_star", "data/**/*"),
])
def test_every_data_file_of_a_package_folder_is_package_data(package, folder, pattern):
    """The files beside a package's modules that its code reads are package data, so that a
    wheel works outside the checkout."""
    import fnmatch
    import tomllib

    globs = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"][
        "package-data"][package]
    files = [path.relative_to(REPO / folder).as_posix()
             for path in (REPO / folder).glob(pattern)
             if path.is_file() and path.suffix not in (".py", ".pyc")]
    assert files, pattern
    assert [name for name in files if not any(fnmatch.fnmatch(name, g) for g in globs)] == []
