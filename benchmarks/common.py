"""
The repository's paths and the benchmark's envs; the rest of what a run is lives in ``sb3_classic.harness.common``
and is re-exported here, so that ``from benchmarks.common import RunSpec`` keeps working.
"""

from pathlib import Path

from sb3_classic.harness.common import (
    ALL_ALGOS,
    LABELS,
    OUR_ALGOS,
    PEER_ALGOS,
    THRESHOLDS,
    ZOO_HYPERPARAMS_DIR,
    RunSpec,
    code_versions,
    hyperparams_path,
    load_hyperparams,
    register_algorithms,
)

__all__ = [
    "ALL_ALGOS",
    "DEFAULT_CACHE_DIR",
    "DEFAULT_RESULTS_DIR",
    "ENV_IDS",
    "LABELS",
    "OUR_ALGOS",
    "OUR_HYPERPARAMS_DIR",
    "PEER_ALGOS",
    "QUICK_RESULTS_DIR",
    "REPO_ROOT",
    "THRESHOLDS",
    "ZOO_HYPERPARAMS_DIR",
    "RunSpec",
    "code_versions",
    "hyperparams_path",
    "load_hyperparams",
    "register_algorithms",
]

#: The envs of the benchmark (``python -m benchmarks.run``)
ENV_IDS = ("CartPole-v1", "Acrobot-v1")

REPO_ROOT = Path(__file__).resolve().parent.parent
#: The package's hyperparameters (rl-zoo3 format), at the repository root (the wheel ships them inside the package)
OUR_HYPERPARAMS_DIR = REPO_ROOT / "hyperparams"
DEFAULT_CACHE_DIR = REPO_ROOT / "benchmarks" / "cache"
DEFAULT_RESULTS_DIR = REPO_ROOT / "benchmarks" / "results"
#: Where ``--quick`` writes its tables and plots: scratch, git-ignored with the cache
QUICK_RESULTS_DIR = DEFAULT_CACHE_DIR / "quick-results"
