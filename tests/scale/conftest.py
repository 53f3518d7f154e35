"""A small local Ray cluster for the ``slow`` Ray tests: 2 CPUs, a 200 MiB object store, no
dashboard; shut down when the module's tests are done. Skipped where ray is not installed."""

from __future__ import annotations

import os

import pytest


@pytest.fixture(scope="module")
def ray_cluster():
    os.environ.setdefault("RAY_DISABLE_IMPORT_WARNING", "1")
    ray = pytest.importorskip("ray")
    ray.init(
        num_cpus=2,
        include_dashboard=False,
        log_to_driver=False,
        object_store_memory=200 * 1024**2,
        logging_level="ERROR",
    )
    try:
        yield ray
    finally:
        ray.shutdown()
