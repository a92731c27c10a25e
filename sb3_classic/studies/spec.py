"""
A study file: one env and algorithm, base hyperparameters in the zoo's YAML form, a few variants of them, seeds, a
budget, and the claims under test. ``load_study`` reads and checks one; ``StudySpec.runs`` turns it into the
harness's runs, one per (variant, reading, seed).

The format (the documentation's page "Study files" has every field)::

    study: fig15-sarsa-cartpole-n           # a name (default: the file's stem)
    title: Values of n, n-step SARSA on CartPole-v1
    source: seed report Fig 15, §4.4.5      # where the claim comes from (optional)
    env: CartPole-v1                        # or module:EnvId, an env your module registers (mychain:Chain-v0)
    algo: nstep_sarsa                       # a key of rl_zoo3.ALGOS
    seeds: 10                               # seeds 0–9, or a list; or looks: {start: 10, step: 10, max: 40}
    margin: 25                              # `better` claims alike within ±25 are decided (default: 5% of the range)
    budget: {episodes: 500}                 # or {steps: 100000}; {episodes: N, max_steps: M} caps the steps
    hyperparams:                            # the base, as an entry of the zoo's YAML
      policy: MlpPolicy
      n_steps: 10
      policy_kwargs: {net_arch: [128, 128]}  # a mapping (variants override its keys), or the zoo's string
    vary: {n_steps: [1, 5, 10]}             # one axis: variants "n_steps=1", ...; or named `variants:`
    claim:                                  # or `claims:`, a list
      text: n = 10 beats n = 1 and n = 5
      kind: better                          # better | similar | reaches | below
      variant: n_steps=10
      others: [n_steps=1, n_steps=5]
      metric: mean_return                   # mean_return | last_100_return | episodes_to_threshold
    readings:                               # optional: settings the source leaves unstated, run as alternatives
      steplr_factor_0.5: {lr_decay_factor: 0.5}
    notes: |
      What the source does not state, and the reading chosen.
"""

import contextlib
import dataclasses
import difflib
import math
from collections.abc import Collection, Hashable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeGuard

import gymnasium
import rl_zoo3
import yaml
from rl_zoo3.exp_manager import ExperimentManager
from rl_zoo3.utils import get_wrapper_class

from sb3_classic.harness.common import (
    THRESHOLDS,
    RunSpec,
    algorithm_defaults,
    env_spec,
    register_algorithms,
    split_env_id,
    unknown_setting,
)
from sb3_classic.harness.lockstep import plan_lockstep
from sb3_classic.studies import untrained
from sb3_classic.zoo import YAML_NAMES, yaml_float_string

if TYPE_CHECKING:
    from sb3_classic.studies.sequential import SequentialDesign

METRICS = ("mean_return", "last_100_return", "episodes_to_threshold")
CLAIM_KINDS = ("better", "similar", "reaches", "below")
STATISTICS = ("mean", "std")
#: Hyperparameters whose mapping a variant or a reading overrides key by key
MERGED_KEYS = ("policy_kwargs", "env_kwargs")
#: How to name an env of one's own in a study file
OWN_ENV = (
    "for an env of your own, register it in a module, gymnasium.register(id='Chain-v0', entry_point='mychain:Chain'), "
    "and name it with that module, env: mychain:Chain-v0 (the module is imported, which registers the env; it must be "
    "importable: in the working directory, on PYTHONPATH, or installed)"
)
#: The reading of a study's settings as its file states them (``readings`` adds others)
STATED = "as stated"
#: Episodes per final deterministic evaluation of a study's run (its only evaluation)
EVAL_EPISODES = 10
_TOP_KEYS = (
    "study",
    "title",
    "source",
    "env",
    "algo",
    "seeds",
    "margin",
    "budget",
    "hyperparams",
    "vary",
    "variants",
    "readings",
    "claim",
    "claims",
    "threshold",
    "threshold_window",
    "smooth",
    "notes",
)


class StudyError(ValueError):
    """A study file that cannot be run: the message names the file, each field that is wrong, and the fix."""


@dataclass(frozen=True)
class Budget:
    """
    :param episodes: training episodes per run (all envs together), or None
    :param steps: env steps per run, or None (exactly one of the two is set)
    :param max_steps: with ``episodes``, the env steps a run may not exceed (default: enough for every episode to
        reach the env's time limit)
    """

    episodes: int | None = None
    steps: int | None = None
    max_steps: int | None = None

    def describe(self) -> str:
        """:return: e.g. ``500 episodes`` or ``100,000 env steps``"""
        return f"{self.episodes:,} episodes" if self.episodes is not None else f"{self.steps:,} env steps"


@dataclass(frozen=True)
class Claim:
    """
    One claim under test, decided by bootstrap confidence intervals over seeds (``sb3_classic.studies.stats``).

    :param text: the claim in one line, as the source makes it
    :param kind: ``better`` (``variant`` beats each of ``others`` on ``metric``), ``similar`` (the difference from
        each of ``others`` is within ``margin``), ``reaches`` (``metric`` of ``variant`` at least ``value``),
        ``below`` (``metric`` of ``variant`` below ``value``)
    :param variant: the variant the claim is about
    :param others: the variants it is compared with (``better``, ``similar``)
    :param metric: a per-seed metric of ``METRICS``
    :param statistic: ``mean`` (the mean over seeds) or ``std`` (their spread: "more consistent" claims, where a
        lower spread is better)
    :param margin: ``similar``: the largest difference that counts as similar, in the metric's units
    :param value: ``reaches``/``below``: the level (default: the study's threshold)
    """

    text: str
    kind: str
    variant: str
    others: tuple[str, ...] = ()
    metric: str = "mean_return"
    statistic: str = "mean"
    margin: float | None = None
    value: float | None = None


@dataclass(frozen=True)
class StudyRun:
    """One run of a study: a variant under a reading, one seed, as the harness's ``RunSpec``."""

    variant: str
    reading: str
    seed: int
    spec: RunSpec


@dataclass(frozen=True)
class StudySpec:
    """
    A study, as loaded and checked by ``load_study``.

    :param name: its name (file names of its results)
    :param title: a title for its figure and table
    :param source: where its claims come from
    :param env_id: the Gymnasium env id, or ``module:EnvId`` (Gymnasium's form: the module registers the env)
    :param algo: the algorithm (a key of ``rl_zoo3.ALGOS``)
    :param seeds: the seeds of every variant
    :param budget: per run
    :param hyperparams: the base zoo entry
    :param variants: name → overrides of the base (in order)
    :param readings: name → overrides of the settings the source leaves unstated, applied on top of every variant
        that has them (``STATED`` first, with none)
    :param claims: the claims under test
    :param threshold: the return that counts as solved (``episodes_to_threshold``); NaN where the study has none (no
        claim reads it)
    :param threshold_window: episodes of the moving average that must reach ``threshold``
    :param smooth: episodes of the moving average drawn in the figure (1: none)
    :param notes: what the source leaves unstated, and the reading chosen
    :param path: the file it was read from
    :param lockstep: train the seeds of each variant and reading in lockstep, one population of the algorithm, where
        the population covers the setting (``harness.lockstep.plan_lockstep``); False: each run alone (``--separate``)
    :param design: seeds drawn in looks (``seeds: {start, step, max}``, ``sequential.SequentialDesign``), the study as
        stated only (its other readings run the first look's seeds); None: every run of ``seeds``
    :param margin: the equivalence margin of its ``better`` claims on a return (``sequential.claim_margin``), in the
        return's units; None: no equivalence verdict
    """

    name: str
    title: str
    source: str
    env_id: str
    algo: str
    seeds: tuple[int, ...]
    budget: Budget
    hyperparams: dict[str, Any]
    variants: dict[str, dict[str, Any]]
    readings: dict[str, dict[str, Any]]
    claims: tuple[Claim, ...]
    threshold: float
    threshold_window: int = 100
    smooth: int = 10
    notes: str = ""
    path: Path | None = field(default=None, compare=False)
    lockstep: bool = True
    design: "SequentialDesign | None" = None
    margin: float | None = None

    def zoo_entry(self, variant: str, reading: str = STATED) -> dict[str, Any]:
        """
        :return: the zoo YAML entry of ``variant`` under ``reading``: the base, the variant's overrides, then the
            reading's (``read_entry``)
        """
        stated = stated_keys(self.hyperparams, self.variants)
        entry = read_entry(self.hyperparams, self.variants[variant], self.readings[reading], stated)
        if isinstance(entry.get("policy_kwargs"), Mapping):
            entry["policy_kwargs"] = policy_kwargs_string(entry["policy_kwargs"])
        # The zoo requires it; the run's budget (and, with an episode budget, the callback that stops it) decides
        return {"n_timesteps": self.step_cap(int(entry.get("n_envs", 1)), entry.get("env_kwargs")), **entry}

    def step_cap(self, n_envs: int = 1, env_kwargs: Mapping[str, Any] | None = None) -> int:
        """
        :param n_envs: the run's envs
        :param env_kwargs: the run's ``env_kwargs`` (a ``max_episode_steps`` there is the env's time limit, as in
            ``gymnasium.make``)
        :return: the env steps of a run: the budget in steps, or the cap of an episode budget
        """
        if self.budget.steps is not None:
            return self.budget.steps
        assert self.budget.episodes is not None
        if self.budget.max_steps is not None:
            return self.budget.max_steps
        limit = time_limit(env_spec(self.env_id), env_kwargs)
        assert limit is not None, "checked by load_study"
        # Every episode at the time limit, and the unfinished episodes of the other envs
        return (self.budget.episodes + n_envs) * limit

    def return_range(self) -> tuple[float, float] | None:
        """:return: the lowest and highest return of an episode of its env (``return_range``), or None where unknown"""
        settings = [self.hyperparams, *self.variants.values(), *self.readings.values()]
        return return_range(self.env_id, env_spec(self.env_id), settings)

    def runs(self, counts: Mapping[tuple[str, str], int] | None = None) -> list[StudyRun]:
        """
        :param counts: per (reading, variant), how many of the study's seeds to run, its first (a sequential design's
            look: ``cli``); default: all of them
        :return: those runs of the study, seed by seed (an interrupted study has whole seeds done)
        """
        runs = []
        for index, seed in enumerate(self.seeds):
            for reading in self.readings:
                for variant in self.variants:
                    if counts is not None and index >= counts.get((reading, variant), 0):
                        continue
                    label = f"{self.name} {variant}" + ("" if reading == STATED else f" [{reading}]") + f" seed {seed}"
                    entry = self.zoo_entry(variant, reading)
                    spec = RunSpec(
                        algo=self.algo,
                        env_id=self.env_id,
                        seed=seed,
                        n_timesteps=entry["n_timesteps"],
                        eval_freq=0,
                        n_eval_episodes=EVAL_EPISODES,
                        hyperparams_yaml=yaml.safe_dump(entry, sort_keys=True),
                        max_episodes=self.budget.episodes,
                        label=label,
                    )
                    runs.append(StudyRun(variant, reading, seed, spec))
        planned = plan_lockstep([run.spec for run in runs], self.lockstep)
        return [dataclasses.replace(run, spec=spec) for run, spec in zip(runs, planned, strict=True)]

    def with_budget(self, seeds: int | None = None, episodes: int | None = None, steps: int | None = None) -> "StudySpec":
        """
        :param seeds: seeds 0 to ``seeds`` − 1 instead of the file's
        :param episodes: training episodes per run instead of the file's budget
        :param steps: env steps per run instead of the file's budget
        :return: the same study with fewer (or more) seeds, or another budget (a reduced run: scratch results)
        :raise StudyError: if a count is not an integer ≥ 1, if both budgets are given, or if ``steps`` is given to a
            study that claims on ``episodes_to_threshold`` (which needs a budget in episodes, as in the file)
        """
        for option, value in (("--seeds", seeds), ("--episodes", episodes), ("--steps", steps)):
            if value is not None and (isinstance(value, bool) or not isinstance(value, int) or value < 1):
                raise StudyError(f"{option} {value!r}: give an integer >= 1")
        if episodes is not None and steps is not None:
            raise StudyError("--episodes and --steps: give one budget")
        if steps is not None and any(claim.metric == "episodes_to_threshold" for claim in self.claims):
            raise StudyError(
                f"{self.path or self.name}: --steps {steps}: a claim of this study is on episodes_to_threshold, which "
                "needs a budget in episodes (each seed would have its own episode count to censor at): give --episodes"
            )
        budget = self.budget
        if episodes is not None:
            budget = Budget(episodes=episodes, max_steps=budget.max_steps)
        if steps is not None:
            budget = Budget(steps=steps)
        if seeds is not None:
            # A reduced run is a fixed design of its seeds
            return dataclasses.replace(self, seeds=tuple(range(seeds)), budget=budget, design=None)
        return dataclasses.replace(self, budget=budget)


def time_limit(spec: gymnasium.envs.registration.EnvSpec, env_kwargs: Mapping[str, Any] | None) -> int | None:
    """:return: the env's time limit: ``max_episode_steps`` of ``env_kwargs`` (as ``gymnasium.make`` reads it), else
    its registration's (None: none)"""
    limit = (env_kwargs or {}).get("max_episode_steps")
    return limit if _is_int(limit) and limit > 0 else spec.max_episode_steps


def read_entry(
    hyperparams: Mapping[str, Any],
    variant: Mapping[str, Any],
    reading: Mapping[str, Any],
    stated: Collection[str] = (),
) -> dict[str, Any]:
    """
    :param stated: the settings the study states somewhere (in ``hyperparams`` or in some variant)
    :return: the base ``hyperparams`` with a variant's overrides, then a reading's: for the settings the variant has
        (a variant without learning-rate decay is the same run under every reading of its factor), and for those the
        study states nowhere (left at the algorithm's default as stated, read otherwise in every variant: a
        ``streaming`` reading adds ``td_lambda`` and ``normalize``)
    """
    entry = merge(hyperparams, variant)
    return merge(entry, {key: value for key, value in reading.items() if key in entry or key not in stated})


def stated_keys(hyperparams: Mapping[str, Any], variants: Mapping[str, Mapping[str, Any]]) -> set[str]:
    """:return: the settings a study states in its ``hyperparams`` or in some variant"""
    return set(hyperparams).union(*variants.values())


def merge(base: Mapping[str, Any], overrides: Mapping[str, Any]) -> dict[str, Any]:
    """
    :return: ``base`` with ``overrides``; a ``policy_kwargs`` or ``env_kwargs`` mapping is merged key by key (a string
        replaces)
    """
    merged = dict(base)
    for key, value in overrides.items():
        if key in MERGED_KEYS and isinstance(value, Mapping) and isinstance(merged.get(key), Mapping):
            merged[key] = {**merged[key], **value}
        else:
            merged[key] = value
    return merged


def policy_kwargs_string(kwargs: Mapping[str, Any]) -> str:
    """
    :param kwargs: ``policy_kwargs`` as a mapping; strings starting with ``nn.`` or ``th.`` are Python names
        (``nn.LeakyReLU``), and so are the names the zoo's YAMLs may use (``TileCoding``: ``features_extractor_class:
        TileCoding``); other strings are strings
    :return: the zoo's form, ``"dict(activation_fn=nn.ReLU, net_arch=[64, 64])"`` (the zoo evaluates it), the keys of
        each mapping sorted: a mapping's order means nothing, and the string is part of each run's cache key
    """

    def code(value: Any) -> str:
        if isinstance(value, str) and (value.startswith(("nn.", "th.")) or value in YAML_NAMES):
            return value
        if isinstance(value, Mapping):
            return "dict(" + ", ".join(f"{key}={code(value[key])}" for key in sorted(value, key=str)) + ")"
        if isinstance(value, list | tuple):
            return "[" + ", ".join(code(item) for item in value) + "]"
        return repr(value)

    return code(kwargs)


class _UniqueKeyLoader(yaml.SafeLoader):
    """PyYAML's safe loader, except that a key given twice in one mapping is an error (PyYAML keeps the last)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: set[Any] = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            if isinstance(key, Hashable) and key in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f"{key!r} is given twice in one mapping: keep one", key_node.start_mark
                )
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


class _Checker:
    """Collects the problems of a study file, each naming its field and the fix."""

    def __init__(self, path: Path):
        self.path = path
        self.problems: list[str] = []

    def fail(self, where: str, problem: str) -> None:
        message = f"{where}: {problem}"
        if message not in self.problems:
            self.problems.append(message)

    def raise_if_any(self) -> None:
        if self.problems:
            lines = "\n  ".join(self.problems)
            raise StudyError(f"{self.path}: {len(self.problems)} problem(s):\n  {lines}")

    def positive_int(self, where: str, value: Any) -> int | None:
        if isinstance(value, float) and value.is_integer() and value > 0:
            return int(value)
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            self.fail(where, f"{value!r} is not a positive integer: write e.g. 500 (or !!float 5e5)")
            return None
        return value

    def hyperparams(self, where: str, entry: Any, algo: str) -> dict[str, Any]:
        if not isinstance(entry, Mapping):
            self.fail(where, f"expected a mapping of hyperparameters (a zoo YAML entry), got {entry!r}")
            return {}
        for key, value in entry.items():
            if key == "n_timesteps":
                self.fail(f"{where}.n_timesteps", "the budget is the study's `budget:` (episodes or steps): remove it")
            elif key == "seed":
                self.fail(f"{where}.seed", "each run's seed comes from the study's `seeds:` (a count or a list): remove it")
            elif (unknown := unknown_setting(algo, str(key))) is not None:
                self.fail(f"{where}.{key}", unknown)
            if not self.float_strings(f"{where}.{key}", value):
                self.as_the_zoo_reads(f"{where}.{key}", str(key), value)
            if key == "policy_kwargs" and not isinstance(value, str | Mapping):
                self.fail(
                    f"{where}.policy_kwargs", "write a mapping (net_arch: [64, 64], ...) or the zoo's string 'dict(...)'"
                )
            if key == "env_kwargs" and (not isinstance(value, Mapping) or not all(isinstance(name, str) for name in value)):
                self.fail(
                    f"{where}.env_kwargs",
                    f"{value!r}: a mapping of the env's keyword arguments, e.g. env_kwargs: {{length: 10}} (passed to "
                    "gymnasium.make with the env's id)",
                )
        return dict(entry)

    def as_the_zoo_reads(self, where: str, key: str, value: Any) -> None:
        """
        Read a hyperparameter as the run will: rl-zoo3's own preprocessing (``ExperimentManager._preprocess_schedules``
        for the step sizes and clip ranges, ``rl_zoo3.utils.get_wrapper_class`` for the wrappers), so that what it
        cannot read fails here, naming the field, and not when the run starts.
        """
        wrapper = key in ("env_wrapper", "vec_env_wrapper")
        try:
            if wrapper:
                read = get_wrapper_class({key: value}, key)
            else:
                read = ExperimentManager._preprocess_schedules({key: value})[key]
        except Exception as error:
            if wrapper:
                takes = (
                    "the full name of an importable wrapper class, module.Class (e.g. gymnasium.wrappers.FlattenObservation), "
                    "or a list of them, each a name or {name: {keyword: value}}"
                )
            else:
                takes = (
                    f"a number ({key}: !!float 1e-3), or the zoo's linear schedule from a value down to 0, "
                    f"'lin_<value>' ({key}: lin_1e-3)"
                )
            self.fail(where, f"{value!r}: rl-zoo3 cannot read it ({type(error).__name__}: {error}): {key} takes {takes}")
            return
        # A string the zoo turned into a schedule (not one it passes on as it is), named otherwise than lin_
        if not wrapper and isinstance(value, str) and read is not value and not value.startswith("lin_"):
            self.fail(
                where,
                f"{value!r}: rl-zoo3 reads every 'NAME_<value>' as its linear schedule, whatever NAME "
                f"({value.split('_')[0]!r} here): write lin_{value.split('_', 1)[1]}",
            )

    def float_strings(self, where: str, value: Any) -> bool:
        """:return: whether a number written as a string was found (and said)"""
        # YAML reads 1e-3 (no dot) as a string, and the zoo would pass it on as one
        if isinstance(value, str):
            fix = yaml_float_string(value)
            if fix is not None:
                self.fail(where, fix)
            return fix is not None
        if isinstance(value, Mapping):
            return any([self.float_strings(f"{where}.{key}", item) for key, item in value.items()])
        if isinstance(value, list):
            return any([self.float_strings(f"{where}[{index}]", item) for index, item in enumerate(value)])
        return False


def _check_top_level(check: _Checker, data: Mapping[str, Any]) -> None:
    """The file's fields: each known, the required ones given; raises at once only for a missing one, which the other
    fields are read from (an unknown field is said with every other problem of the file)"""
    for key in data:
        if key not in _TOP_KEYS:
            close = difflib.get_close_matches(str(key), _TOP_KEYS, n=1)
            check.fail(
                str(key), "unknown field" + (f": did you mean {close[0]!r}?" if close else f"; known: {', '.join(_TOP_KEYS)}")
            )
    missing = [key for key in ("env", "algo", "budget", "hyperparams") if key not in data]
    for key in missing:
        check.fail(key, "missing (a study needs env, algo, budget, hyperparams, variants or vary, and a claim)")
    if ("vary" in data) == ("variants" in data):
        check.fail(
            "variants", "give exactly one of `vary:` (one axis: {n_steps: [1, 5, 10]}) and `variants:` (named overrides)"
        )
    if ("claim" in data) == ("claims" in data):
        check.fail("claim", "give exactly one of `claim:` (one claim) and `claims:` (a list)")
    if missing:
        check.raise_if_any()


def load_study(path: Path | str) -> StudySpec:
    """
    Read and check a study file.

    :param path: the YAML file
    :return: the study
    :raise StudyError: naming every field that is wrong and how to fix it
    """
    path = Path(path)
    check = _Checker(path)
    try:
        data = yaml.load(path.read_text(), Loader=_UniqueKeyLoader)  # a SafeLoader
    except (OSError, yaml.YAMLError) as error:
        raise StudyError(f"{path}: cannot be read as YAML: {error}") from error
    if not isinstance(data, Mapping):
        raise StudyError(f"{path}: a study file is a mapping (env:, algo:, hyperparams:, ...), got {type(data).__name__}")
    _check_top_level(check, data)

    env_id, registration, algo = _env_and_algo(check, data)

    seeds, design = _seeds(check, data.get("seeds", 10))
    budget = _budget(check, data["budget"])
    hyperparams = check.hyperparams("hyperparams", data["hyperparams"], algo)
    uncapped = budget is not None and budget.episodes is not None and budget.max_steps is None
    env_kwargs = hyperparams.get("env_kwargs")
    limit = time_limit(registration, env_kwargs if isinstance(env_kwargs, Mapping) else None) if registration else None
    if uncapped and registration is not None and limit is None:
        check.fail(
            "budget.max_steps",
            f"{env_id} has no time limit: give a step cap, e.g. max_steps: 500000 (or a time limit, env_kwargs: "
            "{max_episode_steps: 500} in hyperparams)",
        )
    variants = _variants(check, data, algo)
    readings = _readings(check, data.get("readings") or {}, algo)
    for name, overrides in variants.items():
        if isinstance(overrides.get("policy_kwargs"), Mapping) and isinstance(hyperparams.get("policy_kwargs"), str):
            check.fail(
                f"variants.{name}.policy_kwargs", "overrides keys of a string: write the base's policy_kwargs as a mapping"
            )
    _check_readings(check, hyperparams, variants, readings)

    threshold = _threshold(check, data, env_id, registration, hyperparams.get("env_kwargs"))
    claims = _claims(check, data, variants, float(threshold))
    if budget is not None and budget.steps is not None:
        for index, claim in enumerate(claims):
            if claim.metric == "episodes_to_threshold":
                check.fail(
                    f"claims[{index}].metric" if "claims" in data else "claim.metric",
                    "episodes_to_threshold needs a budget in episodes (with one in env steps, each seed has its own "
                    "episode count to censor at): write budget: {episodes: ...}, or claim on a return metric",
                )
    settings = [hyperparams, *variants.values(), *readings.values()]
    _check_return_levels(check, data, env_id, registration, settings, float(threshold), claims)
    window = check.positive_int("threshold_window", data.get("threshold_window", 100))
    smooth = check.positive_int("smooth", data.get("smooth", 10))
    name = data.get("study", path.stem)
    if not _is_file_name(name):
        check.fail(
            "study",
            f"{name!r}: the name of the study's output files (NAME.md, NAME.csv, ... in the results folder), without "
            "'/', '\\' or a leading '.', e.g. study: fig27-sarsa-acrobot-layers (default: the file's name)",
        )
    check.raise_if_any()
    assert budget is not None, "checked"
    assert window is not None, "checked"
    assert smooth is not None, "checked"
    study = StudySpec(
        name=str(name),
        title=str(data.get("title", path.stem)),
        source=str(data.get("source", "")),
        env_id=env_id,
        algo=algo,
        seeds=seeds,
        budget=budget,
        hyperparams=hyperparams,
        variants=variants,
        readings=readings,
        claims=claims,
        threshold=float(threshold),
        threshold_window=window,
        smooth=smooth,
        notes=str(data.get("notes", "")).strip(),
        path=path,
        design=design,
        margin=_margin(check, data, env_id, registration, settings),
    )
    check.raise_if_any()
    _check_distinct_variants(check, study)
    return study


def _check_distinct_variants(check: _Checker, study: StudySpec) -> None:
    """
    Refuse variants that are the same run as the file states them (e.g. ``same: {learning_rate: 0.003}`` beside
    a base of 0.003), also where one writes out the algorithm's default (``n_steps: 3`` for NStepSARSA's, beside a
    base without it): each would be compared with the other as if they differed, and a claim between them decided on
    two copies of one run. (Defaults inside ``policy_kwargs`` are not filled in.)
    """
    defaults = algorithm_defaults(study.algo) | {"n_envs": 1}  # (rl-zoo3's default)
    seen: dict[str, str] = {}
    for name in study.variants:
        stated = study.zoo_entry(name)
        without_defaults = {key: value for key, value in stated.items() if key not in defaults or value != defaults[key]}
        entry = yaml.safe_dump(without_defaults, sort_keys=True)
        if entry in seen:
            check.fail(
                f"variants.{name}",
                f"the same run as variant {seen[entry]!r} (the same settings once merged with hyperparams): change "
                "one, or drop it",
            )
        seen.setdefault(entry, name)
    check.raise_if_any()


def _env_and_algo(check: _Checker, data: Mapping[str, Any]) -> tuple[str, Any, str]:
    """
    :return: the env id, its Gymnasium spec (None if unknown) and the algorithm; raises if the algorithm is unknown.
        The module of a ``module:EnvId`` id is imported here (it registers the env), as ``gymnasium.make`` imports it
    """
    env_id = data["env"]
    found = None
    if not isinstance(env_id, str) or env_id.count(":") > 1 or env_id.startswith(":") or env_id.endswith(":"):
        check.fail(
            "env",
            f"{env_id!r}: the id of a registered Gymnasium env, e.g. env: CartPole-v1, or module:EnvId for an env that "
            "the module registers, e.g. env: mychain:Chain-v0",
        )
    else:
        module, gym_id = split_env_id(env_id)
        try:
            found = env_spec(env_id)
        except gymnasium.error.Error as error:
            if module is None:
                check.fail("env", f"{env_id!r} is not a registered Gymnasium env ({error}): {OWN_ENV}")
            else:
                check.fail(
                    "env",
                    f"{env_id!r}: importing {module!r} registers no env {gym_id!r} ({error}): the module must call "
                    f"gymnasium.register(id={gym_id!r}, entry_point=...) when it is imported",
                )
        except Exception as error:
            check.fail(
                "env",
                f"{env_id!r}: its module {module!r} cannot be imported ({type(error).__name__}: {error}): put {module}.py "
                "in the working directory or a folder on PYTHONPATH, or install its package (the study's runs import it "
                "in every process that builds the env)",
            )
    register_algorithms()
    algo = data["algo"]
    if not isinstance(algo, str) or algo not in rl_zoo3.ALGOS:
        check.fail("algo", f"{algo!r} is not an algorithm of rl-zoo3: choose one of {', '.join(sorted(rl_zoo3.ALGOS))}")
        check.raise_if_any()
    return env_id, found, algo


def _threshold(check: _Checker, data: Mapping[str, Any], env_id: str, registration: Any, env_kwargs: Any) -> float:
    """
    :return: the study's threshold: its own, else the harness's (CartPole-v1, Acrobot-v1), else Gymnasium's
        ``reward_threshold`` of the env; NaN where none is given and no claim reads it (a study of one's own env that
        claims on returns), or where it is wrong (said)
    """
    default = THRESHOLDS.get(env_id, registration.reward_threshold if registration is not None else None)
    threshold = data.get("threshold", default)
    uses = _threshold_uses(data)
    if threshold is None and not uses:
        return math.nan
    if not _is_number(threshold):
        check.fail("threshold", _threshold_problem(env_id, threshold, uses, registration, env_kwargs))
        return math.nan
    return float(threshold)


def _threshold_uses(data: Mapping[str, Any]) -> list[str]:
    """:return: the fields of a study file that read its threshold: a claim on episodes to threshold, or a level claim
    (``reaches``, ``below``) on a return without its own ``value``"""
    raw = [data["claim"]] if "claim" in data else data.get("claims")
    uses = []
    for index, item in enumerate(raw if isinstance(raw, list | tuple) else []):
        where = "claim" if "claim" in data else f"claims[{index}]"
        if not isinstance(item, Mapping):
            continue
        if item.get("metric") == "episodes_to_threshold":
            uses.append(f"{where}.metric episodes_to_threshold")
        elif item.get("kind") in ("reaches", "below") and "value" not in item:
            uses.append(f"{where}, a {item.get('kind')!r} claim without value,")
    return uses


def _threshold_problem(env_id: str, threshold: Any, uses: Sequence[str], registration: Any, env_kwargs: Any) -> str:
    """
    :param env_id: the study's env
    :param threshold: the study's threshold (None: none given, and the env has none)
    :param uses: what reads it (``_threshold_uses``)
    :param registration: the env's Gymnasium spec (None if unknown)
    :param env_kwargs: the study's ``env_kwargs``
    :return: what the threshold is for and a level to start from: the env's default where it has one, else a
        uniformly random policy's mean return on it (measured here, on this error only), which a threshold should exceed
    """
    given = "missing" if threshold is None else repr(threshold)
    why = "no claim reads it: it may be left out"
    if uses:
        why = f"{' and '.join(uses)} {'needs' if len(uses) == 1 else 'need'} it"
    problem = f"{given}: give the return that counts as solved on {env_id}, a finite number ({why})"
    default = THRESHOLDS.get(env_id, registration.reward_threshold if registration is not None else None)
    if _is_number(default):
        return f"{problem}, e.g. threshold: {default:g} (the env's)"
    problem += "; the env registers no reward_threshold: a level that a policy's training returns reach once it has learned"
    returns = None
    if registration is not None:
        with contextlib.suppress(Exception):  # (the env's own error comes with the runs)
            returns = untrained.random_returns(env_id, env_kwargs if isinstance(env_kwargs, Mapping) else None)
    if returns is None or not len(returns):
        return problem
    return (
        f"{problem}, above a uniformly random policy's mean return on it, {returns.mean():.4g} ({len(returns)} episodes, "
        f"from {returns.min():.4g} to {returns.max():.4g})"
    )


def _is_int(value: Any) -> TypeGuard[int]:
    """:return: whether ``value`` is an integer (YAML's ``true`` is a bool, not 1)"""
    return isinstance(value, int) and not isinstance(value, bool)


def _is_number(value: Any) -> TypeGuard[int | float]:
    """:return: whether ``value`` is a finite number (not a bool, not YAML's ``.nan`` or ``.inf``)"""
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _is_file_name(name: Any) -> bool:
    """:return: whether ``name`` names a file in a folder (not a path out of it, not hidden, not empty)"""
    return isinstance(name, str) and name.strip() == name != "" and not name.startswith(".") and not {"/", "\\"} & set(name)


def _quote_hint(name: Any, variants: Mapping[str, Any]) -> str:
    """:return: the fix where YAML read a variant's name as a number (``4`` for the variant ``'4'``), else ''"""
    if not isinstance(name, str) and str(name) in variants:
        return f" (YAML reads {name!r} as a number, not a name: quote it, '{name}')"
    return ""


def _seeds(check: _Checker, value: Any) -> tuple[tuple[int, ...], "SequentialDesign | None"]:
    """:return: the study's seeds, and its sequential design (``seeds: {start, step, max}``), if any"""
    from sb3_classic.studies.sequential import BOUNDARIES, SequentialDesign  # (it imports the statistics, which import this)

    if isinstance(value, Mapping):
        fields = ("start", "step", "max", "boundary")
        example = "seeds: {start: 10, step: 10, max: 40} (looks at 10, 20, 30, 40 seeds per variant)"
        unknown = sorted(set(map(str, value)) - set(fields))
        for key in unknown:
            close = difflib.get_close_matches(key, fields, n=1)
            check.fail(f"seeds.{key}", "unknown field" + (f": did you mean {close[0]!r}?" if close else f"; {example}"))
        missing = [key for key in ("start", "max") if key not in value]
        if missing:
            check.fail("seeds", f"{dict(value)!r} lacks {' and '.join(missing)}: {example}")
        counts = {key: check.positive_int(f"seeds.{key}", value[key]) for key in ("start", "step", "max") if key in value}
        boundary = value.get("boundary", "pocock")
        if boundary not in BOUNDARIES:
            check.fail("seeds.boundary", f"{boundary!r}: choose one of {', '.join(BOUNDARIES)}")
        start, step, most = counts.get("start"), counts.get("step", counts.get("start")), counts.get("max")
        if unknown or missing or None in (start, step, most) or boundary not in BOUNDARIES:
            return (), None
        assert start is not None
        assert step is not None
        assert most is not None
        if start < MIN_LOOK_SEEDS:
            check.fail(
                "seeds.start", f"{start}: the first look needs at least {MIN_LOOK_SEEDS} seeds per variant for an interval"
            )
        if most < start:
            check.fail("seeds.max", f"{most} is below start ({start}): the last look has the most seeds")
        return tuple(range(max(most, start))), SequentialDesign(start, step, most, boundary)
    if isinstance(value, int) and not isinstance(value, bool):
        if value < 1:
            check.fail("seeds", f"{value}: give the number of seeds (at least 1; the studies use 10) or a list")
        return tuple(range(value)), None
    if isinstance(value, list) and value and all(_is_int(seed) and seed >= 0 for seed in value):
        if len(set(value)) < len(value):
            check.fail("seeds", f"{value}: a seed appears twice")
        return tuple(value), None
    check.fail(
        "seeds",
        f"{value!r}: give a number of seeds (seeds 0 to k − 1), a list of non-negative integers, or looks, "
        "{start: 10, step: 10, max: 40}",
    )
    return (), None


#: The fewest seeds per variant of a sequential design's first look (the statistics' ``MIN_SEEDS``)
MIN_LOOK_SEEDS = 5
#: The default equivalence margin: this fraction of the env's range of returns (``STEP_REWARDS``)
MARGIN_FRACTION = 0.05


def return_range(env_id: str, env_spec: Any, settings: Sequence[Mapping[str, Any]]) -> tuple[float, float] | None:
    """
    :return: the lowest and highest return of an episode of the env (``STEP_REWARDS``), or None where unknown (another
        env, or settings that give an ``env_wrapper`` or ``env_kwargs``, which may change its time limit)
    """
    limit = env_spec.max_episode_steps if env_spec is not None else None
    wrapped = any({"env_wrapper", "env_kwargs"} & set(setting) for setting in settings)
    if env_id not in STEP_REWARDS or limit is None or wrapped:
        return None
    low, high = STEP_REWARDS[env_id]
    return min(low, limit * low), max(high, limit * high)


def _margin(check: _Checker, data: Mapping[str, Any], env_id: str, env_spec: Any, settings: Sequence[Any]) -> float | None:
    """:return: the study's equivalence margin: its ``margin:``, else 5% of the env's range of returns (two significant
    figures: 25 on CartPole-v1 and Acrobot-v1), else None"""
    if "margin" in data:
        margin = data["margin"]
        if not _is_number(margin) or margin <= 0:
            check.fail(
                "margin",
                f"{margin!r}: the largest difference of returns that counts as alike, a positive number declared before "
                "running, e.g. margin: 25",
            )
            return None
        return float(margin)
    returns = return_range(env_id, env_spec, settings)
    if returns is None:
        return None
    return float(f"{MARGIN_FRACTION * (returns[1] - returns[0]):.2g}")


def _budget(check: _Checker, value: Any) -> Budget | None:
    fields = ("episodes", "steps", "max_steps")
    if not isinstance(value, Mapping) or set(value) - set(fields):
        unknown = sorted(set(value) - set(fields)) if isinstance(value, Mapping) else []
        close = difflib.get_close_matches(str(unknown[0]), fields, n=1) if unknown else []
        hint = f" ({unknown[0]!r}: did you mean {close[0]!r}?)" if close else ""
        check.fail("budget", f"{value!r}{hint}: write {{episodes: 500}} or {{steps: 100000}} (max_steps caps episodes)")
        return None
    if ("episodes" in value) == ("steps" in value):
        both = "episodes" in value
        check.fail(
            "budget",
            ("give episodes or steps, not both" if both else "give episodes or steps")
            + " (the seed report's: 500 episodes while tuning, 1000 for final models)",
        )
        return None
    if "steps" in value:
        if "max_steps" in value:
            check.fail("budget.max_steps", "caps an episode budget only: remove it, or budget in episodes")
        steps = check.positive_int("budget.steps", value["steps"])
        return Budget(steps=steps) if steps is not None else None
    episodes = check.positive_int("budget.episodes", value["episodes"])
    max_steps = check.positive_int("budget.max_steps", value["max_steps"]) if "max_steps" in value else None
    return Budget(episodes=episodes, max_steps=max_steps) if episodes is not None else None


def _variants(check: _Checker, data: Mapping[str, Any], algo: str) -> dict[str, dict[str, Any]]:
    if ("vary" in data) == ("variants" in data):  # (said by _check_top_level)
        return {}
    if "vary" in data:
        vary = data["vary"]
        if not isinstance(vary, Mapping) or len(vary) != 1:
            check.fail("vary", f"{vary!r}: one hyperparameter and its values, e.g. {{n_steps: [1, 5, 10]}}")
            return {}
        ((key, values),) = vary.items()
        if not isinstance(values, list) or len(values) < 2:
            check.fail(f"vary.{key}", f"{values!r}: a list of at least two values")
            return {}
        variants = {}
        for value in values:
            # A number YAML read as a string (1e-3) is named as it will be once written as one (learning_rate=0.001)
            number = isinstance(value, str) and yaml_float_string(value) is not None
            name = f"{key}={float(value) if number else value}"
            if name in variants:
                check.fail(f"vary.{key}", f"{value!r} appears twice")
            variants[name] = check.hyperparams("vary", {key: value}, algo)
        return variants
    raw = data["variants"]
    if not isinstance(raw, Mapping) or not raw:
        check.fail(
            "variants", f"{raw!r}: a mapping of names to overrides, e.g. {{he: {{policy_kwargs: {{weight_init: kaiming}}}}}}"
        )
        return {}
    return {str(name): check.hyperparams(f"variants.{name}", overrides or {}, algo) for name, overrides in raw.items()}


def _readings(check: _Checker, raw: Any, algo: str) -> dict[str, dict[str, Any]]:
    readings: dict[str, dict[str, Any]] = {STATED: {}}
    if not isinstance(raw, Mapping):
        check.fail("readings", "expected a mapping: name → overrides, e.g. {steplr_factor_0.5: {lr_decay_factor: 0.5}}")
        return readings
    for name, overrides in raw.items():
        readings[str(name)] = check.hyperparams(f"readings.{name}", overrides, algo)
    return readings


def _check_readings(
    check: _Checker, hyperparams: Mapping[str, Any], variants: Mapping[str, Mapping[str, Any]], readings: Mapping[str, Any]
) -> None:
    """Each reading must change some run, and must not make two variants the same run."""
    keys = stated_keys(hyperparams, variants)
    stated = {name: read_entry(hyperparams, overrides, {}) for name, overrides in variants.items()}
    for reading, overrides in readings.items():
        if reading == STATED or not overrides:
            continue
        where = f"readings.{reading}"
        if isinstance(overrides.get("policy_kwargs"), Mapping):
            strings = [name for name, entry in stated.items() if isinstance(entry.get("policy_kwargs"), str)]
            if strings:
                check.fail(
                    f"{where}.policy_kwargs",
                    f"would replace the whole policy_kwargs string of variant {strings[0]!r}: write the base's and the "
                    "variants' policy_kwargs as mappings",
                )
                continue
        read = {name: read_entry(hyperparams, variants[name], overrides, keys) for name in variants}
        if read == stated:
            check.fail(
                where,
                f"changes no run: {', '.join(map(str, overrides))} as the study states it (in hyperparams or every "
                "variant): give the value read otherwise",
            )
            continue
        names = list(variants)
        for index, first in enumerate(names):
            for second in names[index + 1 :]:
                if stated[first] != stated[second] and read[first] == read[second]:
                    check.fail(
                        where,
                        f"makes variants {first!r} and {second!r} the same run (it sets what tells them apart): a "
                        "reading must leave the varied settings alone",
                    )


#: Envs whose reward of every step lies in [low, high] (Gymnasium's docs): an episode's return then lies in
#: [min(low, T·low), max(high, T·high)] with T its time limit (an episode has 1 to T steps)
STEP_REWARDS = {"CartPole-v1": (1.0, 1.0), "Acrobot-v1": (-1.0, 0.0), "MountainCar-v0": (-1.0, -1.0)}


def _check_return_levels(
    check: _Checker,
    data: Mapping[str, Any],
    env_id: str,
    env_spec: Any,
    settings: Sequence[Mapping[str, Any]],
    threshold: float,
    claims: Sequence[Claim],
) -> None:
    """
    A threshold or a claim's level outside the returns the env can give (CartPole-v1: 1 to 500) is refused before any
    run: no seed could ever reach it, or every seed would at its first episodes. Only for the envs of
    ``STEP_REWARDS`` with their registered time limit (not where the hyperparameters, a variant's or a reading's, give
    an ``env_wrapper`` or ``env_kwargs``, which may change it).
    """
    returns = return_range(env_id, env_spec, settings)
    if returns is None:
        return
    low, high = STEP_REWARDS[env_id]
    limit = env_spec.max_episode_steps
    lowest, highest = returns
    per_step = f"a reward in [{low:g}, {high:g}] per step, 1 to {limit} steps"
    what = f"{env_id}'s returns lie in [{lowest:g}, {highest:g}] ({per_step})"
    # (a threshold that is not a number has its own message)
    if "threshold" in data and math.isfinite(threshold) and not lowest <= threshold <= highest:
        effect = "no seed can reach it" if threshold > highest else "every seed reaches it in its first episodes"
        check.fail("threshold", f"{threshold:g}: {what}, so {effect}: give a level within them")
    for index, claim in enumerate(claims):
        # (a level of the spread over seeds, statistic: std, is not a return)
        if claim.value is None or claim.metric == "episodes_to_threshold" or claim.statistic == "std":
            continue
        if "threshold" in data and claim.value == threshold:  # (the threshold's own message says it)
            continue
        if not lowest <= claim.value <= highest:
            where = f"claims[{index}].value" if "claims" in data else "claim.value"
            check.fail(where, f"{claim.value:g}: {what}, so its verdict is known before any run: give a level within them")


def _claims(check: _Checker, data: Mapping[str, Any], variants: Mapping[str, Any], threshold: float) -> tuple[Claim, ...]:
    if ("claim" in data) == ("claims" in data):  # (said by _check_top_level)
        return ()
    raw: Sequence[Any] = [data["claim"]] if "claim" in data else data["claims"]
    if not isinstance(raw, list | tuple) or not raw:
        check.fail("claims", "a non-empty list of claims")
        return ()
    claims = []
    for index, item in enumerate(raw):
        where = "claim" if "claim" in data else f"claims[{index}]"
        if not isinstance(item, Mapping):
            check.fail(where, f"{item!r}: a mapping with text, kind, variant, ...")
            continue
        claims.append(_claim(check, where, item, variants, threshold))
    texts = [claim.text for claim in claims]
    for text in sorted({text for text in texts if texts.count(text) > 1}):
        check.fail("claims", f"the text {text!r} is given to two claims: STUDIES.md tells claims apart by their text")
    return tuple(claims)


def _claim(check: _Checker, where: str, item: Mapping[str, Any], variants: Mapping[str, Any], threshold: float) -> Claim:
    fields = ("text", "kind", "variant", "others", "metric", "statistic", "margin", "value")
    for key in sorted(set(item) - set(fields), key=str):
        close = difflib.get_close_matches(str(key), fields, n=1)
        check.fail(
            f"{where}.{key}", "unknown field" + (f": did you mean {close[0]!r}?" if close else f"; known: {', '.join(fields)}")
        )
    kind = item.get("kind")
    if kind not in CLAIM_KINDS:
        check.fail(f"{where}.kind", f"{kind!r}: choose one of {', '.join(CLAIM_KINDS)}")
    if not isinstance(item.get("text"), str) or not item["text"].strip():
        missing = "missing: " if "text" not in item else ""
        check.fail(f"{where}.text", f"{missing}the claim in one line, as its source makes it")
    choices = ", ".join(map(repr, variants))
    variant = item.get("variant")
    # (without variants, their own error says what to write)
    if variants and variant not in variants:
        hint = _quote_hint(variant, variants)
        check.fail(f"{where}.variant", f"{variant!r} is not a variant: choose one of {choices}{hint}")
    others = item.get("others", [])
    if isinstance(others, str):
        others = [others]
    elif not isinstance(others, list):
        hint = _quote_hint(others, variants)
        check.fail(f"{where}.others", f"{others!r}: a variant's name or a list of names, e.g. others: [n_steps=1]{hint}")
        others = []
    for other in others:
        if variants and other not in variants:
            check.fail(f"{where}.others", f"{other!r} is not a variant: choose among {choices}{_quote_hint(other, variants)}")
    if kind in ("better", "similar") and not others:
        check.fail(f"{where}.others", f"a {kind!r} claim compares `variant` with `others`: name at least one")
    if variant in others:
        check.fail(f"{where}.others", f"{variant!r} is compared with itself")
    metric = item.get("metric", "mean_return")
    if metric not in METRICS:
        check.fail(f"{where}.metric", f"{metric!r}: choose one of {', '.join(METRICS)}")
    statistic = item.get("statistic", "mean")
    if statistic not in STATISTICS:
        check.fail(f"{where}.statistic", f"{statistic!r}: choose mean or std (the spread over seeds)")
    margin = item.get("margin")
    if kind == "similar" and (not _is_number(margin) or margin <= 0):
        check.fail(f"{where}.margin", "a 'similar' claim needs the largest difference counted as similar, e.g. margin: 25")
    value = item.get("value", threshold if kind in ("reaches", "below") and metric != "episodes_to_threshold" else None)
    # (a level taken from a missing threshold: the threshold's own message says it)
    if kind in ("reaches", "below") and not _is_number(value) and ("value" in item or math.isfinite(threshold)):
        check.fail(f"{where}.value", f"{value!r}: the level to reach (or stay below), a finite number, e.g. value: 475")
    return Claim(
        text=str(item.get("text", "")).strip(),
        kind=str(kind),
        variant=str(variant),
        others=tuple(str(other) for other in others),
        metric=str(metric),
        statistic=str(statistic),
        margin=float(margin) if _is_number(margin) else None,
        value=float(value) if _is_number(value) else None,
    )
