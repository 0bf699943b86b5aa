"""The committed results, as the docs show them: `python tools/results_page.py` regenerates
docs/result_files.md (every CSV in results/ with its provenance sidecar) and every generated block
in README.md and docs/*.md; `python tools/results_page.py --check` changes nothing and exits 1
when a page is out of step with results/ (tests/test_quoted_figures.py runs the same check).

Two markups tie a page's figures to the CSVs:

- a generated block, rewritten from the CSVs by this tool::

      <!-- generated: fig4c_table -->
      | gait | ... |
      <!-- end generated -->

  (the names are the keys of BLOCKS);
- a quoted figure, checked (not rewritten): the number followed by an HTML comment naming its
  cell, ``0.852<!-- fig4c_accurate.csv gait=A1+A4 sim_speed_mm_s -->``: the CSV (relative to
  results/), selectors COLUMN=VALUE that pick exactly one row (compared as the CSV's text;
  ``COLUMN="A VALUE"`` for one with spaces), the column, and optionally a transform of the
  cell: ``abs``, ``neg`` (−value), ``x1000`` (any factor), ``%`` (×100). A column whose name
  holds other characters than letters, digits, ``_`` and ``+`` (a sensitivity's,
  ``d(signed_speed_mm_s)/d(alpha)``) is written in quotes. The number must be
  the cell rounded to the number's decimals (thousands separators and the minus sign −
  allowed; a power of ten as ``5.5·10⁻⁷``).
  Readers see only the number. A comment that names a CSV but does not read as such a marker
  (no number right before it, a stray space) is reported, not skipped.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Dict, List, Optional

import numpy as np
import pandas as pd

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "results"
GENERATED_PAGE = REPO / "docs" / "result_files.md"

BLOCK = re.compile(r"(<!-- generated: (?P<name>\w+) -->\n)(?P<body>.*?)(<!-- end generated -->)",
                   re.S)
QUOTE = re.compile(
    r"(?P<number>[-−+]?\d[\d,]*(?:\.\d+)?(?:·10[⁻]?[⁰¹²³⁴⁵⁶⁷⁸⁹]+)?)<!-- (?P<file>[\w./-]+\.csv)"
    r'(?P<selectors>(?: [\w.]+=(?:"[^"]*"|[^\s="]+))*) (?:"(?P<quoted_column>[^"]+)"|'
    r'(?P<column>[\w+]+))'
    r"(?: (?P<transform>abs|neg|%|x[\d.]+))? -->")
SELECTOR = re.compile(r'([\w.]+)=(?:"([^"]*)"|([^\s="]+))')
"""One selector of a marker: COLUMN=VALUE, or COLUMN="VALUE WITH SPACES"."""
MARKER = re.compile(r"<!-- [\w./-]+\.csv\b.*?-->")
"""Anything that looks like a figure's marker: one QUOTE cannot read is reported, not skipped."""

SMALL_TABLE_ROWS = 12
"""A CSV of at most this many rows is shown whole on the generated page."""


@dataclass(frozen=True)
class Mismatch:
    """One figure or block of a page that its CSV does not give."""
    page: str
    what: str
    quoted: str
    expected: str

    def __str__(self):
        return f"{self.page}: {self.what}: the page says {self.quoted!r}, results/ gives {self.expected!r}"


def read_table(name: str) -> pd.DataFrame:
    """results/<name> with every cell as its text (so selectors compare what the file says);
    parsed once per version of the file (a page quotes one table many times; callers only read
    the frame)."""
    path = RESULTS / name
    status = path.stat()
    return _parsed_table(path, status.st_mtime_ns, status.st_size)


@functools.lru_cache(maxsize=None)
def _parsed_table(path: Path, mtime_ns: int, size: int) -> pd.DataFrame:
    return pd.read_csv(path, dtype=str, keep_default_na=False)


def cell(name: str, selectors: Dict[str, str], column: str) -> str:
    """The text of the one cell of column `column` in the row of results/<name> that
    `selectors` ({column: text}) pick. Raises ValueError unless exactly one row matches."""
    table = read_table(name)
    for key in [*selectors, column]:
        if key not in table.columns:
            raise ValueError(f"{name} has no column {key!r}")
    picked = np.ones(len(table), dtype=bool)
    for key, value in selectors.items():
        picked &= table[key].to_numpy() == value
    rows = np.flatnonzero(picked)
    if len(rows) != 1:
        raise ValueError(f"{name} {selectors}: {len(rows)} rows match, not one")
    return table[column].iat[rows[0]]


def apply_transform(value: float, transform: Optional[str]) -> float:
    if transform is None:
        return value
    if transform == "abs":
        return abs(value)
    if transform == "neg":
        return -value
    if transform == "%":
        return 100.0 * value
    return value * float(transform[1:])


SUPERSCRIPTS = str.maketrans("⁻⁰¹²³⁴⁵⁶⁷⁸⁹", "-0123456789")


def quoted_number_matches(quoted: str, value: float) -> bool:
    """Whether `quoted` (text, e.g. "-1,234.5", or with a power of ten, "5.5·10⁻⁷") is `value`
    rounded to the quoted decimals (of the mantissa, times the power)."""
    text = quoted.replace(",", "").replace("−", "-")
    mantissa, _, power = text.partition("·10")
    scale = 10.0 ** int(power.translate(SUPERSCRIPTS)) if power else 1.0
    decimals = len(mantissa.split(".")[1]) if "." in mantissa else 0
    # half a unit of the last quoted digit, and a hair more for values exactly halfway that the
    # CSV's own rounding put on one side
    return math.isfinite(value) and (abs(float(mantissa) * scale - value)
                                     <= 0.5 * 10.0 ** -decimals * scale * (1 + 1e-9))


def check_quotes(page: str, text: str) -> List[Mismatch]:
    """Every quoted figure of `text` that is not its CSV cell (or names no single cell)."""
    problems = []
    read = {match.start("number") + len(match["number"]) for match in QUOTE.finditer(text)}
    for marker in MARKER.finditer(text):
        if marker.start() not in read:
            problems.append(Mismatch(page, "unreadable marker", marker.group(),
                                     "NUMBER<!-- FILE.csv [COLUMN=VALUE ...] COLUMN "
                                     "[abs|neg|%|xF] --> (a value with spaces, a column with "
                                     "other characters than \\w and +, in quotes)"))
    for match in QUOTE.finditer(text):
        selectors = {key: quoted if quoted or not bare else bare
                     for key, quoted, bare in SELECTOR.findall(match["selectors"])}
        column = match["quoted_column"] or match["column"]
        what = f"{match['file']} {match['selectors'].strip()} {column}".replace("  ", " ")
        try:
            value = apply_transform(float(cell(match["file"], selectors, column)),
                                    match["transform"])
        except (ValueError, FileNotFoundError) as error:
            problems.append(Mismatch(page, what, match["number"], str(error)))
            continue
        if not quoted_number_matches(match["number"], value):
            problems.append(Mismatch(page, what, match["number"], repr(value)))
    return problems


def fixed(value: str, decimals: int) -> str:
    return f"{float(value):.{decimals}f}"


def fig4c_table() -> str:
    """The README's Fig. 4c table: both presets' speeds beside the measurement."""
    paper = read_table("fig4c.csv").set_index("gait")
    accurate = read_table("fig4c_accurate.csv").set_index("gait")
    lines = ["| gait | paper preset (mm/s) | accurate preset (mm/s) | direction (both) "
             "| experiment (mm/s) | paper's direction |",
             "|---|---|---|---|---|---|"]
    for gait, row in paper.iterrows():
        other = accurate.loc[gait]
        direction = row["sim_direction"] if row["sim_direction"] == other["sim_direction"] \
            else f"{row['sim_direction']} / {other['sim_direction']}"
        if direction != row["paper_direction"]:
            direction = f"**{direction}**"
        lines.append(f"| {gait} | {fixed(row['sim_speed_mm_s'], 3)} | "
                     f"{fixed(other['sim_speed_mm_s'], 3)} | {direction} | "
                     # 3 decimals, as speeds.csv holds them (its trailing zeros dropped:
                     # "2.85" beside "3.349" read as less precise; an audit, 2026-12)
                     f"{fixed(row['exp_speed_mm_s'], 3)} ± "
                     f"{fixed(row['exp_cycle_speed_std_mm_s'], 2)} | "
                     f"{row['paper_direction']} |")
    return "\n".join(lines) + "\n"


def thousands(value: str) -> str:
    return f"{float(value):,.0f}"


def bench_batch_table() -> str:
    """docs/performance.md: robot-steps/s per precision × Jacobian (rows) and batch size."""
    table = read_table("bench.csv")
    table = table[table["section"] == "batch"]
    sizes = sorted(set(table["batch_size"]), key=int)
    lines = ["| robot-steps/s, in one process | " + " | ".join(f"B = {size}" for size in sizes) + " |",
             "|---|" + "---|" * len(sizes)]
    for precision in ("f64", "f32"):
        for jacobian in ("newton", "chord"):
            rows = table[(table["precision"] == precision) & (table["jacobian"] == jacobian)]
            by_size = dict(zip(rows["batch_size"], rows["robot_steps_per_s"]))
            lines.append(f"| {precision}, {'Newton' if jacobian == 'newton' else 'chord'} Jacobian | "
                         + " | ".join(thousands(by_size[size]) for size in sizes) + " |")
    return "\n".join(lines) + "\n"


def bench_processes_table() -> str:
    """docs/performance.md: worker processes at B = 512, f64."""
    table = read_table("bench.csv")
    table = table[table["section"] == "processes"]
    lines = ["| robot-steps/s | 1 worker process | 2 worker processes |", "|---|---|---|"]
    for jacobian, label in (("newton", "Newton Jacobian"), ("chord", "chord Jacobian")):
        rows = table[table["jacobian"] == jacobian]
        by_workers = {float(w): v for w, v in zip(rows["workers"], rows["robot_steps_per_s"])}
        lines.append(f"| {label} | {thousands(by_workers[1.0])} | {thousands(by_workers[2.0])} |")
    return "\n".join(lines) + "\n"


def scaling_table() -> str:
    """docs/performance.md: one sweep in process, on worker processes and on Dask workers."""
    labels = {("in-process", "0"): "in process (Taichi threads)", ("processes", "1"): "1 worker process",
              ("dask-local", "1"): "1 Dask worker", ("processes", "2"): "2 worker processes",
              ("dask-local", "2"): "2 Dask workers"}
    lines = ["| mode | wall time, best round | median | speed-up, median of rounds | "
             "same table as in process |", "|---|---|---|---|---|"]
    for _, row in read_table("scaling.csv").iterrows():
        lines.append(f"| {labels[(row['mode'], row['workers'])]} | {float(row['wall_s']):.2f} s | "
                     f"{float(row['wall_s_median']):.2f} s | "
                     f"{float(row['speedup_vs_in_process']):.2f} | "
                     f"{'yes' if row['same_table_as_in_process'] == 'True' else '**no**'} |")
    return "\n".join(lines) + "\n"


BLOCKS: Dict[str, Callable[[], str]] = {
    "fig4c_table": fig4c_table, "bench_batch_table": bench_batch_table,
    "bench_processes_table": bench_processes_table, "scaling_table": scaling_table}
"""Generated blocks by name: each returns its Markdown, ending in a newline."""


def regenerate_blocks(text: str) -> str:
    """`text` with every generated block rewritten from results/."""
    def rewrite(match):
        if match["name"] not in BLOCKS:
            raise ValueError(f"unknown generated block {match['name']!r}; known: {sorted(BLOCKS)}")
        return match.group(1) + BLOCKS[match["name"]]() + match.group(4)
    return BLOCK.sub(rewrite, text)


def _provenance(sidecar: dict) -> str:
    command = sidecar.get("command", "")
    if isinstance(command, list):
        command = " ".join(command)
    parts = [f"`{command}`" if command else "command not recorded"]
    version = sidecar.get("taichi_star_version")
    commit = sidecar.get("git_commit")
    if version:
        parts.append(f"taichi_star {version}")
    if commit:
        parts.append(f"commit {commit[:7]}{' (uncommitted changes)' if sidecar.get('git_dirty') else ''}")
    if sidecar.get("date"):
        parts.append(sidecar["date"][:10])
    machine = sidecar.get("machine") or {}
    note = sidecar.get("note")  # a sidecar written after the run says how it was made
    if machine.get("cpu_model"):
        gpus = ", ".join(gpu if isinstance(gpu, str) else str(gpu.get("name", gpu))
                         for gpu in machine.get("gpus") or [])
        # sidecars since the vector sets and caches were recorded: the widest set, the
        # last-level cache (where a batch's matrices may or may not fit)
        vectors = machine.get("vector_extensions") or []
        caches = machine.get("caches") or {}
        last_level = max(caches, default=None)
        parts.append(f"{machine['cpu_model']}, {machine.get('cores', '?')} cores"
                     + (f", {vectors[-1]}" if vectors else "")
                     + (f", {last_level} {caches[last_level]}" if last_level else "")
                     + (f", {gpus}" if gpus else ""))
    if note:
        parts.append(f"note: {note}")
    return "; ".join(parts)


def _format_cell(text: str) -> str:
    try:
        number = float(text)
    except ValueError:
        return text.replace("|", "\\|")
    if text.lstrip("-").isdigit():
        return text
    return f"{number:.4g}"


def result_files_page() -> str:
    """docs/result_files.md: every CSV under results/, grouped by the study that wrote it, with
    its size, columns (and units), provenance, and the whole table when it is small."""
    entries: Dict[str, List[str]] = {}
    for path in sorted(RESULTS.rglob("*.csv")):
        name = path.relative_to(RESULTS).as_posix()
        sidecar_path = path.with_name(path.name + ".json")
        sidecar = json.loads(sidecar_path.read_text(encoding="utf-8")) if sidecar_path.exists() else {}
        if "runs" in sidecar:  # a merge of several runs: each has its provenance
            runs = sidecar["runs"]
            study = runs[0].get("study", "other")
            provenance = "; ".join(f"run {index + 1}: {_provenance(run)}"
                                   for index, run in enumerate(runs))
        else:
            study = sidecar.get("study", "other")
            provenance = _provenance(sidecar) if sidecar else "no provenance sidecar"
        table = read_table(name)
        units = sidecar.get("units", {})
        columns = ", ".join(f"{column} ({units[column]})" if units.get(column) else column
                            for column in table.columns)
        lines = [f"### `results/{name}`", "",
                 f"{len(table)} rows. Written by {provenance}.", "",
                 f"Columns: {columns}.", ""]
        if len(table) <= SMALL_TABLE_ROWS and len(table.columns) <= 12:
            lines.append("| " + " | ".join(table.columns) + " |")
            lines.append("|" + "---|" * len(table.columns))
            for _, row in table.iterrows():
                lines.append("| " + " | ".join(_format_cell(value) for value in row) + " |")
            lines.append("")
        entries.setdefault(study, []).append("\n".join(lines))
    page = ["# Result files", "",
            "<!-- written by `python tools/results_page.py` from results/*.csv and their "
            "sidecars: do not edit by hand -->", "",
            "Every table in `results/`, grouped by the study that wrote it, with the command, "
            "version, commit, date and machine from its provenance sidecar (`<file>.json`). "
            "Tables of up to 12 rows are shown whole (4 significant digits; the CSV has them "
            "all). The pages that discuss these numbers: [Results](results.md), "
            "[Performance](performance.md), [Reliability](reliability.md).", ""]
    for study in sorted(entries):
        page += [f"## {study}", "", *entries[study]]
    return "\n".join(page).rstrip("\n") + "\n"


def pages() -> List[Path]:
    """The pages that may quote results: README.md and every docs page."""
    return [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]


def check() -> List[Mismatch]:
    """Every figure and block of README.md and docs/*.md out of step with results/."""
    problems = []
    for path in pages():
        text = path.read_text(encoding="utf-8")
        page = path.relative_to(REPO).as_posix()
        expected = result_files_page() if path == GENERATED_PAGE else regenerate_blocks(text)
        if text != expected:
            problems.append(Mismatch(page, "generated text", "(as committed)",
                                     "(regenerate: python tools/results_page.py)"))
        problems += check_quotes(page, text)
    return problems


def write() -> None:
    """Regenerate docs/result_files.md and every generated block."""
    GENERATED_PAGE.write_text(result_files_page(), encoding="utf-8")
    for path in pages():
        text = path.read_text(encoding="utf-8")
        new = regenerate_blocks(text)
        if new != text:
            path.write_text(new, encoding="utf-8")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true",
                        help="change nothing; exit 1 if a page is out of step with results/")
    args = parser.parse_args(argv)
    if not args.check:
        write()
    problems = check()
    for problem in problems:
        print(problem, file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
