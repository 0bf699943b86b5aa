"""The provenance sidecars the studies read, through `taichi_star.output.read_provenance`, which
checks the table's SHA-256 against its sidecar: of a table the run wrote (plot titles:
`cli.run_settings`, simd's; a sidecar damaged or describing another table is a one-line error
naming the file; model_select --reassess's earlier run's table: in test_model_select.py) and of
a table the user gives (plan --primitives: read as a table without a sidecar, and that is said;
elasticities --sobol: refused, in test_cli_input_files.py)."""

import json
import re
import types

import pandas as pd
import pytest

from taichi_star import SolverConfig, StarParams

from studies import cli, plan, provenance, simd

COMMITTED_PRIMITIVES = cli.COMMITTED_RESULTS / "primitives.csv"
EDITED = ("not the table its provenance {name} describes (its SHA-256 differs: damaged or "
          "edited since it was written)")
"""`read_provenance`'s reason for a table whose sidecar describes it before an edit."""


def output(tmp_path, **record) -> cli.Output:
    """The output folder `tmp_path`/out of a study run, whose tables `write_csv` writes with
    their stamped sidecars; `record`: model, solver, extra."""
    args = types.SimpleNamespace(study="sweep", out=str(tmp_path / "out"), quick=False)
    return cli.Output(args, [], **record)


def damage(sidecar):
    """Cut the sidecar's JSON in half."""
    text = sidecar.read_text()
    sidecar.write_text(text[:len(text) // 2])


# --------------------------------------------------------------------------- the run's own tables

def test_a_plot_title_is_read_from_the_sidecar_of_the_table_it_describes(tmp_path):
    out = output(tmp_path, model={"preset": "paper", "params": StarParams.preset("paper")},
                 solver=SolverConfig(dt=2e-3))
    csv = out.write_csv(pd.DataFrame({"speed_mm_s": [1.5, 2.5]}), "sweep.csv")
    assert cli.run_settings(csv) == "paper preset, n_arc 18, euler h = 2 ms"
    data, sidecar = csv.read_bytes(), provenance.sidecar_path(csv)
    csv.write_bytes(data.replace(b"1.5", b"1.6"))  # another run's table beside this sidecar
    edited = f"{csv}: {EDITED.format(name=sidecar.name)}"
    with pytest.raises(cli.StudyOutputError, match=f"^{re.escape(edited)}$"):
        cli.run_settings(csv)
    csv.write_bytes(data)
    damage(sidecar)
    with pytest.raises(cli.StudyOutputError, match=rf"^{re.escape(str(sidecar))}: no taichi_star "
                                                   r"provenance in it \(JSONDecodeError: "):
        cli.run_settings(csv)
    sidecar.unlink()
    sidecar.mkdir()
    with pytest.raises(cli.StudyOutputError,
                       match=rf"^{re.escape(str(sidecar))}: cannot read it \(Is a directory\)$"):
        cli.run_settings(csv)
    sidecar.rmdir()
    assert cli.run_settings(csv) == ""  # none: no title


def speedups(out):
    """A simd table of one panel (today's form and one grouped form), written by `out`."""
    return out.write_csv(pd.DataFrame({
        "preset": ["paper", "paper"], "precision": ["f64", "f64"], "n_slots": [1, 1],
        "form": ["instance_major", "lane_vector"], "lanes": [1, 4], "batch_size": [8, 8],
        "speedup_median_of_rounds": [1.0, 1.25]}), "simd.csv")


def test_simd_titles_its_plot_from_the_tables_sidecar(tmp_path, monkeypatch):
    titles = []
    monkeypatch.setattr(cli, "write_figure",
                        lambda fig, path, **kwargs: titles.append(fig.get_suptitle()))
    out = output(tmp_path, model={"presets": ["paper"]})
    csv = speedups(out)
    facts = json.loads(provenance.sidecar_path(csv).read_text())
    simd.plot_speedups(csv, tmp_path / "simd.png")
    assert titles == [f"{facts['machine']['cpu_model']}, commit {str(facts['git_commit'])[:7]}"]
    csv.write_bytes(csv.read_bytes().replace(b"1.25", b"1.5"))
    with pytest.raises(cli.StudyOutputError, match=re.escape(EDITED.format(name="simd.csv.json"))):
        simd.plot_speedups(csv, tmp_path / "simd.png")
    provenance.sidecar_path(csv).unlink()
    simd.plot_speedups(csv, tmp_path / "simd.png")
    assert titles[-1] == ""  # no sidecar: no title


# --------------------------------------------------------------------------- the user's tables

def test_plan_compares_a_field_its_sidecar_does_not_record_at_its_default(tmp_path):
    """A table's sidecar written before a field existed (the committed table's, until its
    rerun, predated wake_coupling and four other fields) does not record it: such fields were
    skipped, so --set wake_coupling=5 (A1+A3's first step 31 % shorter) planned with the
    paper robot's steps without a word (an audit, 2026-12). A field the sidecar does not
    record is compared at its default: the paper robot passes, the other is refused naming
    the field."""
    paper = StarParams.preset("paper")
    older = {name: value for name, value in provenance.plain(paper).items()
             if name != "wake_coupling"}
    path = output(tmp_path, model={"preset": "paper", "params": older}).write_csv(
        pd.read_csv(COMMITTED_PRIMITIVES), "primitives.csv")
    recorded = json.loads(provenance.sidecar_path(path).read_text())["model"]["params"]
    assert "wake_coupling" not in recorded
    assert len(plan.read_primitive_model(path, 3.15, 1e-3, base=paper).gaits) == 256
    with pytest.raises(cli.StudyArgumentError, match=re.escape(
            "measured on a robot whose wake_coupling is 0.0, this run's 5.0 (1 field(s) "
            "differ")):
        plan.read_primitive_model(path, 3.15, 1e-3, base=paper.replace(wake_coupling=5.0))


def test_plan_compares_the_robot_only_of_a_sidecar_that_describes_the_primitives(tmp_path,
                                                                                 capsys):
    """A sidecar records the robot its table was measured on: another robot's is refused (an
    audit); once the table is edited (a gait left out) or the sidecar damaged, the record no
    longer vouches for it, and the table is read as one without a sidecar, which is said."""
    paper = StarParams.preset("paper")
    out = output(tmp_path, model={"preset": "paper", "params": paper.replace(alpha=1.2)})
    path = out.write_csv(pd.read_csv(COMMITTED_PRIMITIVES), "primitives.csv")
    with pytest.raises(cli.StudyArgumentError, match=re.escape(
            f"--primitives {path}: measured on a robot whose alpha is 1.2, this run's 0.8 (1 "
            f"field(s) differ")):
        plan.read_primitive_model(path, 3.15, 1e-3, base=paper)
    assert capsys.readouterr().out == ""
    lines = path.read_text().splitlines(keepends=True)
    assert lines[4].startswith("A4,")
    path.write_text("".join(lines[:4] + lines[5:]))  # A4 left out
    model = plan.read_primitive_model(path, 3.15, 1e-3, base=paper)
    assert len(model.gaits) == 255 and "A4" not in model.gaits
    assert capsys.readouterr().out == (f"--primitives {path}: "
                                       f"{EDITED.format(name='primitives.csv.json')}; the robot "
                                       f"it was measured on is not compared with this run's\n")
    sidecar = provenance.sidecar_path(path)
    damage(sidecar)
    assert len(plan.read_primitive_model(path, 3.15, 1e-3, base=paper).gaits) == 255
    assert capsys.readouterr().out.startswith(f"--primitives {sidecar}: no taichi_star "
                                              f"provenance in it (JSONDecodeError: ")
    # without a sidecar (a table copied alone) the same is said (it planned silently: an audit)
    sidecar.unlink()
    assert len(plan.read_primitive_model(path, 3.15, 1e-3, base=paper).gaits) == 255
    assert capsys.readouterr().out == (f"--primitives {path}: no sidecar primitives.csv.json "
                                       f"beside it; the robot it was measured on is not compared "
                                       f"with this run's\n")
