"""
One learning run: moved to ``sb3_classic.harness.runner``, re-exported here so that
``from benchmarks.runner import run_one`` keeps working (patch the names there, not here).
"""

from sb3_classic.harness.runner import (
    EPISODES_FILE,
    EVALUATIONS_FILE,
    RUN_FILE,
    ClusterError,
    ProgressCallback,
    ProgressQueue,
    RunError,
    RunResult,
    TimedEvalCallback,
    episodes_from_monitors,
    evaluations_frame,
    execute_run,
    init_worker,
    load_run,
    run_in_worker,
    run_one,
    store_failure,
    store_run,
)

__all__ = [
    "EPISODES_FILE",
    "EVALUATIONS_FILE",
    "RUN_FILE",
    "ClusterError",
    "ProgressCallback",
    "ProgressQueue",
    "RunError",
    "RunResult",
    "TimedEvalCallback",
    "episodes_from_monitors",
    "evaluations_frame",
    "execute_run",
    "init_worker",
    "load_run",
    "run_in_worker",
    "run_one",
    "store_failure",
    "store_run",
]
