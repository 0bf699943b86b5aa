"""Every figure README.md and docs/*.md quote from results/ equals its CSV cell: the generated
tables and the Result files page regenerate to what is committed, and every marked figure
(`0.852<!-- fig4c_accurate.csv gait=A1+A4 sim_speed_mm_s -->`) is its cell rounded to the
quoted decimals (tools/results_page.py)."""

import importlib.util
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def results_page():
    spec = importlib.util.spec_from_file_location("results_page", REPO / "tools" / "results_page.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclass looks its module up there
    spec.loader.exec_module(module)
    return module


def test_readme_and_docs_agree_with_results(results_page):
    problems = results_page.check()
    assert not problems, "\n".join(map(str, problems))


def test_the_pages_quote_figures_and_carry_the_generated_table(results_page):
    """The check has something to check: marked figures on several pages, the README's Fig. 4c
    table generated from the CSVs."""
    quoted_pages = [path.name for path in results_page.pages()
                    if results_page.QUOTE.search(path.read_text(encoding="utf-8"))]
    assert len(quoted_pages) >= 3, quoted_pages
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    assert "<!-- generated: fig4c_table -->" in readme


@pytest.mark.parametrize("quoted, value, matches", [
    ("0.852", 0.85235, True), ("0.852", 0.8525, True),  # ≤ half a unit of the last digit
    ("0.852", 0.85251, False), ("0.852", 0.8514, False), ("0.852", -0.852, False),
    ("51,155", 51155.20863, True), ("51,155", 51155.6, False),
    ("−2.06", -2.0577, True), ("-2.06", -2.0649, True), ("-2.06", 2.06, False),
    ("3", float("nan"), False),
    # a power of ten: the mantissa's decimals, scaled
    ("5.5·10⁻⁷", 5.52e-7, True), ("5.5·10⁻⁷", 5.56e-7, False), ("1.0·10⁻⁵", 1.045e-5, True),
    ("1.0·10⁻⁵", 1.06e-5, False), ("2·10³", 2400.0, True), ("2·10³", 2600.0, False)])
def test_a_quoted_number_is_its_cell_rounded_to_the_quoted_decimals(results_page, quoted, value,
                                                                     matches):
    assert results_page.quoted_number_matches(quoted, value) is matches


def test_a_wrong_or_ambiguous_quote_is_reported(results_page):
    correct = results_page.check_quotes("page", "0.796<!-- fig4c.csv gait=A1+A4 sim_speed_mm_s -->")
    assert correct == []
    wrong = results_page.check_quotes("page", "0.797<!-- fig4c.csv gait=A1+A4 sim_speed_mm_s -->")
    assert [(m.quoted, float(m.expected)) for m in wrong] == [("0.797", pytest.approx(0.79583, abs=1e-5))]
    negated = results_page.check_quotes(
        "page", "5.805<!-- fig4c.csv gait=A1+A3 sim_signed_speed_mm_s neg -->"
                " 5.805<!-- fig4c.csv gait=A1+A3 sim_signed_speed_mm_s -->")
    assert [m.quoted for m in negated] == ["5.805"] and "-5.80" in negated[0].expected
    ambiguous = results_page.check_quotes("page", "0.1<!-- fig4c.csv status=ok sim_speed_mm_s -->")
    assert len(ambiguous) == 1 and "5 rows match" in ambiguous[0].expected
    unknown = results_page.check_quotes("page", "1<!-- fig4c.csv gait=A1 no_such_column -->")
    assert len(unknown) == 1 and "no column 'no_such_column'" in unknown[0].expected


def test_every_marker_is_read_or_reported(results_page):
    """A selector value with spaces is read in quotes and a column may hold '+', or anything
    in quotes; a marker that the pattern cannot read (no number right before it, two spaces,
    an unquoted value with spaces, an unquoted column with a parenthesis) is reported, never
    skipped."""
    polish = 'gradient_fit/set20fired_polish/gradient_fit.csv optimiser="CMA-ES + least-squares"'
    assert results_page.check_quotes("page", f"187.0<!-- {polish} objective -->") == []
    wrong = results_page.check_quotes("page", f"187.9<!-- {polish} objective -->")
    assert [m.quoted for m in wrong] == ["187.9"]
    plus = "calibration_best.csv signed_speed_A1+A2"
    value = float(results_page.cell("calibration_best.csv", {}, "signed_speed_A1+A2"))
    assert results_page.check_quotes("page", f"{value:.3f}<!-- {plus} -->") == []
    assert len(results_page.check_quotes("page", f"{value + 1:.3f}<!-- {plus} -->")) == 1
    # a column of other characters (a sensitivity's) in quotes; unquoted, it is unreadable
    slope = 'sweep_slopes/sweep.csv gait=A1+A2 alpha=1.0 "d(signed_speed_mm_s)/d(alpha)"'
    value = float(results_page.cell("sweep_slopes/sweep.csv", {"gait": "A1+A2", "alpha": "1.0"},
                                    "d(signed_speed_mm_s)/d(alpha)"))
    assert results_page.check_quotes("page", f"{value:.4f}<!-- {slope} -->") == []
    assert [m.quoted for m in results_page.check_quotes(
        "page", f"{value + 1:.4f}<!-- {slope} -->")] == [f"{value + 1:.4f}"]
    for unreadable in (f"{value:.4f}<!-- {slope.replace(chr(34), '')} -->",
                       "0.796 <!-- fig4c.csv gait=A1+A4 sim_speed_mm_s -->",
                       "0.796<!-- fig4c.csv  gait=A1+A4 sim_speed_mm_s -->",
                       "187.0<!-- gradient_fit/set20fired_polish/gradient_fit.csv "
                       "optimiser=CMA-ES + least-squares objective -->"):
        problems = results_page.check_quotes("page", unreadable)
        assert [m.what for m in problems] == ["unreadable marker"], unreadable


def test_a_hand_edited_generated_table_is_reported(results_page, tmp_path):
    text = "<!-- generated: fig4c_table -->\n| stale |\n<!-- end generated -->\n"
    regenerated = results_page.regenerate_blocks(text)
    assert "| stale |" not in regenerated
    assert "| A1+A4 | 0.796 | 0.852 | **forward** | 3.349 ± 0.50 | reverse |" in regenerated


def test_a_sidecar_with_vector_sets_and_caches_names_the_widest_and_the_last_level(results_page):
    machine = {"cpu_model": "Some CPU", "cores": 2, "gpus": [],
               "vector_extensions": ["sse2", "avx", "avx2", "avx512f"],
               "caches": {"L1d": "48K", "L1i": "64K", "L2": "2048K", "L3": "491520K"}}
    text = results_page._provenance({"command": "python -m studies bench", "machine": machine})
    assert text.endswith("Some CPU, 2 cores, avx512f, L3 491520K")
    # a sidecar from before they were recorded reads as it did
    older = {key: machine[key] for key in ("cpu_model", "cores", "gpus")}
    assert results_page._provenance({"machine": older}).endswith("Some CPU, 2 cores")


def test_every_committed_table_has_its_provenance_sidecar():
    """Results record how they were made: two committed CSVs had no sidecar (an audit,
    2026-12; theirs are now written from the tables' own columns, with a note saying so)."""
    without = [path.relative_to(REPO).as_posix() for path in sorted((REPO / "results").rglob("*.csv"))
               if not path.with_name(path.name + ".json").exists()]
    assert without == []


def test_a_sidecars_note_is_shown_with_its_provenance(results_page):
    text = results_page._provenance({"command": "python -m studies bench", "git_commit": "abc1234f",
                                     "note": "written after the run"})
    assert text == "`python -m studies bench`; commit abc1234; note: written after the run"
