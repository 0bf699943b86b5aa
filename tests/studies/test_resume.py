"""Resumable sweeps: a sweep killed with SIGKILL after its first chunks and then resumed gives,
row for row and bit for bit, the table of an uninterrupted run; a run store refuses a different
sweep definition and an unfinished run without --resume, before any compute."""

import json
import logging
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from studies import sweep
from studies.__main__ import main as studies_main

REPO = Path(__file__).resolve().parents[2]
# 16 instances in 8 chunks of 2 (one compiled engine), 1.2 s of 2 ms steps each (~0.2 s a
# chunk here: the kill, 5 ms after the first chunk file appears, lands well before the last)
SWEEP = ["--gaits", "A1,A1+A3", "--alpha", "0.4:1.2:8", "--period", "0.3", "--cycles", "4",
         "--dt", "0.002", "--chunk-size", "2", "--no-progress"]
N_INSTANCES, N_CHUNKS = 16, 8


def chunk_files(folder):
    return sorted(Path(folder).glob("chunk_*.parquet"))


@pytest.mark.slow
def test_killed_sweep_resumes_to_the_uninterrupted_table(tmp_path, capsys, caplog, monkeypatch):
    killed_out = tmp_path / "killed"
    run_dir = tmp_path / "run"
    process = subprocess.Popen(
        [sys.executable, "-m", "studies", "sweep", *SWEEP, "--out", str(killed_out),
         "--run-dir", str(run_dir)],
        cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120
        while not chunk_files(run_dir):
            assert process.poll() is None, process.stderr.read().decode()
            assert time.monotonic() < deadline, "no chunk written in 120 s"
            time.sleep(0.005)
        os.kill(process.pid, signal.SIGKILL)
        process.wait(timeout=30)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
        process.stderr.close()
    assert process.returncode == -signal.SIGKILL
    done = chunk_files(run_dir)
    assert 1 <= len(done) < N_CHUNKS, f"{len(done)} chunks done: the kill came too late"
    manifest = json.loads((run_dir / "manifest.json").read_text())
    assert manifest["complete"] is False and manifest["definition"]["n_chunks"] == N_CHUNKS
    assert manifest["definition"]["n_instances"] == N_INSTANCES and manifest["code"]["version"]
    assert not (killed_out / "sweep.csv").exists()

    # before any compute: no mixing in of another definition, no silent restart
    def forbidden(*args, **kwargs):
        raise AssertionError("simulate was called despite a refused run folder")
    with monkeypatch.context() as patch:
        patch.setattr("taichi_star.batch.tasks.simulate", forbidden)
        other = [a if a != "0.4:1.2:8" else "0.4:1.2:7" for a in SWEEP]
        assert studies_main(["sweep", *other, "--out", str(killed_out), "--run-dir", str(run_dir),
                             "--resume"]) == 2
        error = capsys.readouterr().err
        assert "another definition" in error and "n_instances" in error
        assert studies_main(["sweep", *SWEEP, "--out", str(killed_out),
                             "--run-dir", str(run_dir)]) == 2
        error = capsys.readouterr().err
        assert "unfinished run" in error and "resume" in error
        # named by the flag the user has (the library's argument, run_dir, before)
        assert f"--run-dir {run_dir} holds an unfinished run" in error, error
        finer = [a if a != "0.002" else "0.001" for a in SWEEP]  # --dt 0.001
        assert studies_main(["sweep", *finer, "--out", str(killed_out),
                             "--run-dir", str(run_dir), "--resume"]) == 2
        assert "solver.dt: 0.002 -> 0.001" in capsys.readouterr().err
    assert chunk_files(run_dir) == done  # nothing touched
    before = {path.name: path.stat().st_mtime_ns for path in done}

    with caplog.at_level(logging.WARNING, logger="taichi_star.batch"):
        resumed = sweep.main([*SWEEP, "--out", str(killed_out), "--run-dir", str(run_dir),
                              "--resume"])
    assert f"{len(done)} of {N_CHUNKS} chunks already done" in caplog.text
    # the finished chunks were not recomputed
    assert {p.name: p.stat().st_mtime_ns for p in done} == before
    assert len(chunk_files(run_dir)) == N_CHUNKS
    assert json.loads((run_dir / "manifest.json").read_text())["complete"] is True

    whole = sweep.main([*SWEEP, "--out", str(tmp_path / "whole")])
    assert resumed["instance"].tolist() == list(range(N_INSTANCES))
    pd.testing.assert_frame_equal(resumed, whole, check_exact=True)
    assert (resumed["status"] == "ok").all()
    resumed_csv = pd.read_csv(killed_out / "sweep.csv")
    pd.testing.assert_frame_equal(resumed_csv, pd.read_csv(tmp_path / "whole" / "sweep.csv"),
                                  check_exact=True)
    assert (tmp_path / "whole" / "chunks" / "manifest.json").exists()
