"""Dask worker preload for taichi_star studies: sets the worker's Taichi arch and CPU threads.

    dask worker tcp://HOST:8786 --nthreads 1 --nworkers 4 --preload studies.dask_worker
    dask worker tcp://HOST:8786 --nthreads 1 --preload studies.dask_worker --arch gpu

A worker started with `--arch gpu` runs every chunk it receives on its GPU, whatever the client's
`--arch` (the client's `--arch` still picks the default chunk size); without the preload, or with
`--arch auto`, a worker runs the arch the client asked for. `--taichi-threads` caps Taichi's CPU
threads in the worker process (default 1: one worker process per core scales better than
Taichi's own threads).
"""

from __future__ import annotations

import click

WORKER_ARCH = None
"""The arch this worker process was started with (None: the client's)."""
WORKER_THREADS = None
"""Taichi CPU threads of this worker process (None: 1)."""


@click.command()
@click.option("--arch", type=click.Choice(["auto", "cpu", "gpu", "cuda", "vulkan", "metal"]),
              default="auto", show_default=True,
              help="Taichi backend for the chunks this worker runs (auto: the client's --arch)")
@click.option("--taichi-threads", type=click.IntRange(min=1), default=1, show_default=True,
              help="Taichi CPU threads in this worker process")
def dask_setup(worker, arch, taichi_threads):
    global WORKER_ARCH, WORKER_THREADS
    WORKER_ARCH = None if arch == "auto" else arch
    WORKER_THREADS = taichi_threads
    from .distributed import configure_worker_process
    configure_worker_process(taichi_threads)
