"""
The runs on a Dask cluster: moved to ``sb3_classic.harness.cluster``, re-exported here so that
``from benchmarks.cluster import ...`` keeps working. Importing it imports Dask (the ``dask`` extra).
"""

from sb3_classic.harness.cluster import (
    CONNECT_TIMEOUT_S,
    PROGRESS_TOPIC,
    DaskRuns,
    WorkerProgress,
    check_workers,
    connect,
    harness_digest,
    run_on_worker,
    version_differences,
    worker_versions,
)
from sb3_classic.harness.runner import ClusterError

__all__ = [
    "CONNECT_TIMEOUT_S",
    "PROGRESS_TOPIC",
    "ClusterError",
    "DaskRuns",
    "WorkerProgress",
    "check_workers",
    "connect",
    "harness_digest",
    "run_on_worker",
    "version_differences",
    "worker_versions",
]
