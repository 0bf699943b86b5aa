"""Input files named on the command line (plan's and gait_design's --primitives, gradient_fit's
--start, model_select's --candidates, elasticities' --sobol and its sidecar), the parameter
names of --vary and --fit, and plan's flags of a measurement that --primitives replaces:
refused before any compute and before the output folder is made, in one line naming the flag,
the file and what is wrong, exit code 2, no traceback (each case below crashed with a
traceback, printed a warning before its refusal, left out the flag, or ran a malformed table
to the end: an audit, 2026-12); and the input just inside each limit accepted."""

import json
import warnings
from types import SimpleNamespace

import pandas as pd
import pytest

from taichi_star.provenance import table_stamp

from studies import cli, elasticities, identify, plan
from studies.__main__ import main as studies_main

COMMITTED_PRIMITIVES = cli.COMMITTED_RESULTS / "primitives.csv"
"""Made at the paper preset's period (3.15 s) and dt (1 ms, plan's without --quick), glides
measured, every gait of status ok; rows A1, A2, ... first."""
PNG_BYTES = b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR"
"""The start of a PNG: not UTF-8 from its first byte."""


class PastTheChecks(Exception):
    """The study got past its input checks (its next step is stubbed: nothing runs)."""


def stop_at_output(*args, **kwargs):
    """A stand-in for cli.Output, a study's first step after its checks: raises PastTheChecks
    with the details the study would record (gait_design's direction among them)."""
    raise PastTheChecks(kwargs.get("extra"))


def primitives(tmp_path, changes=(), columns=None):
    """A copy of the committed primitives table (its `columns` only, default all) with the
    cells of `changes` ((row, column, value), row a label or a slice) set, without the
    committed sidecar."""
    table = pd.read_csv(COMMITTED_PRIMITIVES).astype(object)
    if columns is not None:
        table = table[columns]
    for row, column, value in changes:
        table.loc[row, column] = value
    path = tmp_path / "primitives.csv"
    table.to_csv(path, index=False)
    return path


def refusal(argv, tmp_path, capsys) -> str:
    """The study's one-line refusal (exit code 2, no output folder), after its prefix."""
    out = tmp_path / "out"
    assert studies_main([*argv, "--out", str(out), "--no-progress"]) == 2
    error = capsys.readouterr().err
    assert len(error.strip().splitlines()) == 1 and "Traceback" not in error, error
    assert not out.exists()
    return error.strip().split(": error: ", 1)[1]


WITHOUT_GLIDES = [column for column in pd.read_csv(COMMITTED_PRIMITIVES, nrows=0).columns
                  if not column.startswith("glide")]
"""A table the planner warns about (no glides): its warning came before a refusal."""
NAN = float("nan")


# --------------------------------------------------------------------------- plan --primitives

@pytest.mark.parametrize("changes, columns, message", [
    # a ValueError traceback (float() of the first row's period)
    ([(0, "period_s", "abc")], None, "period_s of gait A1 is 'abc', not a number"),
    # a TypeError traceback from the planner's isfinite
    ([(3, "step_x_mm", "abc")], None, "step_x_mm of gait A4 is 'abc', not a number"),
    # a measured gait (status ok) with a NaN step_y_mm: refused after the planner's warning
    # of a table without glides (the planner's checks, `PrimitiveModel.from_table`)
    ([(3, "step_y_mm", NAN)], WITHOUT_GLIDES, "step_y_mm of gait A4 is nan, not a finite "
                                              "number (status ok)"),
    ([(3, "glide2_y_mm", float("inf"))], None, "glide2_y_mm of gait A4 is inf, not a finite "
                                               "number (status ok)"),
    ([(3, "gait", "Z9")], WITHOUT_GLIDES, "gait 'Z9': unknown actuator 'Z9' (allowed: \"none\" "
                                          "or actuators \"A1\"..\"A8\" joined by \"+\", each at "
                                          "most once)"),
    ([(3, "gait", "A1")], None, "gaits must name each gait once, got A1 more than once"),
    ([(slice(None), "status", "diverged")], None, "gaits must name at least one gait other than "
                                                  "'none' (from a primitive table: its rows of "
                                                  "status ok), got []"),
    # only the first row's period and step were compared with the run's
    ([(5, "period_s", 3.2)], None, "made at period 3.2 s, dt 0.001 s (gait A6); this run has "
                                   "3.15 s, 0.001 s"),
    ([], ["gait", "step_x_mm", "step_y_mm", "turn_deg", "period_s", "dt_s"],
     "not a primitives table (needs rows with ['dt_s', 'gait', 'period_s', 'status', "
     "'step_x_mm', 'step_y_mm', 'turn_deg']; no status)"),
])
def test_plan_refuses_a_malformed_primitives_table(no_compute, tmp_path, capsys, changes,
                                                   columns, message):
    path = primitives(tmp_path, changes, columns)
    with warnings.catch_warnings():
        # the planner's warning of a table without glides, two lines, came before the refusal
        warnings.simplefilter("error", RuntimeWarning)
        assert refusal(["plan", "--primitives", str(path)], tmp_path, capsys) == \
            f"--primitives {path}: {message}"


def test_plan_reads_the_tables_just_inside_the_checks(tmp_path):
    """The committed table makes a model of all its gaits; a gait that failed (status not ok)
    may have NaN steps and is left out, and so is one of status ok without a steady step (the
    planner's rule); one gait of status ok is enough."""
    assert len(plan.read_primitive_model(COMMITTED_PRIMITIVES, 3.15, 1e-3).gaits) == 256
    failed = primitives(tmp_path, [(3, "status", "diverged"), (3, "step_x_mm", NAN),
                                   (3, "step_y_mm", NAN)])
    model = plan.read_primitive_model(failed, 3.15, 1e-3)
    assert "A4" not in model.gaits and len(model.gaits) == 255
    unsteady = primitives(tmp_path, [(3, "step_x_mm", NAN)])
    assert "A4" not in plan.read_primitive_model(unsteady, 3.15, 1e-3).gaits
    one = primitives(tmp_path, [(slice(1, None), "status", "diverged")])
    assert plan.read_primitive_model(one, 3.15, 1e-3).gaits == ["none", "A1"]


def test_plan_reads_a_primitives_table_a_study_wrote_at_a_step_of_many_digits(tmp_path):
    """A study's table kept dt_s to 10 digits, so a table made at a step of 3.15/1100 s (a
    whole number of steps per period, as plan asks) was refused as made at another step (an
    audit): `Output.write_csv` now writes it exactly (`cli.EXACT_SETTING_COLUMNS`)."""
    dt = 3.15 / 1100
    assert float(f"{dt:.10g}") != dt  # the step the table lost
    table = pd.read_csv(COMMITTED_PRIMITIVES).assign(dt_s=dt)
    out = cli.Output(SimpleNamespace(study="primitives", out=str(tmp_path), quick=False), [])
    path = out.write_csv(table, "primitives.csv")
    assert pd.read_csv(path)["dt_s"].eq(dt).all()
    assert len(plan.read_primitive_model(path, 3.15, dt).gaits) == 256


@pytest.mark.parametrize("flags, flag", [
    (["--cycles", "3"], "--cycles"),
    (["--glide-cycles=0"], "--glide-cycles"),
    # refused by plan's own range (>= 2) before, though the table replaced the measurement
    (["--cycles", "1"], "--cycles"),
])
def test_plan_refuses_the_measurement_flags_with_primitives(no_compute, tmp_path, capsys, flags,
                                                            flag):
    """--cycles and --glide-cycles set the measurement that --primitives replaces: they were
    ignored, yet range-checked; now refused with it."""
    assert refusal(["plan", "--primitives", str(COMMITTED_PRIMITIVES), *flags], tmp_path,
                   capsys) == (f"{flag}: not with --primitives (it sets the primitives' "
                               f"measurement, which the table given replaces)")


@pytest.mark.parametrize("flags", [
    ["--primitives", str(COMMITTED_PRIMITIVES)],
    # --quick's defaults of the two flags are not flags given; --dt keeps the table's step
    ["--primitives", str(COMMITTED_PRIMITIVES), "--quick", "--dt", "1e-3"],
    ["--cycles", "3", "--glide-cycles", "0", "--quick"],
])
def test_plan_takes_primitives_or_the_measurement_flags(no_compute, monkeypatch, tmp_path,
                                                        flags):
    monkeypatch.setattr(cli, "Output", stop_at_output)
    with pytest.raises(PastTheChecks):
        studies_main(["plan", *flags, "--out", str(tmp_path / "out"), "--no-progress"])


# --------------------------------------------------------------------------- gait_design

@pytest.mark.parametrize("changes, message", [
    # ran 43 s and exited 0
    ([(3, "step_mm", "abc")], "step_mm of gait A4 is 'abc', not a number"),
    # a traceback from idxmax
    ([(slice(None), "step_mm", NAN)], "no gait whose step_mm, direction_deg, step_x_mm, "
                                      "step_y_mm and turn_deg are all finite"),
])
def test_gait_design_refuses_a_malformed_primitives_table(no_compute, tmp_path, capsys, changes,
                                                          message):
    path = primitives(tmp_path, changes)
    assert refusal(["gait_design", "--quick", "--primitives", str(path)], tmp_path, capsys) == \
        f"--primitives {path}: {message}"


def test_gait_design_takes_its_direction_from_the_fastest_usable_gait(no_compute, monkeypatch,
                                                                      tmp_path):
    """One gait with every number finite is enough, and the direction is the fastest such
    gait's: NaN step_mm in every row but A1's leaves A1 (about 0 deg; the table's fastest gait,
    A1+A2+A3+A4+A5+A7, goes at 90 deg)."""
    path = primitives(tmp_path, [(slice(1, None), "step_mm", NAN)])
    monkeypatch.setattr(cli, "Output", stop_at_output)
    with pytest.raises(PastTheChecks) as stopped:
        studies_main(["gait_design", "--quick", "--primitives", str(path), "--out",
                      str(tmp_path / "out"), "--no-progress"])
    a1 = pd.read_csv(COMMITTED_PRIMITIVES).iloc[0]
    assert stopped.value.args[0]["direction_deg"] == pytest.approx(a1["direction_deg"])


# --------------------------------------------------------------------------- CSV files

@pytest.mark.parametrize("content, problem", [
    (b"", "empty (not even a header row)"),
    (b"\n\n", "empty (not even a header row)"),
    (PNG_BYTES, "not a UTF-8 text file (byte 0x89 at 0: invalid start byte)"),
    # pandas' message ends in a newline: two lines on stderr
    (b"field,value\nalpha,1\nbeta,1,2,3\n", "cannot read it (Error tokenizing data. C error: "
                                            "Expected 2 fields in line 3, saw 4)"),
])
@pytest.mark.parametrize("study, flag", [("gradient_fit", "--start"),
                                         ("model_select", "--candidates")])
def test_a_file_that_is_no_csv_is_refused(no_compute, tmp_path, capsys, content, problem, study,
                                          flag):
    path = tmp_path / "table.csv"
    path.write_bytes(content)
    assert refusal([study, "--quick", flag, str(path)], tmp_path, capsys) == \
        f"{flag} {path}: {problem}"


def test_a_header_alone_is_read_and_refused_as_a_table_without_rows(no_compute, tmp_path,
                                                                    capsys):
    """Just inside the empty file: a header is a CSV, and --start's own check says it has no
    rows."""
    path = tmp_path / "identified.csv"
    path.write_text("field,value\n")
    assert refusal(["gradient_fit", "--quick", "--start", str(path)], tmp_path, capsys) == \
        f"--start {path}: no rows"
    # --candidates' header alone ended in an IndexError's traceback, --sobol's in a table whose
    # every S1 and ST was empty (an audit, 2026-12)
    candidates = tmp_path / "candidates.csv"
    candidates.write_text("name,set,fit,description\n")
    assert refusal(["model_select", "--quick", "--candidates", str(candidates)], tmp_path,
                   capsys) == "--candidates: no candidates (the table has no rows)"
    sobol = tmp_path / "sobol.csv"
    sobol.write_text("gait,parameter,S1,S1_conf,ST,ST_conf\n")
    assert refusal(["elasticities", "--quick", "--sobol", str(sobol)], tmp_path, capsys) == \
        f"--sobol {sobol}: no rows (a header alone)"


# --------------------------------------------------------------------------- elasticities --sobol

REMOVE_IT = "; remove sobol.csv.json to use the table without its preset"
"""How a refused --sobol sidecar's message ends: the table is served without it."""


@pytest.mark.parametrize("sidecar, message", [
    ("[1]", "{sidecar}: no taichi_star provenance in it (not a JSON object)" + REMOVE_IT),
    ("{", "{sidecar}: no taichi_star provenance in it (JSONDecodeError: Expecting property name "
          "enclosed in double quotes: line 1 column 2 (char 1))" + REMOVE_IT),
    (None, "{table}: its provenance sidecar {sidecar} cannot be read (Is a directory)"),
])
def test_elasticities_refuses_a_sobol_sidecar_that_is_no_record(no_compute, tmp_path, capsys,
                                                                sidecar, message):
    table = tmp_path / "sobol.csv"
    table.write_bytes((cli.COMMITTED_RESULTS / "sensitivity.csv").read_bytes())
    path = tmp_path / "sobol.csv.json"
    if sidecar is None:  # a folder
        path.mkdir()
    else:
        path.write_text(sidecar)
    assert refusal(["elasticities", "--quick", "--sobol", str(table)], tmp_path, capsys) == \
        "--sobol " + message.format(table=table, sidecar=path)


def test_elasticities_refuses_a_sobol_table_edited_since_its_sidecar(no_compute, tmp_path,
                                                                    capsys):
    """The sidecar's preset is that of the indices it describes by their SHA-256: a table
    edited since (its values, or another table beside the sidecar) is not labelled with it.
    Served without it once the sidecar is removed."""
    table = tmp_path / "sobol.csv"
    data = (cli.COMMITTED_RESULTS / "sensitivity.csv").read_bytes()
    table.write_bytes(data)
    (tmp_path / "sobol.csv.json").write_text(json.dumps(
        {"model": {"preset": "accurate"}, **table_stamp(0, data)}))
    assert elasticities.sobol_table(table)[1] == "accurate"  # the table it describes
    table.write_bytes(data.replace(b"A1+A3", b"A1+A4", 1))
    assert refusal(["elasticities", "--quick", "--sobol", str(table)], tmp_path, capsys) == \
        (f"--sobol {table}: not the table its provenance sobol.csv.json describes (its SHA-256 "
         f"differs: damaged or edited since it was written)" + REMOVE_IT)
    (tmp_path / "sobol.csv.json").unlink()
    assert elasticities.sobol_table(table)[1] == ""


@pytest.mark.parametrize("sidecar, preset", [
    (None, ""),
    ("{}", ""),
    ('{"model": [1]}', ""),
    ('{"model": {"preset": "accurate"}}', "accurate"),
])
def test_a_sobol_sidecar_that_is_a_record_gives_its_preset(tmp_path, sidecar, preset):
    table = tmp_path / "sobol.csv"
    table.write_bytes((cli.COMMITTED_RESULTS / "sensitivity.csv").read_bytes())
    if sidecar is not None:
        (tmp_path / "sobol.csv.json").write_text(sidecar)
    sobol, recorded = elasticities.sobol_table(table)
    assert recorded == preset and list(sobol.columns) == ["gait", "parameter",
                                                         *elasticities.SOBOL_COLUMNS]


def test_elasticities_refuses_a_sobol_table_without_its_columns(no_compute, tmp_path, capsys):
    assert refusal(["elasticities", "--quick", "--sobol", str(COMMITTED_PRIMITIVES)], tmp_path,
                   capsys) == (f"--sobol {COMMITTED_PRIMITIVES}: not a Sobol table with columns "
                               f"gait, parameter, S1, S1_conf, ST, ST_conf (no parameter, S1, "
                               f"S1_conf, ST, ST_conf)")


# --------------------------------------------------------------------------- --vary, --fit

@pytest.mark.parametrize("study, flag", [("sensitivity", "--vary"), ("calibrate", "--fit")])
def test_an_unknown_parameter_is_named_with_its_flag(no_compute, tmp_path, capsys, study, flag):
    fittable = identify.fittable_fields()
    # the fields a box may vary, not every StarParams field
    assert "gait" not in fittable and "n_arc" not in fittable
    assert {"alpha", "cooling_time", "actuator_gains[INDEX]"} <= set(fittable)
    assert refusal([study, "--quick", flag, "foo=1:2"], tmp_path, capsys) == \
        f"{flag}: unknown parameter 'foo'; fittable fields: {', '.join(fittable)}"
    assert refusal([study, "--quick", flag, "alpa=1:2"], tmp_path, capsys) == \
        f"{flag}: unknown parameter 'alpa'; did you mean alpha?"
    # a field that is known but not fittable keeps its own refusal
    assert refusal([study, "--quick", flag, "gait=1:2"], tmp_path, capsys).startswith(
        f"{flag} gait: not a real-valued numeric field (fix it with --set); fittable fields: ")
