"""Batches of any size: chunks, executors, the resumable run store.

    from taichi_star.batch import run_batch
    result = run_batch(params, cycles=3, workers=2)   # chunks (of 2048) on two worker processes
    result.summary                                     # one row per instance, input order

- `run_batch`: cut a batch into chunks (`plan_chunks`, `ChunkTask`), run them (`run_chunk`)
  on an executor and gather one `SimulationResult`.
- Executors: `InProcess` (default), `LocalProcesses(n)`, and on Dask `DaskExecutor`
  (`taichi_star.batch.dask_cluster`, with the worker preload `taichi_star.batch.dask_worker`);
  `executor_for(workers=..., scheduler=...)` picks one.
- `read_run(run_dir)`: a stored run's result read back without its arguments (verified;
  read-only; `partial=True` for a run not yet finished).
- `RunStore`: resumable runs (verified Parquet chunks and a manifest); `RunStoreError`;
  `write_atomic`, how it writes every file (whole or not at all).

Dask is imported only when a scheduler is used.
"""

from .executors import (DEFAULT_RETRIES, MAX_LOCAL_WORKERS, MAX_RETRIES, Executor, InProcess,
                        LocalProcesses)
from .run import DEFAULT_CHUNK_SIZE, executor_for, read_run, run_batch
from .store import (RunStore, RunStoreError, code_version, has_chunks, stored_chunk_size,
                    write_atomic)
from .tasks import ChunkResult, ChunkTask, plan_chunks, run_chunk

__all__ = ["run_batch", "read_run", "plan_chunks", "run_chunk", "ChunkTask", "ChunkResult",
           "Executor", "InProcess", "LocalProcesses", "executor_for", "RunStore", "RunStoreError",
           "code_version", "has_chunks", "stored_chunk_size", "write_atomic",
           "DEFAULT_CHUNK_SIZE", "DEFAULT_RETRIES", "MAX_LOCAL_WORKERS", "MAX_RETRIES"]
