"""A chunk function whose worker process dies where a marker file says so, for the tests of
`LocalProcesses`' deaths (tests/studies/test_batch.py). A spawned worker imports it by name: the
test puts this folder on sys.path, which a spawned process inherits.

The folder `os.environ[FOLDER_VARIABLE]` holds a file `chunk_<index>` for each chunk that is to
kill its worker: "always", or the number of deaths left (one taken each time)."""

import os
from pathlib import Path

from taichi_star.batch.tasks import run_chunk

FOLDER_VARIABLE = "TAICHI_STAR_TEST_DEATHS"


def run_chunk_or_die(task, progress=False):
    """`run_chunk`, unless the marker of `task` says its worker dies (an exit without cleanup,
    as the OOM killer's)."""
    marker = Path(os.environ[FOLDER_VARIABLE]) / f"chunk_{task.index}"
    if marker.exists():
        left = marker.read_text()
        if left == "always":
            os._exit(1)
        if int(left) > 0:
            marker.write_text(str(int(left) - 1))
            os._exit(1)
    return run_chunk(task, progress)
