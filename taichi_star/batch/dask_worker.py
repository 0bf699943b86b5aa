"""Dask worker preload: configures the worker's Taichi runtime and arch before its first chunk.

    dask worker tcp://HOST:8786 --nthreads 1 --nworkers 4 --preload taichi_star.batch.dask_worker
    dask worker tcp://HOST:8786 --nthreads 1 --preload taichi_star.batch.dask_worker --arch gpu

A worker started with `--arch gpu` runs every chunk it receives on its GPU, whatever the client
asked for; with `--arch auto` (the default) it runs the client's arch. `--taichi-threads` caps
Taichi's CPU threads in the worker process (default 1: one worker process per core scales better
than Taichi's own threads).
"""

from __future__ import annotations

import click

from ..runtime import MAX_CPU_THREADS
from .dask_cluster import prepare_worker


@click.command()
@click.option("--arch", type=click.Choice(["auto", "cpu", "gpu", "cuda", "vulkan", "metal"]),
              default="auto", show_default=True,
              help="Taichi backend of the chunks this worker runs (auto: the client's)")
@click.option("--taichi-threads", type=click.IntRange(1, MAX_CPU_THREADS), default=1,
              show_default=True,
              help="Taichi CPU threads in this worker process")
def dask_setup(worker, arch, taichi_threads):
    prepare_worker(worker, arch=None if arch == "auto" else arch, cpu_threads=taichi_threads)
