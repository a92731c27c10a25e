"""
Which runs train in lockstep: the seeds of one setting, as one population of their algorithm (``NStepSARSAPopulation``,
``REINFORCEPopulation``: ``common.population_class``), where the population covers the setting. The planning is here;
``runner.execute_population`` trains a population's runs, and ``pool.run_pending`` sends each population to one worker.
"""

import importlib
import io
import re
from collections.abc import Callable, Sequence
from contextlib import redirect_stderr, redirect_stdout
from dataclasses import replace
from functools import cache
from typing import Any

from sb3_classic.harness.common import RunSpec, population_class
from sb3_classic.harness.runner import built_model


def population_checker(algo: str) -> Callable[[Sequence[Any]], None] | None:
    """:return: the ``check_members`` of ``algo``'s population module (it raises for what it does not cover), or None"""
    population = population_class(algo)
    if population is None:
        return None
    checker: Callable[[Sequence[Any]], None] = importlib.import_module(population.__module__).check_members
    return checker


@cache
def refusal(algo: str, env_id: str, hyperparams_yaml: str) -> str | None:
    """
    Whether a population of ``algo`` covers a setting: one model of it is built as a run builds it (rl-zoo3's
    ``ExperimentManager``, ``runner.check_run``'s way) and given to the population's ``check_members``, the check its
    ``learn`` makes, so that what the harness plans is what the population accepts. Once per setting and process.

    :param algo: the algorithm
    :param env_id: the env
    :param hyperparams_yaml: the zoo YAML entry (a ``RunSpec``'s)
    :return: None if a population covers it, else why not (the population's error, or that the algorithm has none;
        a setting that cannot be built at all is not refused here: its runs fail with their own error)
    """
    checker = population_checker(algo)
    if checker is None:
        return f"{algo} has no population class: only reinforce's and nstep_sarsa's seeds train together"
    try:
        with redirect_stdout(io.StringIO()), redirect_stderr(io.StringIO()):
            model = built_model(RunSpec(algo, env_id, 0, 1, 0, 1, hyperparams_yaml))
    except Exception as error:
        return f"the setting cannot be built ({type(error).__name__}: {error})"
    try:
        checker([model])
    except (TypeError, ValueError) as error:
        # (the one member checked is this setting, not a member of the user's)
        return re.sub(r"^member 0 \(seed \d+\): ", "", str(error))
    finally:
        assert model.env is not None
        model.env.close()
    return None


#: Why the runs of a command given ``--separate`` train alone
SEPARATE = "--separate: every run alone (without it, the seeds of a setting that a population covers train together)"
#: Why a setting with one seed among a command's runs trains alone
ONE_SEED = "one seed: a population trains two or more seeds of one setting together"


def training_plan(specs: Sequence[RunSpec], enabled: bool = True) -> list[str | None]:
    """
    :param specs: a command's runs
    :param enabled: False: every run is trained alone (``--separate``)
    :return: per run, in order: None if its setting's seeds train together, one population of its algorithm; else why
        they train one by one, and what would train them together (``SEPARATE``, ``ONE_SEED``, or ``refusal``'s reason)
    """
    # (a setting's key without the plan's mark, which is part of it)
    keys = [replace(spec, lockstep=False).setting_key() for spec in specs]
    seeds: dict[str, set[int]] = {}
    for key, spec in zip(keys, specs, strict=True):
        seeds.setdefault(key, set()).add(spec.seed)
    reasons: dict[str, str | None] = {}
    for key, spec in zip(keys, specs, strict=True):
        if key in reasons:
            continue
        if not enabled:
            reasons[key] = SEPARATE
        elif len(seeds[key]) < 2:
            reasons[key] = ONE_SEED
        else:
            reasons[key] = refusal(spec.algo, spec.env_id, spec.hyperparams_yaml)
    return [reasons[key] for key in keys]


def plan_lockstep(specs: Sequence[RunSpec], enabled: bool = True) -> list[RunSpec]:
    """
    :param specs: a command's runs
    :param enabled: False: every run is trained alone (``--separate``)
    :return: the same runs, in the same order, those whose setting has two seeds or more among ``specs`` and is
        covered by its algorithm's population (``training_plan``, ``refusal``) marked ``lockstep`` (their cache key
        says so), the others trained alone
    """
    return [replace(spec, lockstep=reason is None) for spec, reason in zip(specs, training_plan(specs, enabled), strict=True)]


def lockstep_jobs(specs: Sequence[RunSpec]) -> list[tuple[RunSpec, ...]]:
    """
    :param specs: runs to train (distinct keys)
    :return: the jobs to send to workers, in the order of their first run: each run trained alone a job of its own, the
        lockstep runs of one setting one job (a population), ordered by seed
    """
    jobs: dict[str, list[RunSpec]] = {}
    for spec in specs:
        group = spec.setting_key() if spec.lockstep else f"alone {spec.key()}"
        jobs.setdefault(group, []).append(spec)
    return [tuple(sorted(job, key=lambda spec: spec.seed)) for job in jobs.values()]
