"""The Celery application of hockle's workers: ``celery -A worker.app worker`` or ``hockle worker``.

Configuration comes from :mod:`service.settings` (``HOCKLE_`` variables) through
:func:`service.queue.make_celery`, the same function the API uses to enqueue, so both sides agree
on broker, queue and transport options. BLAS/OpenMP threads are pinned here, before numpy can be
imported in this process or in the pool processes forked from it.
"""
from __future__ import annotations

import os

from service.settings import get_settings

settings = get_settings()

BLAS_THREAD_VARIABLES = (
    "OMP_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "MKL_NUM_THREADS",
    "BLIS_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
    "NUMEXPR_NUM_THREADS",
)
for _var in BLAS_THREAD_VARIABLES:
    os.environ[_var] = str(settings.blas_threads)

if settings.worker_nice:
    # lower the CPU priority of this process (and of the pool processes forked from it)
    os.nice(settings.worker_nice)

from service.queue import make_celery  # noqa: E402

app = make_celery(settings, main="worker")
# the worker imports its task module at start (it registers hockle.run_job, a shared_task,
# and the worker signals); the tasks never import this module
app.conf.imports = ("worker.tasks",)
app.conf.update(
    worker_concurrency=settings.worker_concurrency,
    worker_max_tasks_per_child=200,
)

celery = app
