"""
The repository's paths and the benchmark's envs; the rest of what a run is lives in ``sb3_classic.harness.common``
and is re-exported here, so that ``from benchmarks.common import RunSpec`` keeps working.
"""

import argparse
import contextlib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import yaml

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
    unknown_setting,
)
from sb3_classic.harness.runner import RunError, check_run

__all__ = [
    "ALL_ALGOS",
    "DEFAULT_CACHE_DIR",
    "DEFAULT_RESULTS_DIR",
    "ENV_IDS",
    "LABELS",
    "OPTIONAL_ENV_IDS",
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
    "overrides_from_args",
    "parse_overrides",
    "register_algorithms",
]

#: The envs of the benchmark (``python -m benchmarks.run``)
ENV_IDS = ("CartPole-v1", "Acrobot-v1")
#: Envs it runs only when ``--envs`` names them (Box2D's, from the ``zoo`` extra)
OPTIONAL_ENV_IDS = ("LunarLander-v3",)

REPO_ROOT = Path(__file__).resolve().parent.parent
#: The package's hyperparameters (rl-zoo3 format), at the repository root (the wheel ships them inside the package)
OUR_HYPERPARAMS_DIR = REPO_ROOT / "hyperparams"
DEFAULT_CACHE_DIR = REPO_ROOT / "benchmarks" / "cache"
DEFAULT_RESULTS_DIR = REPO_ROOT / "benchmarks" / "results"
#: Where ``--quick`` writes its tables and plots: scratch, git-ignored with the cache
QUICK_RESULTS_DIR = DEFAULT_CACHE_DIR / "quick-results"


def parse_overrides(values: Sequence[str], algos: Sequence[str]) -> dict[str, dict[str, Any]]:
    """
    :param values: ``ALGO.KEY=VALUE``, each value read as YAML (``10.0`` and ``5e-4`` floats, ``lin_1e-3`` a string)
    :param algos: the algorithms benchmarked
    :return: per algorithm, the keys to replace in (or add to) its YAML entries
    :raises ValueError: naming the ``--set`` value that is malformed, names an algorithm not benchmarked, or a key
        that is neither an argument of the algorithm nor one the zoo reads (a typo would otherwise fail every run)
    """
    overrides: dict[str, dict[str, Any]] = {}
    for value in values:
        target, equals, text = value.partition("=")
        algo, dot, key = target.partition(".")
        if not (equals and dot and algo and key):
            raise ValueError(f"--set {value!r}: write ALGO.KEY=VALUE, e.g. nstep_sarsa.max_grad_norm=10.0")
        if algo not in algos:
            raise ValueError(f"--set {value!r}: {algo!r} is not one of the algorithms benchmarked ({', '.join(algos)})")
        if key == "n_timesteps":
            raise ValueError(f"--set {value!r}: the env steps per run are the command's --budget (or --steps)")
        unknown = unknown_setting(algo, key)
        if unknown is not None:
            raise ValueError(f"--set {value!r}: {unknown}")
        parsed = yaml.safe_load(text)
        if isinstance(parsed, str):
            # YAML 1.1 reads 5e-4 (no dot) as a string, which the zoo would then take for a schedule name
            with contextlib.suppress(ValueError):
                parsed = float(text)
        overrides.setdefault(algo, {})[key] = parsed
    return overrides


def overrides_from_args(
    parser: argparse.ArgumentParser, values: Sequence[str], results_dir: Path | None, algos: Sequence[str]
) -> dict[str, dict[str, Any]]:
    """
    The ``--set`` of a benchmark command: ``parse_overrides``, with its errors and a missing ``--results-dir`` reported
    as the parser's (the committed results stay those of the YAML entries as they are).

    :param parser: the command's parser
    :param values: its ``--set`` values
    :param results_dir: its ``--results-dir``
    :param algos: the algorithms it benchmarks
    :return: per algorithm, the keys to replace in its YAML entries
    """
    if values and results_dir is None:
        parser.error("--set needs --results-dir: the default results are those of the YAML entries as they are")
    try:
        return parse_overrides(values, algos)
    except ValueError as error:
        parser.error(str(error))


def check_overridden_settings(specs: Sequence[RunSpec], overrides: Mapping[str, Mapping[str, Any]]) -> list[str]:
    """
    Build the envs and model of each distinct setting that ``--set`` changed (``check_run``, no training), so that a
    value the algorithm rejects (``update_mode=perstep``) fails before any run starts, not in every run of it.

    :param specs: the runs to run
    :param overrides: per algorithm, the keys ``--set`` replaces (``overrides_from_args``)
    :return: the problems, each naming the algorithm, the env and the error
    """
    to_check: dict[tuple[str, str, str], RunSpec] = {}
    for spec in specs:
        if spec.algo in overrides:
            to_check.setdefault((spec.algo, spec.env_id, spec.hyperparams_yaml), spec)
    problems = []
    for spec in to_check.values():
        try:
            check_run(spec)
        except RunError as error:
            problems.append(f"{spec.algo} on {spec.env_id}: {error}")
    return problems
