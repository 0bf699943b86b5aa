"""The user documentation builds cleanly, and the licence and citation files are well formed."""

import html
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]

CFF_REQUIRED_KEYS = ("cff-version", "message", "title", "authors")
CFF_REFERENCE_KEYS = ("type", "title", "authors")
TEXT_SUFFIXES = {".md", ".yml", ".yaml", ".js", ".css", ".html", ".txt", ".cff", ".py"}

INTERNAL_CITATION = "design " + "\u00a7"
"""How a section of the internal design document is cited (built here so that searching the
repository for such citations does not find this check itself)."""


@pytest.fixture(scope="module")
def built_site(tmp_path_factory):
    """`mkdocs build --strict` into a temporary folder: (completed process, site folder)."""
    pytest.importorskip("mkdocs")
    pytest.importorskip("material")
    pytest.importorskip("mkdocstrings_handlers.python")
    site = tmp_path_factory.mktemp("docs") / "site"
    completed = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-d", str(site)],
        cwd=REPO_ROOT, capture_output=True, text=True, timeout=600)
    return completed, site


def test_mkdocs_build_strict(built_site):
    completed, site = built_site
    assert completed.returncode == 0, completed.stdout + completed.stderr
    for page in ("index", "model", "numerics", "performance", "studies", "reproducibility", "results",
                 "reliability", "result_files", "api"):
        assert (site / page / "index.html").exists() or (site / f"{page}.html").exists(), page
    api = (site / "api" / "index.html").read_text(encoding="utf-8")
    # dataclass fields and their documented units reach the reference
    assert "youngs_modulus" in api and "newton_tol" in api
    # long signatures are wrapped one parameter a line (mkdocstrings formats them with ruff)
    signature = re.sub(r"<[^>]+>", "", api[api.index('id="taichi_star.simulate"'):])
    assert re.search(r"simulate\(\n\s+params: Sequence\[StarParams\],\n", html.unescape(signature))
    # the result's columns are a table
    assert "<td>signed_speed_mm_s</td>" in api and "<td>failure_time_s</td>" in api
    # the plots the pages show come from results/
    assert (site / "results" / "fig4c.png").read_bytes() == (REPO_ROOT / "results" / "fig4c.png").read_bytes()


def test_site_reads_offline_with_its_equations_rendered_by_the_vendored_katex(built_site):
    """No page loads a script, stylesheet or font from the network; every page with equations
    loads KaTeX from the site itself, and the files it names are there."""
    completed, site = built_site
    assert completed.returncode == 0
    remote = re.compile(r'<(?:script|link)[^>]+(?:src|href)="(?:https?:)?//[^"]+"')
    pages_with_math = 0
    for page in site.rglob("*.html"):
        text = page.read_text(encoding="utf-8")
        assert not remote.findall(text), (page.name, remote.findall(text))
        if 'class="arithmatex"' in text:
            pages_with_math += 1
            assert "vendor/katex/katex.min.js" in text and "katex.min.css" in text, page
    assert pages_with_math >= 3  # model, numerics, ... carry the equations
    css = (site / "vendor" / "katex" / "katex.min.css").read_text(encoding="utf-8")
    fonts = set(re.findall(r"url\((fonts/[^)]+\.woff2)\)", css))
    assert fonts and all((site / "vendor" / "katex" / font).exists() for font in fonts)


def test_the_readme_links_to_pages_and_headings_the_site_has(built_site):
    completed, site = built_site
    assert completed.returncode == 0
    readme = (REPO_ROOT / "README.md").read_text(encoding="utf-8")
    links = re.findall(r"\]\(docs/(\w+)\.md(?:#([\w-]+))?\)", readme)
    assert len(links) >= 10
    for page, anchor in links:
        built = site / page / "index.html"
        assert built.exists(), page
        if anchor:
            assert f'id="{anchor}"' in built.read_text(encoding="utf-8"), (page, anchor)


def test_rendered_site_does_not_cite_the_internal_design(built_site):
    completed, site = built_site
    assert completed.returncode == 0
    offenders = [str(page.relative_to(site)) for page in site.rglob("*.html")
                 if INTERNAL_CITATION in page.read_text(encoding="utf-8")]
    assert not offenders, offenders


def test_citation_file_is_valid_cff():
    yaml = pytest.importorskip("yaml")
    tomllib = pytest.importorskip("tomllib")  # Python 3.11 and later
    data = yaml.safe_load((REPO_ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    for key in CFF_REQUIRED_KEYS:
        assert key in data, key
    assert data["cff-version"] == "1.2.0"
    assert data["title"] == "taichi_star"
    assert data["license"] == "MIT"
    assert all(isinstance(author, dict) and author for author in data["authors"])
    # the version has one source, taichi_star.__version__ (written into every result's
    # provenance), which the package metadata reads
    pyproject = tomllib.loads((REPO_ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    assert pyproject["project"]["dynamic"] == ["version"]
    assert "version" not in pyproject["project"]
    assert pyproject["tool"]["setuptools"]["dynamic"]["version"] == {
        "attr": "taichi_star.__version__"}
    import taichi_star

    assert taichi_star.__version__ == data["version"]
    references = [data["preferred-citation"], *data.get("references", [])]
    for reference in references:
        for key in CFF_REFERENCE_KEYS:
            assert key in reference, key
        assert "Star-Shaped Swimming Robot" in reference["title"]
        assert [a["family-names"] for a in reference["authors"]] == [
            "Huang", "Huang", "Patterson", "Ren", "Jawed", "Majidi"]


def test_licence_is_mit():
    text = (REPO_ROOT / "LICENSE").read_text(encoding="utf-8")
    assert text.startswith("MIT License")
    assert "Copyright (c) 2026 the taichi_star developers" in text


def _user_facing_text_files():
    files = [path for path in (REPO_ROOT / "docs").rglob("*")
             if path.is_file() and path.suffix in TEXT_SUFFIXES]
    return files + [REPO_ROOT / "taichi_star" / "data" / "SOURCE.md"]


def test_user_docs_do_not_cite_the_internal_design():
    offenders = [str(path.relative_to(REPO_ROOT)) for path in _user_facing_text_files()
                 if INTERNAL_CITATION in path.read_text(encoding="utf-8")]
    assert not offenders, offenders


def test_readme_opens_with_the_two_commands_and_the_api():
    """What a newcomer reads first: the install + main job and install + tests commands, then
    within 60 lines a Python quickstart whose every `ts.` name exists; at most 200 lines."""
    import taichi_star

    lines = (REPO_ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= 200
    commands = [line.split("#")[0].strip() for line in lines[2:6] if line and not line.startswith("```")]
    assert commands == ['pip install -e ".[plots]" && python -m studies fig4c',
                        'pip install -e ".[test]" && python -m pytest -q']
    start = lines.index("```python")
    end = lines.index("```", start)
    assert end < 60
    quickstart = "\n".join(lines[start + 1:end])
    compile(quickstart, "README quickstart", "exec")
    for name in ("simulate", "Simulator", "StarParams"):
        assert f"ts.{name}(" in quickstart and hasattr(taichi_star, name), name
    assert 'gymnasium.make_vec("StarSwimmer-v0"' in quickstart


def test_the_extras_paragraph_names_every_study_with_its_extra():
    """docs/index.md's "Which study needs which extra" lists, after each extra, the studies
    whose launcher checks for it (studies.EXTRA_OF_STUDY): none missing, none misplaced."""
    from studies import EXTRA_OF_STUDY

    text = (REPO_ROOT / "docs" / "index.md").read_text()
    paragraph = text[text.index("Which study needs which extra:"):]
    paragraph = paragraph[:paragraph.index("\n\n")]
    for extra in ("plots", "envs", "studies"):
        part = paragraph[paragraph.index(f"`{extra}` for"):]
        listed = set(re.findall(r"[a-z][a-z0-9_]*", part[:part.index(";")]))
        expected = {name for name, needs in EXTRA_OF_STUDY.items() if needs == extra}
        assert expected <= listed, (extra, expected - listed)
        others = {name for name, needs in EXTRA_OF_STUDY.items() if needs != extra}
        assert not (others & listed), (extra, others & listed)


@pytest.mark.parametrize("module", ["taichi_star", "taichi_star.batch", "taichi_star.envs"])
def test_the_api_reference_lists_every_public_name_of_the_packages(module):
    """The README says the API reference lists every function; fourteen names of these
    `__all__`s were not in it (an audit, 2026-12). Each is an entry (`::: ...name`) or a member
    line (`- name`) of docs/api.md."""
    import importlib

    text = (REPO_ROOT / "docs" / "api.md").read_text()
    entries = re.findall(r"^::: ([\w.]+)", text, re.M)
    members = set(re.findall(r"^\s+- (\w+)$", text, re.M))
    public = [name for name in importlib.import_module(module).__all__ if name != "__version__"]
    missing = [name for name in public
               if name not in members and not any(entry.endswith(f".{name}") for entry in entries)]
    assert missing == [], f"{module}: not in docs/api.md: {missing}"


def python_blocks(page: Path) -> list:
    """The ```python blocks of a Markdown page, in order, dedented (a block may sit in a list
    item)."""
    import textwrap

    blocks = re.findall(r"^( *)```python\n(.*?)^\1```", page.read_text(encoding="utf-8"),
                        re.M | re.S)
    return [textwrap.dedent(body) for _, body in blocks]


@pytest.mark.parametrize("page", ["README.md", *sorted(
    str(path.relative_to(REPO_ROOT)) for path in (REPO_ROOT / "docs").glob("*.md")
    if path.name != "result_files.md")])
def test_a_pages_python_examples_define_every_name_they_use(page):
    """A reader copies a page's examples in order: together they compile, and every name
    their top level reads is imported or assigned by one of them or is a builtin (the
    numerics page's time-step check read `ts`, `params` and `duration` from nowhere: a
    NameError; an audit of the docs' examples, 2026-12, which ran every example)."""
    import builtins
    import symtable

    source = "\n".join(python_blocks(REPO_ROOT / page))
    compile(source, page, "exec")
    table = symtable.symtable(source, page, "exec")
    unbound = sorted(symbol.get_name() for symbol in table.get_symbols()
                     if symbol.is_referenced() and not (symbol.is_assigned()
                                                        or symbol.is_imported())
                     and not hasattr(builtins, symbol.get_name()))
    assert unbound == [], f"{page}: names read but never defined: {unbound}"
