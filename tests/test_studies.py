"""Hyperparameter studies: the study file's checks, the statistics and verdicts, the episode budget, the
seed report's study files, and a tiny study run end to end by the command."""

import contextlib
import dataclasses
import hashlib
import inspect
import io
import json
import math
import queue
import re
import shlex
import shutil
import signal
import subprocess
import sys
import threading
import time
import warnings
from collections.abc import Iterator
from concurrent.futures import Future
from pathlib import Path
from typing import Any

import matplotlib.figure
import matplotlib.pyplot as plt
import matplotlib.text
import numpy as np
import pandas as pd
import pytest
import yaml
from rich.console import Console

from benchmarks.common import REPO_ROOT
from benchmarks.studies import SEED_REPORT_STUDIES
from sb3_classic import REINFORCE, NStepSARSA
from sb3_classic.harness import lockstep, pool
from sb3_classic.harness.common import RunSpec, code_versions
from sb3_classic.harness.runner import check_run, execute_run
from sb3_classic.studies import cli as studies_cli
from sb3_classic.studies import outputs, stats, untrained
from sb3_classic.studies.spec import STATED, Claim, StudyError, load_study, policy_kwargs_string

TINY = """
title: Tiny
env: CartPole-v1
algo: nstep_sarsa
seeds: 2
budget: {episodes: 6}
hyperparams:
  policy: MlpPolicy
  learning_rate: !!float 1e-3
  train_freq: 1
  gradient_steps: 1
  policy_kwargs: {net_arch: [16], weight_init: kaiming}
variants:
  n1: {n_steps: 1}
  n3: {n_steps: 3, policy_kwargs: {net_arch: [8]}}
claim: {text: "n = 3 beats n = 1", kind: better, variant: n3, others: [n1]}
threshold_window: 3
smooth: 2
"""


def write_study(tmp_path: Path, text: str, name: str = "study.yml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_a_study_file_loads_into_runs(tmp_path: Path) -> None:
    study = load_study(write_study(tmp_path, TINY))
    assert study.name == "study"
    assert list(study.variants) == ["n1", "n3"]
    assert list(study.readings) == [STATED]
    # policy_kwargs mappings merge key by key and become the zoo's string
    assert study.zoo_entry("n3")["policy_kwargs"] == "dict(net_arch=[8], weight_init='kaiming')"
    assert study.zoo_entry("n1")["policy_kwargs"] == "dict(net_arch=[16], weight_init='kaiming')"
    runs = study.runs()
    assert [(run.variant, run.seed) for run in runs] == [("n1", 0), ("n3", 0), ("n1", 1), ("n3", 1)]
    spec = runs[1].spec
    assert spec.max_episodes == 6
    # Every episode at CartPole-v1's time limit (500), and the unfinished one of the env
    assert spec.n_timesteps == (6 + 1) * 500
    assert spec.hyperparams["n_steps"] == 3
    assert spec.name == "study n3 seed 0"
    assert len({run.spec.key() for run in runs}) == 4


def test_policy_kwargs_string() -> None:
    kwargs = {"net_arch": [256], "activation_fn": "nn.LeakyReLU", "activation_kwargs": {"negative_slope": 0.1}}
    expected = "dict(activation_fn=nn.LeakyReLU, activation_kwargs=dict(negative_slope=0.1), net_arch=[256])"
    assert policy_kwargs_string(kwargs) == expected
    # A mapping's order means nothing, and the string is in each run's cache key: reordered, the keys all changed
    assert policy_kwargs_string(dict(reversed(kwargs.items()))) == expected


def test_tile_coding_is_a_name_in_the_mapping_form(tmp_path: Path) -> None:
    """
    ``features_extractor_class: TileCoding`` in a mapping is the zoo's name, as in its string (it was the string
    'TileCoding', and the check before any run failed with "'str' object is not callable", naming no field).
    """
    text = """
title: Tiles
env: MountainCar-v0
algo: nstep_sarsa
seeds: 2
budget: {steps: 400}
hyperparams:
  policy: MlpPolicy
  update_mode: per_step
  train_freq: 1
  gradient_steps: 1
  policy_kwargs:
    net_arch: []
    with_bias: false
    optimizer_class: th.optim.SGD
    features_extractor_class: TileCoding
    features_extractor_kwargs: {n_tilings: 8, tiles_per_dim: 8}
variants:
  n1: {n_steps: 1}
  four_tilings: {n_steps: 1, policy_kwargs: {features_extractor_kwargs: {n_tilings: 4, tiles_per_dim: 8}}}
claim: {text: "8 tilings beat 4", kind: better, variant: n1, others: [four_tilings]}
"""
    study = load_study(write_study(tmp_path, text))
    entry = study.zoo_entry("four_tilings")
    assert "features_extractor_class=TileCoding," in entry["policy_kwargs"]
    assert "features_extractor_kwargs=dict(n_tilings=4, tiles_per_dim=8)" in entry["policy_kwargs"]
    for run in study.runs():
        if run.spec.seed == 0:
            check_run(run.spec)  # builds the model as the zoo does: raises if the class were a string


def test_readings_reinterpret_the_settings_a_variant_has_or_the_study_leaves_unstated(tmp_path: Path) -> None:
    text = TINY.replace(
        "claim:", "readings:\n  halved: {lr_decay_factor: 0.5, learning_rate: 0.002, td_lambda: 0.8}\nclaim:"
    ).replace("n1: {n_steps: 1}", "n1: {n_steps: 1, lr_decay_every: 10, lr_decay_factor: 0.1}")
    study = load_study(write_study(tmp_path, text))
    assert study.zoo_entry("n1", "halved")["lr_decay_factor"] == 0.5
    assert study.zoo_entry("n1", "halved")["learning_rate"] == 0.002
    # n3 has no decay: the reading's factor is not added to it
    assert "lr_decay_factor" not in study.zoo_entry("n3", "halved")
    # λ, which the study states nowhere (the algorithm's default), is read otherwise in every variant
    assert study.zoo_entry("n1", "halved")["td_lambda"] == study.zoo_entry("n3", "halved")["td_lambda"] == 0.8
    assert "td_lambda" not in study.zoo_entry("n3")
    assert len(study.runs()) == 8
    assert study.runs()[0].spec.label == "study n1 seed 0"
    assert study.runs()[2].spec.label == "study n1 [halved] seed 0"


def test_a_study_file_without_its_budget_or_claim_names_both(tmp_path: Path) -> None:
    text = TINY.replace("budget: {episodes: 6}\n", "").split("claim:")[0]
    with pytest.raises(StudyError) as refused:
        load_study(write_study(tmp_path, text))
    assert "budget: missing" in str(refused.value), str(refused.value)
    assert "claim: give exactly one of `claim:`" in str(refused.value), str(refused.value)


def test_a_number_varied_as_a_string_names_its_variant_as_once_fixed(tmp_path: Path) -> None:
    # The claim's suggestion must be the name the variant has once the value is written as a number
    text = TINY.replace("variants:\n  n1: {n_steps: 1}\n  n3: {n_steps: 3, policy_kwargs: {net_arch: [8]}}\n", "")
    text = text.replace("  learning_rate: !!float 1e-3\n", "")
    text = text.replace("claim: {", "vary: {learning_rate: [1e-3, 1e-4]}\nclaim: {")
    with pytest.raises(StudyError) as refused:
        load_study(write_study(tmp_path, text))
    assert "'learning_rate=0.001', 'learning_rate=0.0001'" in str(refused.value), str(refused.value)
    fixed = text.replace("[1e-3, 1e-4]", "[!!float 1e-3, !!float 1e-4]")
    fixed = fixed.replace("variant: n3, others: [n1]", "variant: learning_rate=0.001, others: [learning_rate=0.0001]")
    assert list(load_study(write_study(tmp_path, fixed)).variants) == [
        "learning_rate=0.001",
        "learning_rate=0.0001",
    ]


@pytest.mark.parametrize(
    ("change", "expected"),
    [
        (("hyperparams:", "hyperparms:"), ["hyperparms: unknown field: did you mean 'hyperparams'?", "hyperparams: missing"]),
        (
            ("train_freq: 1", "train_frequency: 1"),
            ["hyperparams.train_frequency: nstep_sarsa has no argument", "'train_freq'"],
        ),
        (
            ("learning_rate: !!float 1e-3", "learning_rate: 1e-3"),
            ["hyperparams.learning_rate: '1e-3' is read as a string by YAML: write !!float 1e-3, or 0.001"],
        ),
        (("budget: {episodes: 6}", "budget: {episodes: -6}"), ["budget.episodes: -6 is not a positive integer"]),
        (("others: [n1]", "others: [n2]"), ["claim.others: 'n2' is not a variant"]),
        (("kind: better", "kind: beats"), ["claim.kind: 'beats': choose one of better, similar, reaches, below"]),
        (("kind: better", "kind: similar"), ["claim.margin: a 'similar' claim needs"]),
        (("seeds: 2", "seeds: [0, 0]"), ["seeds: [0, 0]: a seed appears twice"]),
        (("env: CartPole-v1", "env: CartPole-v9"), ["env: 'CartPole-v9' is not a registered Gymnasium env"]),
        (("algo: nstep_sarsa", "algo: sarsa"), ["algo: 'sarsa' is not an algorithm of rl-zoo3"]),
        (("  policy: MlpPolicy", "  policy: MlpPolicy\n  n_timesteps: 1000"), ["hyperparams.n_timesteps: the budget is"]),
        (("variants:", "vary: {n_steps: [1, 3]}\nvariants:"), ["variants: give exactly one of `vary:`"]),
        (("others: [n1]", "others: 5"), ["claim.others: 5: a variant's name or a list of names"]),
        (("env: CartPole-v1", "env: 5"), ["env: 5: the id of a registered Gymnasium env"]),
        (("algo: nstep_sarsa", "algo: [nstep_sarsa]"), ["algo: ['nstep_sarsa'] is not an algorithm of rl-zoo3"]),
        (("seeds: 2", "seeds: 2\nseeds: 3"), ["'seeds' is given twice in one mapping: keep one"]),
        (("budget: {episodes: 6}", "budget: {episode: 6}"), ["budget: {'episode': 6} ('episode': did you mean 'episodes'?)"]),
        (("budget: {episodes: 6}", "budget: {episodes: 6, steps: 100}"), ["budget: give episodes or steps, not both"]),
        (("{text:", "{txt:"), ["claim.txt: unknown field: did you mean 'text'?", "claim.text: missing: the claim"]),
        # A misspelt top-level field is said with the file's other problems, not alone before them
        (
            ("seeds: 2\nbudget: {episodes: 6}", "seed: 2\nbudget: {episodes: -6}"),
            ["seed: unknown field: did you mean 'seeds'?", "budget.episodes: -6 is not a positive integer"],
        ),
        # Each was taken: outputs written outside the results folder (or as hidden files), a seed `True`, a margin of
        # `true` (1), a threshold of .nan, a level of .inf, and the zoo's "multiple values for keyword argument 'seed'"
        (("title: Tiny", "study: ../escaped/name\ntitle: Tiny"), ["study: '../escaped/name': the name of the study's output"]),
        (("title: Tiny", "study: ''\ntitle: Tiny"), ["study: '': the name of the study's output files"]),
        (("seeds: 2", "seeds: [0, true]"), ["seeds: [0, True]: give a number of seeds"]),
        (("kind: better", "kind: similar, margin: true"), ["claim.margin: a 'similar' claim needs"]),
        (
            ("threshold_window: 3", "threshold_window: 3\nthreshold: .nan"),
            ["threshold: nan: give the return", "a finite number"],
        ),
        (("kind: better", "kind: reaches, value: .inf"), ["claim.value: inf: the level to reach", "a finite number"]),
        (("  policy: MlpPolicy", "  policy: MlpPolicy\n  seed: 3"), ["hyperparams.seed: each run's seed comes from"]),
        # Variants named by numbers are strings to the loader; YAML reads a claim's 3 as an int
        (("n1: {n_steps: 1}", "'1': {n_steps: 1}"), ["claim.others: 'n1' is not a variant"]),
        (("others: [n1]", "others: [1]"), ["claim.others: 1 is not a variant"]),
        # Levels CartPole-v1 cannot give (returns 1 to 500): "not supported" or "supported" after the runs
        (
            ("threshold_window: 3", "threshold_window: 3\nthreshold: 600"),
            ["threshold: 600: CartPole-v1's returns lie in [1, 500]", "no seed can reach it"],
        ),
        (("threshold_window: 3", "threshold_window: 3\nthreshold: -10"), ["every seed reaches it in its first episodes"]),
        (("kind: better", "kind: reaches, value: 1000"), ["claim.value: 1000: CartPole-v1's returns lie in [1, 500]"]),
        # Not a number: its own message only (it said too that "every seed reaches" nan)
        (("threshold_window: 3", "threshold_window: 3\nthreshold: abc"), ["threshold: 'abc': give the return"]),
        # An env of one's own: how to register it, and Gymnasium's module:EnvId form (it was "not a registered
        # Gymnasium env" with no way shown). The ids are ones no test registers: Gymnasium's registry is global to
        # the process, and the docs' examples and the chain_env study register Chain-v0 and ShortChain-v0 in it
        (
            ("env: CartPole-v1", "env: Unregistered-v0"),
            ["env: 'Unregistered-v0' is not a registered Gymnasium env", "gymnasium.register(", "env: mychain:Chain-v0"],
        ),
        (
            ("env: CartPole-v1", "env: no_such_module_here:Chain-v0"),
            ["env: 'no_such_module_here:Chain-v0': its module 'no_such_module_here' cannot be imported", "PYTHONPATH"],
        ),
        (
            ("env: CartPole-v1", "env: chain_env:Unregistered-v0"),
            [
                "importing 'chain_env' registers no env 'Unregistered-v0'",
                "gymnasium.register(id='Unregistered-v0', entry_point=...)",
            ],
        ),
        (("env: CartPole-v1", "env: a:b:Chain-v0"), ["env: 'a:b:Chain-v0': the id of a registered", "module:EnvId"]),
        (
            ("  policy: MlpPolicy", "  policy: MlpPolicy\n  env_kwargs: [3]"),
            ["hyperparams.env_kwargs: [3]: a mapping of the env's keyword arguments"],
        ),
        # What rl-zoo3 reads when the run starts, read at load: "fast" passed --list and stopped the run with
        # "ValueError: not enough values to unpack (expected 2, got 1)"
        (
            ("learning_rate: !!float 1e-3", "learning_rate: fast"),
            ["hyperparams.learning_rate: 'fast': rl-zoo3 cannot read it (ValueError:", "a number", "lin_1e-3"],
        ),
        (("n3: {n_steps: 3,", "n3: {learning_rate: lin_fast, n_steps: 3,"), ["variants.n3.learning_rate: 'lin_fast'"]),
        (("learning_rate: !!float 1e-3", "learning_rate: [0.1]"), ["hyperparams.learning_rate: [0.1]: rl-zoo3 cannot"]),
        # The zoo reads any NAME_value as its linear schedule
        (("learning_rate: !!float 1e-3", "learning_rate: exp_0.01"), ["'exp_0.01': rl-zoo3 reads every", "write lin_0.01"]),
        (
            ("  policy: MlpPolicy", "  policy: MlpPolicy\n  env_wrapper: gymnasium.wrappers.NoSuchWrapper"),
            ["hyperparams.env_wrapper: 'gymnasium.wrappers.NoSuchWrapper': rl-zoo3 cannot read it", "module.Class"],
        ),
    ],
)
def test_study_file_errors_name_the_field_and_the_fix(tmp_path: Path, change: tuple[str, str], expected: list[str]) -> None:
    old, new = change
    assert old in TINY
    path = write_study(tmp_path, TINY.replace(old, new, 1))
    with pytest.raises(StudyError) as error:
        load_study(path)
    message = str(error.value)
    assert str(path) in message
    for part in expected:
        assert part in message
    # One message per problem: a threshold that is not a number was also said to lie outside the env's returns
    assert sum(line.strip().startswith("threshold:") for line in message.splitlines()) <= 1


def test_hyperparameters_load_as_the_zoo_reads_them(tmp_path: Path) -> None:
    # The zoo's schedules and wrappers, and a variant's env_kwargs merged key by key into the base's
    text = TINY.replace("learning_rate: !!float 1e-3", "learning_rate: lin_1e-3\n  env_kwargs: {sutton_barto_reward: true}")
    text = text.replace("n3: {n_steps: 3,", "n3: {env_kwargs: {max_episode_steps: 50}, n_steps: 3,")
    study = load_study(write_study(tmp_path, text))
    assert study.zoo_entry("n1")["learning_rate"] == "lin_1e-3"
    assert study.zoo_entry("n3")["env_kwargs"] == {"sutton_barto_reward": True, "max_episode_steps": 50}
    # The time limit of env_kwargs is the episode budget's cap: (6 episodes + 1 env) × 50 steps
    assert study.zoo_entry("n3")["n_timesteps"] == 7 * 50
    assert study.zoo_entry("n1")["n_timesteps"] == 7 * 500
    # REINFORCE's second step size is read as the zoo reads learning_rate
    reinforce = TINY.replace("algo: nstep_sarsa", "algo: reinforce").replace("  train_freq: 1\n  gradient_steps: 1\n", "")
    reinforce = reinforce.replace("n1: {n_steps: 1}", "n1: {value_learning_rate: fast}").replace("n_steps: 3, ", "")
    with pytest.raises(StudyError, match=re.escape("variants.n1.value_learning_rate: 'fast': rl-zoo3 cannot read it")):
        load_study(write_study(tmp_path, reinforce, "reinforce.yml"))


def test_a_variant_with_its_own_time_limit_may_have_a_threshold_beyond_the_envs(tmp_path: Path) -> None:
    # The return-range check looked at the base settings only: a variant's TimeLimit of 2,000 steps was refused
    wrapper = "env_wrapper: [{gymnasium.wrappers.TimeLimit: {max_episode_steps: 2000}}]"
    text = TINY.replace("n3: {n_steps: 3,", f"n3: {{{wrapper}, n_steps: 3,").replace(
        "threshold_window: 3", "threshold_window: 3\nthreshold: 1000"
    )
    assert load_study(write_study(tmp_path, text)).threshold == 1000


def test_a_folder_of_study_files_lists_every_bad_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # It stopped at the first file's errors
    write_study(tmp_path, TINY.replace("algo: nstep_sarsa", "algo: sarsa"), "a.yml")
    write_study(tmp_path, TINY, "b.yml")
    write_study(tmp_path, TINY.replace("seeds: 2", "seeds: 0"), "c.yml")
    assert studies_cli.main([str(tmp_path), "--list", "--cache-dir", str(tmp_path / "cache")]) == 2
    output = " ".join(capsys.readouterr().out.split())
    assert "a.yml: 1 problem(s): algo: 'sarsa' is not an algorithm" in output
    assert "c.yml: 1 problem(s): seeds: 0: give the number of seeds" in output
    assert "b.yml" not in output


def test_a_variant_named_by_a_number_is_quoted_in_the_hint(tmp_path: Path) -> None:
    text = TINY.replace("n1: {n_steps: 1}", "'1': {n_steps: 1}").replace("others: [n1]", "others: [1]")
    with pytest.raises(
        StudyError,
        match=re.escape("1 is not a variant: choose among '1', 'n3' (YAML reads 1 as a number, not a name: quote it, '1')"),
    ):
        load_study(write_study(tmp_path, text))


def test_study_file_errors_are_all_listed_at_once(tmp_path: Path) -> None:
    text = (
        TINY.replace("train_freq: 1", "train_frq: 1").replace("others: [n1]", "others: [n9]").replace("seeds: 2", "seeds: 0")
    )
    with pytest.raises(StudyError, match=r"3 problem\(s\)") as error:
        load_study(write_study(tmp_path, text))
    assert "did you mean 'train_freq'" in str(error.value)


@pytest.mark.parametrize(
    ("changes", "expected"),
    [
        # A reading that sets what the study states would run the same as stated, silently
        ([("claim:", "readings:\n  freq: {train_freq: 1}\nclaim:")], "readings.freq: changes no run"),
        # A reading of what tells the variants apart would make them one run
        (
            [
                ("n3: {n_steps: 3, policy_kwargs: {net_arch: [8]}}", "n3: {n_steps: 3}"),
                ("claim:", "readings:\n  n5: {n_steps: 5}\nclaim:"),
            ],
            "readings.n5: makes variants 'n1' and 'n3' the same run",
        ),
        # A reading's policy_kwargs mapping would replace a variant's string whole
        (
            [
                ("n3: {n_steps: 3, policy_kwargs: {net_arch: [8]}}", "n3: {n_steps: 3, policy_kwargs: 'dict(net_arch=[8])'}"),
                ("claim:", "readings:\n  relu: {policy_kwargs: {activation_fn: nn.ReLU}}\nclaim:"),
            ],
            "readings.relu.policy_kwargs: would replace the whole policy_kwargs string of variant 'n3'",
        ),
        # Two claims of one text: STUDIES.md would show the first's verdict for both
        (
            [
                ("claim: {", "claims:\n  - {"),
                ("others: [n1]}", 'others: [n1]}\n  - {text: "n = 3 beats n = 1", kind: reaches, variant: n3, value: 100}'),
            ],
            "claims: the text 'n = 3 beats n = 1' is given to two claims",
        ),
        # With a budget in env steps, seeds complete different numbers of episodes: nothing to censor at
        (
            [
                ("budget: {episodes: 6}", "budget: {steps: 600}"),
                ("others: [n1]}", "others: [n1], metric: episodes_to_threshold}"),
            ],
            "claim.metric: episodes_to_threshold needs a budget in episodes",
        ),
    ],
)
def test_study_files_that_would_mislead_are_errors(tmp_path: Path, changes: list[tuple[str, str]], expected: str) -> None:
    text = TINY
    for old, new in changes:
        assert old in text
        text = text.replace(old, new, 1)
    with pytest.raises(StudyError, match=re.escape(expected)):
        load_study(write_study(tmp_path, text))


def test_the_step_cap_counts_each_variants_envs(tmp_path: Path) -> None:
    study = load_study(write_study(tmp_path, TINY.replace("n3: {n_steps: 3,", "n3: {n_steps: 3, n_envs: 4,")))
    # Every episode at CartPole-v1's time limit, and the unfinished episodes of the other envs
    assert study.zoo_entry("n1")["n_timesteps"] == (6 + 1) * 500
    assert study.zoo_entry("n3")["n_timesteps"] == (6 + 4) * 500


def test_vary_names_its_variants(tmp_path: Path) -> None:
    text = TINY.replace(
        "variants:\n  n1: {n_steps: 1}\n  n3: {n_steps: 3, policy_kwargs: {net_arch: [8]}}", "vary: {n_steps: [1, 3]}"
    )
    text = text.replace("variant: n3, others: [n1]", "variant: n_steps=3, others: [n_steps=1]")
    study = load_study(write_study(tmp_path, text))
    assert list(study.variants) == ["n_steps=1", "n_steps=3"]
    assert study.zoo_entry("n_steps=3")["n_steps"] == 3


# ---- statistics -------------------------------------------------------------------------------------------------


def metrics_of(
    values: list[float] | np.ndarray, metric: str = "mean_return", reached: list[bool] | np.ndarray | None = None
) -> dict[str, np.ndarray]:
    """:param reached: per seed, whether it reached the threshold (episodes to threshold: every seed, if None)"""
    metrics = {metric: np.asarray(values, dtype=float)}
    if metric == "episodes_to_threshold":
        metrics["reached"] = np.ones(len(values), dtype=bool) if reached is None else np.asarray(reached, dtype=bool)
    return metrics


def claim(kind: str = "better", **fields: object) -> Claim:
    return Claim(text="A beats B", kind=kind, variant="A", others=() if kind in ("reaches", "below") else ("B",), **fields)  # type: ignore[arg-type]


def test_verdicts_of_a_better_claim() -> None:
    rng = np.random.default_rng(0)
    high, low = 400 + rng.normal(0, 10, 10), 200 + rng.normal(0, 10, 10)
    same = 300 + rng.normal(0, 30, 10)
    assert stats.judge(claim(), {"A": metrics_of(high), "B": metrics_of(low)}).verdict == stats.SUPPORTED
    assert stats.judge(claim(), {"A": metrics_of(low), "B": metrics_of(high)}).verdict == stats.REVERSED
    # Two samples of the same distribution: the interval of the difference contains 0
    other = 300 + rng.normal(0, 30, 10)
    assert stats.judge(claim(), {"A": metrics_of(same), "B": metrics_of(other)}).verdict == stats.TOO_CLOSE
    # Fewer episodes to the threshold is better
    faster = claim(metric="episodes_to_threshold")
    episodes = {"A": metrics_of(low, "episodes_to_threshold"), "B": metrics_of(high, "episodes_to_threshold")}
    assert stats.judge(faster, episodes).verdict == stats.SUPPORTED
    # A lower spread over seeds is better
    consistent = claim(statistic="std")
    tight, wide = 300 + rng.normal(0, 1, 10), 300 + rng.normal(0, 100, 10)
    assert stats.judge(consistent, {"A": metrics_of(tight), "B": metrics_of(wide)}).verdict == stats.SUPPORTED


def test_a_spread_is_decided_only_where_the_permutation_test_agrees() -> None:
    consistent = claim(statistic="std")
    # Every seed of A solved, three of B's ten not: BCa's interval of the spreads' difference excludes 0, but three
    # seeds in ten off the optimum are what equal spreads give often (the permutation test: p ≈ 0.2)
    solved = np.full(10, 500.0)
    lumpy = np.array([500.0, 255.0, 500.0, 500.0, 268.0, 500.0, 500.0, 349.0, 500.0, 500.0])
    bca = stats.difference_interval(solved, lumpy, "std")
    assert bca.high < 0, bca
    assert stats.spread_p_value(solved, lumpy) > 0.1
    result = stats.judge(consistent, {"A": metrics_of(solved), "B": metrics_of(lumpy)})
    assert result.verdict == stats.TOO_CLOSE, result.measured
    assert "permutation test p = 0.2" in result.measured
    # Spreads a hundredfold apart: both agree
    rng = np.random.default_rng(3)
    tight, wide = 300 + rng.normal(0, 1, 10), 300 + rng.normal(0, 100, 10)
    assert stats.spread_p_value(tight, wide) < 0.001
    assert stats.judge(consistent, {"A": metrics_of(tight), "B": metrics_of(wide)}).verdict == stats.SUPPORTED


def test_the_spreads_permutation_test_holds_its_level_alike_or_shifted() -> None:
    # Equal spreads, means 200 apart, skewed values: shuffled seeds mix the two locations, so the test rejects at 10%
    # at most as often as 10% (100 pairs: at most 18, the binomial's 99.5% quantile)
    rng = np.random.default_rng(0)
    rejections = sum(
        stats.spread_p_value(rng.exponential(50, 10), 200 + rng.exponential(50, 10), seed=index, n_resamples=999) < 0.1
        for index in range(100)
    )
    assert rejections <= 18, rejections
    # Alike in distribution (lumpy, as returns are): at most 10% of 200 pairs up to the binomial's 99.5% quantile (ties
    # at 500 make the p-values discrete, so fewer is right too)
    pairs = np.where(rng.random((200, 2, 10)) < 0.8, 500.0, rng.uniform(0, 500, (200, 2, 10)))
    alike = sum(stats.spread_p_value(a, b, seed=index, n_resamples=999) < 0.1 for index, (a, b) in enumerate(pairs))
    assert alike <= 32, alike


def test_too_few_seeds_give_no_verdict() -> None:
    # Far apart, but 4 seeds: the interval excludes 0, the verdict still waits for MIN_SEEDS seeds
    high, low = np.array([400.0, 410.0, 405.0, 395.0]), np.array([200.0, 210.0, 205.0, 195.0])
    result = stats.judge(claim(), {"A": metrics_of(high), "B": metrics_of(low)})
    assert result.comparisons[0].verdict == stats.SUPPORTED
    assert result.verdict == stats.TOO_CLOSE
    assert "only 4 seeds" in result.measured
    five = {"A": metrics_of(np.append(high, 402.0)), "B": metrics_of(np.append(low, 202.0))}
    assert stats.judge(claim(), five).verdict == stats.SUPPORTED
    assert stats.judge(claim("reaches", value=300.0), {"A": metrics_of(high)}).verdict == stats.TOO_CLOSE


def test_a_claim_against_several_variants_needs_each() -> None:
    several = Claim(text="A beats B and C", kind="better", variant="A", others=("B", "C"))
    data = {"A": metrics_of(np.arange(10.0) + 100), "B": metrics_of(np.arange(10.0)), "C": metrics_of(np.arange(10.0) + 100.5)}
    result = stats.judge(several, data)
    assert [comparison.verdict for comparison in result.comparisons] == [stats.SUPPORTED, stats.TOO_CLOSE]
    assert result.verdict == stats.TOO_CLOSE
    data["C"] = metrics_of(np.arange(10.0) + 200)
    assert stats.judge(several, data).verdict == stats.NOT_SUPPORTED


def test_verdicts_of_similar_reaches_and_below() -> None:
    similar = claim("similar", margin=20.0)
    base = np.linspace(290, 310, 10)
    assert stats.judge(similar, {"A": metrics_of(base), "B": metrics_of(base + 2)}).verdict == stats.SUPPORTED
    assert stats.judge(similar, {"A": metrics_of(base), "B": metrics_of(base + 100)}).verdict == stats.NOT_SUPPORTED
    noisy = np.linspace(0, 600, 10)
    assert stats.judge(similar, {"A": metrics_of(noisy), "B": metrics_of(noisy[::-1] + 5)}).verdict == stats.TOO_CLOSE
    reaches = claim("reaches", value=475.0)
    assert stats.judge(reaches, {"A": metrics_of(np.linspace(480, 500, 10))}).verdict == stats.SUPPORTED
    assert stats.judge(reaches, {"A": metrics_of(np.linspace(100, 200, 10))}).verdict == stats.NOT_SUPPORTED
    assert stats.judge(reaches, {"A": metrics_of(np.linspace(400, 550, 10))}).verdict == stats.TOO_CLOSE
    below = claim("below", value=-100.0)
    assert stats.judge(below, {"A": metrics_of(np.linspace(-300, -200, 10))}).verdict == stats.SUPPORTED
    assert stats.judge(below, {"A": metrics_of(np.linspace(-90, -80, 10))}).verdict == stats.NOT_SUPPORTED
    # On the metric's own scale, also where lower is better: episodes to the threshold, the spread over seeds
    fast = metrics_of(np.linspace(100, 150, 10), "episodes_to_threshold")
    assert stats.judge(claim("below", value=200.0, metric="episodes_to_threshold"), {"A": fast}).verdict == stats.SUPPORTED
    assert (
        stats.judge(claim("reaches", value=200.0, metric="episodes_to_threshold"), {"A": fast}).verdict == stats.NOT_SUPPORTED
    )
    spread = metrics_of(300 + np.random.default_rng(0).normal(0, 16, 10))
    assert stats.judge(claim("below", value=100.0, statistic="std"), {"A": spread}).verdict == stats.SUPPORTED


def test_censored_episodes_to_threshold_give_no_verdict_they_cannot_support() -> None:
    """
    A seed that never reaches the threshold counts as the budget (60 here), a lower bound. With no seed reaching it,
    "below 100 episodes" was supported (60 < 100) and two variants were "alike" (+0.0 [+0.0, +0.0]).
    """
    budget = np.full(10, 60.0)
    never = metrics_of(budget, "episodes_to_threshold", reached=np.zeros(10, dtype=bool))
    below = claim("below", value=100.0, metric="episodes_to_threshold")
    result = stats.judge(below, {"A": never})
    assert result.verdict == stats.TOO_CLOSE
    assert "never reached the threshold, counted as the budget: A 10/10" in result.measured
    assert stats.judge(claim("similar", margin=5.0, metric="episodes_to_threshold"), {"A": never, "B": never}).verdict == (
        stats.TOO_CLOSE
    )
    assert stats.judge(claim(metric="episodes_to_threshold"), {"A": never, "B": never}).verdict == stats.TOO_CLOSE
    # Censoring only hides larger values: at or above a level stands ("reaches 50": every seed took at least 60)
    assert stats.judge(claim("reaches", value=50.0, metric="episodes_to_threshold"), {"A": never}).verdict == stats.SUPPORTED
    # Within the budget, one variant reaching it earlier stands (the restricted means: fig 27's 4/10 against 0/10)
    rng = np.random.default_rng(0)
    some = np.concatenate([20 + rng.normal(0, 2, 6), budget[:4]])
    partly = metrics_of(some, "episodes_to_threshold", reached=[True] * 6 + [False] * 4)
    faster = stats.judge(claim(metric="episodes_to_threshold"), {"A": partly, "B": never})
    assert faster.verdict == stats.SUPPORTED
    assert "A 4/10, B 10/10" in faster.measured
    # ... but not shown below a level, nor alike, nor in its spread
    assert stats.judge(below, {"A": partly}).verdict == stats.TOO_CLOSE
    reached = metrics_of(some[:6].tolist() * 2, "episodes_to_threshold")
    assert stats.judge(below, {"A": reached}).verdict == stats.SUPPORTED
    similar = claim("similar", margin=50.0, metric="episodes_to_threshold")
    assert stats.judge(similar, {"A": reached, "B": reached}).verdict == stats.SUPPORTED
    assert stats.judge(similar, {"A": reached, "B": partly}).verdict == stats.TOO_CLOSE
    spread = claim(metric="episodes_to_threshold", statistic="std")
    assert stats.judge(spread, {"A": reached, "B": partly}).verdict == stats.TOO_CLOSE


def test_a_budget_in_steps_gives_each_seed_its_own_episodes() -> None:
    # Acrobot-like: seed 0 never learns (200 episodes of -500), seed 1 reaches -90 from episode 150 (900 episodes)
    frames = [
        pd.DataFrame({"return": np.full(200, -500.0)}),
        pd.DataFrame({"return": np.concatenate([np.full(149, -500.0), np.full(751, -90.0)])}),
    ]
    returns = stats.seed_returns(frames)
    metrics = stats.seed_metrics(returns, threshold=-100.0, window=100)
    np.testing.assert_allclose(metrics["last_100_return"], [-500.0, -90.0])
    assert metrics["reached"].tolist() == [False, True]
    # Seed 1: the first window of 100 whose mean reaches -100 holds at most two -500s (episodes 148-149), so it ends at
    # episode 247; seed 0 is censored at its 200
    assert metrics["episodes_to_threshold"].tolist() == [200.0, 247.0]
    # The figure draws the episodes every seed has
    assert stats.returns_matrix(returns).shape == (2, 200)
    # An episode budget: each seed's first episodes
    assert [len(row) for row in stats.seed_returns(frames, 150)] == [150, 150]
    with pytest.raises(ValueError, match="only 200 episodes"):
        stats.seed_returns(frames, 300)


def test_intervals() -> None:
    values = np.arange(10.0)
    interval = stats.interval(values)
    assert interval.estimate == 4.5
    assert 2.0 < interval.low < 4.5 < interval.high < 7.0
    assert stats.interval(np.full(10, 3.0)) == stats.Interval(3.0, 3.0, 3.0)
    assert np.isnan(stats.interval(np.array([1.0])).low)
    difference = stats.difference_interval(values + 10, values)
    assert difference.estimate == pytest.approx(10.0)
    assert 5.0 < difference.low < 10.0 < difference.high < 15.0


def test_episode_metrics() -> None:
    returns = np.array(
        [
            [10.0, 20.0, 480.0, 490.0, 500.0, 500.0],
            [10.0, 10.0, 10.0, 10.0, 500.0, 10.0],
        ]
    )
    np.testing.assert_allclose(stats.moving_average(returns[:1], 2), [[10.0, 15.0, 250.0, 485.0, 495.0, 500.0]])
    first, reached = stats.episodes_to_threshold(returns, 475.0, window=2)
    # Seed 0: episodes 3 and 4 are the first window of 2 whose mean reaches 475; seed 1 never does (counted as 6)
    assert first.tolist() == [4.0, 6.0]
    assert reached.tolist() == [True, False]
    metrics = stats.seed_metrics(returns, 475.0, window=2)
    np.testing.assert_allclose(metrics["mean_return"], returns.mean(axis=1))
    np.testing.assert_allclose(metrics["last_100_return"], returns.mean(axis=1))
    mean, low, high = stats.episode_band(returns)
    np.testing.assert_allclose(mean, returns.mean(axis=0))
    assert (low <= mean).all()
    assert (mean <= high).all()


# ---- the harness's episode budget --------------------------------------------------------------------------------


@pytest.mark.parametrize(("algo", "n_envs", "at_least"), [("nstep_sarsa", 1, 7), ("reinforce", 1, 7), ("reinforce", 2, 7)])
def test_an_episode_budget_stops_training(algo: str, n_envs: int, at_least: int) -> None:
    spec = RunSpec(
        algo=algo,
        env_id="CartPole-v1",
        seed=0,
        n_timesteps=100_000,
        eval_freq=0,
        n_eval_episodes=1,
        hyperparams_yaml=f"n_timesteps: 100000\npolicy: MlpPolicy\nn_envs: {n_envs}\n",
        max_episodes=7,
        label="budget",
    )
    result = execute_run(spec)
    episodes = pd.read_csv(io.BytesIO(result.files["episodes.csv"]))
    if n_envs == 1:
        assert len(episodes) == 7
    else:
        # SB3's callback counts ceil(7 / 2) = 4 per env: at least 7 in all, at most one more per env
        assert 7 <= len(episodes) <= 8
    assert result.summary["n_episodes"] == len(episodes)
    if n_envs == 1:
        assert result.summary["num_timesteps"] == episodes["length"].sum()
    assert result.summary["max_episodes"] == 7
    # Only the final evaluation (eval_freq 0)
    assert json.loads(result.files["run.json"])["num_timesteps"] < 100_000
    evaluations = pd.read_csv(io.BytesIO(result.files["evaluations.csv"]))
    assert evaluations["eval_index"].unique().tolist() == [0]


def test_step_budget_keys_are_unchanged() -> None:
    """Runs cached before episode budgets existed keep their keys (and their folders)."""
    spec = RunSpec("reinforce", "CartPole-v1", 3, 1000, 500, 2, "learning_rate: 0.003\npolicy: MlpPolicy\n")
    content = {
        "algo": "reinforce",
        "env_id": "CartPole-v1",
        "seed": 3,
        "n_timesteps": 1000,
        "eval_freq": 500,
        "n_eval_episodes": 2,
        "hyperparams": {"learning_rate": 0.003, "policy": "MlpPolicy"},
        "versions": code_versions("reinforce"),
    }
    assert spec.key() == hashlib.sha256(json.dumps(content, sort_keys=True).encode()).hexdigest()[:16]
    assert spec.run_dir(Path("c")).name == f"1000-{spec.key()}"
    budgeted = RunSpec(
        "reinforce", "CartPole-v1", 3, 1000, 500, 2, "learning_rate: 0.003\npolicy: MlpPolicy\n", max_episodes=5
    )
    assert budgeted.key() != spec.key()
    assert budgeted.run_dir(Path("c")).name == f"5ep-{budgeted.key()}"


# ---- the seed report's study files -------------------------------------------------------------------------------

#: The report's comparisons (Figs 2–7, 9–17, 20–23, 25–29) and final models (Figs 8, 18, 24, 30)
REPORT_FIGURES = [*range(2, 19), *range(20, 31)]
PER_STEP_MODE = all("update_mode" in inspect.signature(algo.__init__).parameters for algo in (REINFORCE, NStepSARSA))


def test_every_figure_of_the_report_has_a_study_file() -> None:
    figures = sorted(int(path.name[3:5]) for path in SEED_REPORT_STUDIES.glob("fig*.yml"))
    assert figures == REPORT_FIGURES


@pytest.mark.skipif(not PER_STEP_MODE, reason="the studies use update_mode='per_step'")
def test_the_report_studies_load() -> None:
    runs = 0
    for path in sorted(SEED_REPORT_STUDIES.glob("*.yml")):
        study = load_study(path)
        assert len(study.seeds) >= 10, f"{path.name}: at least 10 seeds (twice the report's 5)"
        final = "final" in path.stem
        assert study.budget.episodes == (1000 if final else 500), path.name
        for variant in study.variants:
            entry = study.zoo_entry(variant)
            assert entry["update_mode"] == "per_step", path.name
            assert entry["n_envs"] == 1, path.name
        assert study.notes, f"{path.name}: say what the report leaves unstated"
        runs += len(study.runs())
    assert runs > 500


@pytest.mark.skipif(not PER_STEP_MODE, reason="the studies use update_mode='per_step'")
def test_every_setting_of_the_report_studies_builds() -> None:
    # The check the runner makes before it runs anything (each distinct setting's model built once), over every
    # committed study file: a variant the algorithm refuses (an option its schedule would ignore) fails here, not
    # when the study is run
    studies = [load_study(path) for path in sorted(SEED_REPORT_STUDIES.glob("*.yml"))]
    pending = {run.spec.key() for study in studies for run in study.runs()}
    assert studies_cli.check_settings(studies, pending, Console(file=io.StringIO())) == []


def test_settings_only_the_algorithm_can_judge_fail_before_any_run(tmp_path: Path) -> None:
    # A policy_kwargs key, an activation's name, an option's value: each variant's model is built once, before anything
    # runs, and every problem is named with its file and variant
    text = TINY.replace("n1: {n_steps: 1}", "n1: {n_steps: 1, update_mode: perstep}").replace("[8]}", "[8], net_arc: [4]}")
    study_file = write_study(tmp_path, text)
    cache = tmp_path / "cache"
    output = io.StringIO()
    with contextlib.redirect_stdout(output):
        status = studies_cli.main([str(study_file), "--cache-dir", str(cache), "--results-dir", str(tmp_path / "out")])
    assert status == 2
    printed = " ".join(output.getvalue().split())
    assert "Nothing was run" in printed
    assert f"{study_file}: variant 'n1': ValueError: update_mode='perstep' must be one of" in printed
    assert f"{study_file}: variant 'n3': TypeError:" in printed
    assert "'net_arc'" in printed
    assert not cache.exists() or not any(cache.rglob("run.json"))


def test_report_only_names_the_runs_not_run(tmp_path: Path) -> None:
    output = io.StringIO()
    with contextlib.redirect_stdout(output):
        status = studies_cli.main(
            [str(write_study(tmp_path, TINY)), "--report-only", "--cache-dir", str(tmp_path / "cache"), "--results-dir",
             str(tmp_path / "out")]
        )  # fmt: skip
    assert status == 1
    printed = " ".join(output.getvalue().split())
    assert "4 runs not run yet (this command runs nothing: run it without --report-only)" in printed
    assert "failed" not in printed


def test_reduced_runs_of_other_budgets_keep_their_own_outputs(tmp_path: Path) -> None:
    # A second reduced run of a study (another --seeds/--episodes) wrote over the first's report
    study_file, cache = write_study(tmp_path, TINY), tmp_path / "cache"
    for budget in (["--seeds", "1"], ["--seeds", "2", "--episodes", "3"]):
        with contextlib.redirect_stdout(io.StringIO()):
            studies_cli.main([str(study_file), "--report-only", "--cache-dir", str(cache), *budget])
    reduced = cache / studies_cli.REDUCED_RESULTS
    assert sorted(path.name for path in reduced.iterdir()) == ["seeds-1", "seeds-2_episodes-3"]
    assert "--seeds 1`" in (reduced / "seeds-1" / "STUDIES.md").read_text()
    assert "--seeds 2 --episodes 3`" in (reduced / "seeds-2_episodes-3" / "STUDIES.md").read_text()


@pytest.mark.parametrize(
    ("options", "message"),
    [
        # Each would otherwise run (or cache as done) nonsense: -5 episodes per run, 0 seeds, a table of nan, exit status 0
        (["--episodes", "-5"], "--episodes: '-5' is not an integer >= 1"),
        (["--steps", "0"], "--steps: '0' is not an integer >= 1"),
        (["--seeds", "0"], "--seeds: '0' is not an integer >= 1"),
        (["--workers", "0"], "--workers: '0' is not an integer >= 1"),
    ],
)
def test_reduced_run_counts_are_usage_errors(
    tmp_path: Path, options: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exit_:
        studies_cli.main([str(write_study(tmp_path, TINY)), "--list", "--cache-dir", str(tmp_path), *options])
    assert exit_.value.code == 2
    assert message in capsys.readouterr().err


def test_variants_that_are_the_same_run_are_refused(tmp_path: Path) -> None:
    # They were run (twice), compared, and a claim between them decided on noise ("too close to call" on +0.0)
    text = TINY.replace("  n3: {n_steps: 3,", "  again: {n_steps: 1, learning_rate: 0.001}\n  n3: {n_steps: 3,")
    with pytest.raises(StudyError, match=r"variants.again: the same run as variant 'n1'"):
        load_study(write_study(tmp_path, text))
    # A variant that differs in one setting is another run
    load_study(write_study(tmp_path, text.replace("learning_rate: 0.001}", "learning_rate: 0.002}"), "other.yml"))
    # One that writes out the algorithm's default (NStepSARSA's n_steps=3) is the same run as one that leaves it out
    default = TINY.replace("  n3: {n_steps: 3,", "  base: {}\n  three: {n_steps: 3}\n  n3: {n_steps: 3,")
    with pytest.raises(StudyError, match=r"variants.three: the same run as variant 'base'"):
        load_study(write_study(tmp_path, default, "default.yml"))


def test_a_step_budget_is_refused_where_a_claim_counts_episodes(tmp_path: Path) -> None:
    # The file's own check ("episodes_to_threshold needs a budget in episodes") was bypassed by --steps
    text = TINY.replace("others: [n1]}", "others: [n1], metric: episodes_to_threshold}")
    study = load_study(write_study(tmp_path, text))
    with pytest.raises(StudyError, match="--steps 300: a claim of this study is on episodes_to_threshold"):
        study.with_budget(steps=300)
    assert study.with_budget(episodes=3).budget.episodes == 3
    with pytest.raises(StudyError, match="--seeds 0: give an integer >= 1"):
        study.with_budget(seeds=0)
    output = io.StringIO()
    with contextlib.redirect_stdout(output):
        status = studies_cli.main([str(tmp_path / "study.yml"), "--list", "--cache-dir", str(tmp_path), "--steps", "300"])
    assert status == 2
    assert "give --episodes" in " ".join(output.getvalue().split())


def test_runs_shared_by_readings_or_studies_are_run_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # A variant under two readings, or two study files of the same run, trained it once per reference
    shared = RunSpec("reinforce", "CartPole-v1", 0, 1000, 500, 2, "policy: MlpPolicy\n", label="a seed 0")
    again = dataclasses.replace(shared, label="a [reading] seed 0")
    other = dataclasses.replace(shared, seed=1, label="a seed 1")
    ran: list[RunSpec] = []

    def run_pending(specs: list[RunSpec], *args: object) -> list[RunSpec]:
        ran.extend(specs)
        return []

    monkeypatch.setattr(pool, "run_pending", run_pending)
    output = io.StringIO()
    status = pool.run_missing_runs(3, [shared, again, other], 1, tmp_path, Console(file=output, width=200))
    assert status is None
    assert ran == [shared, other]
    assert "3 runs: 0 cached, 2 to run on 1 worker (1 of them the same runs as others)" in output.getvalue()


def test_the_overall_progress_moves_as_the_runs_train(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # It sat at 0% and then jumped as populations ended (its reports were read every 0.5 s, when a run's end had often
    # come first). A population of 2 runs that reports a quarter and a half of its env steps, then ends 0.4 s later
    base = RunSpec("reinforce", "CartPole-v1", 0, 1000, 0, 2, "policy: MlpPolicy\n", label="a seed 0", lockstep=True)
    specs = [base, dataclasses.replace(base, seed=1, label="a seed 1")]
    ended: list[float] = []

    class Population:
        progress: "queue.Queue[tuple[str, int]]" = queue.Queue()

        def submit_population(self, job: list[RunSpec]) -> "Future[list[Any]]":
            future: Future[list[Any]] = Future()

            def train() -> None:
                for steps in (250, 500):
                    for spec in job:
                        self.progress.put((spec.name, steps))
                    time.sleep(0.2)
                ended.append(time.perf_counter())
                future.set_result([None] * len(job))

            threading.Thread(target=train, daemon=True).start()
            return future

        def cancel(self) -> None:
            pass

    shown: list[tuple[float, str, float]] = []

    class Recorded(pool.Progress):
        def add_task(self, description: str, *args: Any, **kwargs: Any) -> Any:
            shown.append((time.perf_counter(), description, 0.0))
            return super().add_task(description, *args, **kwargs)

        def advance(self, task_id: Any, advance: float = 1) -> None:
            super().advance(task_id, advance)
            task = self.tasks[0]
            shown.append((time.perf_counter(), task.description, task.percentage))

    monkeypatch.setattr(pool, "open_runs", lambda *args: contextlib.nullcontext(Population()))
    monkeypatch.setattr(pool, "Progress", Recorded)
    monkeypatch.setattr(pool, "_store", lambda *args: None)
    assert pool.run_pending(specs, 1, tmp_path, Console(file=io.StringIO())) == []
    (end,) = ended
    before_the_end = [percentage for at, _, percentage in shown if at < end]
    assert before_the_end, shown
    assert 0 < max(before_the_end) <= 50
    # Until the first report it says the workers are building the models; then it counts the runs
    assert shown[0][1] == "2 runs (starting: building the models)"
    assert shown[-1][1:] == ("2 runs", 100)


def test_sigterm_stops_the_runs_as_ctrl_c_does(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """
    SIGTERM (``timeout``, a cluster job's time limit) during the runs: the message and an exit status, as Ctrl-C gets
    (it killed the command without a word), and the previous handler back afterwards.
    """
    if threading.current_thread() is not threading.main_thread():
        pytest.skip("Python runs signal handlers in the main thread only")
    spec = RunSpec("reinforce", "CartPole-v1", 0, 1000, 500, 2, "policy: MlpPolicy\n", label="a seed 0")
    for sent, status, message in ((signal.SIGTERM, 143, "Terminated (SIGTERM)"), (signal.SIGINT, 130, "Interrupted")):

        def run_pending(specs: list[RunSpec], *args: object, signum: int = sent) -> list[RunSpec]:
            # To this thread, its Python handler run before raise_signal returns: nothing left to the timing of a
            # process-wide os.kill and an interrupted sleep
            signal.raise_signal(signum)
            raise AssertionError("the signal should have stopped the runs")

        monkeypatch.setattr(pool, "run_pending", run_pending)
        output = io.StringIO()
        with signals_as_a_command_starts():
            before = signal.getsignal(signal.SIGTERM)
            assert pool.run_missing_runs(1, [spec], 1, tmp_path, Console(file=output, width=200)) == status
            assert signal.getsignal(signal.SIGTERM) is before
        assert f"{message}: the finished runs are cached; run the same command again to resume." in output.getvalue()


@contextlib.contextmanager
def signals_as_a_command_starts() -> Iterator[None]:
    """
    SIGINT and SIGTERM as in the main thread of a command Python starts (Ctrl-C raises KeyboardInterrupt, SIGTERM has
    its default action, neither blocked), whatever the test process's libraries did to them; restored afterwards.
    """
    handlers = {signum: signal.getsignal(signum) for signum in (signal.SIGINT, signal.SIGTERM)}
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    blocked = signal.pthread_sigmask(signal.SIG_UNBLOCK, handlers)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
        for signum, handler in handlers.items():
            signal.signal(signum, handler if handler is not None else signal.SIG_DFL)


def fake_cache(tmp_path: Path, text: str = TINY) -> tuple[Path, Path, Path]:
    """
    :return: the study file of ``text``, a cache holding each of its runs (6 episodes of return 9 + seed + 10 × variant
        n3), and a results folder
    """
    study_file = write_study(tmp_path, text)
    cache = tmp_path / "cache"
    for run in load_study(study_file).runs():
        run_dir = run.spec.run_dir(cache)
        run_dir.mkdir(parents=True)
        (run_dir / "run.json").write_text(json.dumps({"learn_time_s": 1.0, "eval_time_s": 0.0}))
        value = 9.0 + run.seed + 10 * (run.variant == "n3")
        (run_dir / "episodes.csv").write_text("return\n" + "\n".join([str(value)] * 6) + "\n")
    return study_file, cache, tmp_path / "results"


def test_the_outputs_give_each_seed_and_say_when_runs_are_missing(tmp_path: Path) -> None:
    study_file, cache, results = fake_cache(tmp_path)
    command = [str(study_file), "--report-only", "--cache-dir", str(cache), "--results-dir", str(results)]
    assert studies_cli.main(command) == 0
    # The values the intervals are computed from, one row per run (the CSV had the means and intervals only)
    seeds = pd.read_csv(results / "study-seeds.csv")
    assert seeds[["variant", "seed"]].values.tolist() == [["n1", 0], ["n1", 1], ["n3", 0], ["n3", 1]]
    assert seeds["mean_return"].tolist() == [9.0, 10.0, 19.0, 20.0]
    assert "Partial" not in (results / "study.md").read_text()
    # A run missing: its study's own page says the verdicts are partial (only STUDIES.md did)
    shutil.rmtree(load_study(study_file).runs()[0].spec.run_dir(cache))
    # (the page's record of it too: a run recorded in study-seeds.csv counts as run, test_sequential.py)
    (results / "study-seeds.csv").unlink()
    assert studies_cli.main(command) == 1
    page = (results / "study.md").read_text()
    assert "**Partial**: 1 of 4 runs are missing" in page
    assert "(partial: 1 runs missing): n = 3 beats n = 1" in page
    assert len(pd.read_csv(results / "study-seeds.csv")) == 3


def test_the_figure_keeps_a_long_title_within_it_and_counts_episodes_in_whole_numbers(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # A user's one-panel study with a long title: the title ran off both sides of the figure, and a run of a few
    # episodes had ticks at half episodes
    title = "Expected SARSA or not, on CartPole-v1, with the long title that a user may well give their own study"
    text = TINY.replace("title: Tiny", f"title: {title}").replace("episodes: 6", "episodes: 3")
    study_file, cache, results = fake_cache(tmp_path, text)
    for episodes in cache.rglob("episodes.csv"):
        episodes.write_text("return\n" + "\n".join(episodes.read_text().splitlines()[1:4]) + "\n")
    drawn: list[matplotlib.figure.Figure] = []
    monkeypatch.setattr(outputs.plt, "close", drawn.append)
    command = [str(study_file), "--report-only", "--cache-dir", str(cache), "--results-dir", str(results)]
    assert studies_cli.main(command) == 0
    (figure,) = drawn
    renderer = figure.canvas.get_renderer()  # type: ignore[attr-defined]
    suptitle = figure.get_suptitle()
    assert suptitle.replace("\n", " ").startswith(title), suptitle
    (drawn_title,) = (text for text in figure.findobj(matplotlib.text.Text) if text.get_text() == suptitle)
    box, frame = drawn_title.get_window_extent(renderer), figure.bbox
    assert frame.x0 <= box.x0, (box, frame)
    assert box.x1 <= frame.x1, (box, frame)
    (axis,) = figure.axes
    ticks = [tick for tick in axis.get_xticks() if axis.get_xlim()[0] <= tick <= axis.get_xlim()[1]]
    assert ticks
    assert all(float(tick).is_integer() for tick in ticks), ticks


def test_a_report_of_too_few_seeds_does_not_call_its_intervals_95_percent(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # A study of 2 seeds called its figure's band and its table's intervals 95% ones, which a bootstrap over fewer than
    # MIN_SEEDS values does not give (its verdicts were too close to call, said only beside each claim)
    titles: list[str] = []
    suptitle = matplotlib.figure.Figure.suptitle

    def recorded(figure: matplotlib.figure.Figure, text: str, **kwargs: Any) -> Any:
        titles.append(text)
        return suptitle(figure, text, **kwargs)

    monkeypatch.setattr(matplotlib.figure.Figure, "suptitle", recorded)
    pages = {}
    for n_seeds in (2, stats.MIN_SEEDS):
        folder = tmp_path / str(n_seeds)
        folder.mkdir()
        study_file, cache, results = fake_cache(folder, TINY.replace("seeds: 2", f"seeds: {n_seeds}"))
        command = [str(study_file), "--report-only", "--cache-dir", str(cache), "--results-dir", str(results)]
        assert studies_cli.main(command) == 0
        pages[n_seeds] = " ".join((results / "study.md").read_text().split())
    few, enough = pages[2], pages[stats.MIN_SEEDS]
    assert "- Intervals: 95% bootstrap over seeds (`scipy.stats.bootstrap`, BCa); verdicts" in enough
    assert "- Intervals: bootstrap over seeds (`scipy.stats.bootstrap`, BCa), at 95% but from 2 seeds, too few" in few
    assert "every verdict is too close to call" in few
    assert ["95% bootstrap band" in title for title in titles] == [False, True], titles
    assert "bootstrap band (2 seeds: too few for a 95% one)" in titles[0]
    # A partial run: the intervals are those of the seeds found
    shutil.rmtree(load_study(study_file).runs()[0].spec.run_dir(cache))
    # (the page's record of it too: a run recorded in study-seeds.csv counts as run, test_sequential.py)
    (results / "study-seeds.csv").unlink()
    assert studies_cli.main(command) == 1
    partial = " ".join((results / "study.md").read_text().split())
    assert f"at 95% but from {stats.MIN_SEEDS - 1} seeds, too few" in partial
    assert f"bootstrap band ({stats.MIN_SEEDS - 1} seeds: too few for a 95% one)" in titles[-1]


def test_the_settings_of_a_report_are_written_out_in_full(tmp_path: Path) -> None:
    # Two variants sharing a setting's value were written with a YAML anchor and alias (env_kwargs: &id001, then
    # env_kwargs: *id001): valid YAML, but not what a reader pastes into a zoo file
    shared = TINY.replace("  policy: MlpPolicy\n", "  policy: MlpPolicy\n  env_kwargs: {sutton_barto_reward: true}\n")
    study_file, cache, results = fake_cache(tmp_path, shared)
    command = [str(study_file), "--report-only", "--cache-dir", str(cache), "--results-dir", str(results)]
    assert studies_cli.main(command) == 0
    page = (results / "study.md").read_text()
    settings = page.split("## Settings", 1)[1].split("```yaml\n", 1)[1].split("```", 1)[0]
    assert "&id" not in settings, settings
    entries = yaml.safe_load(settings)
    assert [entries[variant]["env_kwargs"] for variant in ("n1", "n3")] == [{"sutton_barto_reward": True}] * 2, settings


def test_a_budget_in_steps_shows_each_variants_fewest_and_most_episodes(tmp_path: Path) -> None:
    # The table's Episodes were the figure's (the fewest any seed completed) while each seed's metrics were over all of
    # its own episodes, and seeds that never reached the threshold were said to count as "the episode budget"
    study_file, cache, results = fake_cache(tmp_path, TINY.replace("budget: {episodes: 6}", "budget: {steps: 600}"))
    (run,) = (run for run in load_study(study_file).runs() if (run.variant, run.seed) == ("n1", 1))
    run_dir = run.spec.run_dir(cache)
    (run_dir / "episodes.csv").write_text("return\n" + "10.0\n" * 9)
    command = [str(study_file), "--report-only", "--cache-dir", str(cache), "--results-dir", str(results)]
    studies_cli.main(command)
    summary = pd.read_csv(results / "study.csv").set_index("variant")
    assert summary.loc["n1", ["episodes", "episodes_max"]].tolist() == [6, 9]
    assert summary.loc["n3", ["episodes", "episodes_max"]].tolist() == [6, 6]
    page = " ".join((results / "study.md").read_text().split())
    assert "| `n1` | 2 | 6–9 |" in page
    assert "| `n3` | 2 | 6 |" in page
    assert "The table's Episodes are the fewest and the most a seed of the variant completed" in page
    assert "count as the episodes they completed, a lower bound" in page
    assert "A run stops at the end of the update that reaches the budget" in page
    # 6 episodes: the short-run notes the episode budgets get
    assert "**6 episodes** for the seed with the fewest: the mean over the last 100" in page
    assert "**6 episodes**, fewer than the threshold's window of 3" not in page
    # A budget in episodes: one number, and the budget
    (tmp_path / "episodes").mkdir()
    study_file, cache, results = fake_cache(tmp_path / "episodes")
    studies_cli.main([str(study_file), "--report-only", "--cache-dir", str(cache), "--results-dir", str(results)])
    page = " ".join((results / "study.md").read_text().split())
    assert "| `n1` | 2 | 6 |" in page
    assert "count as the episode budget, a lower bound" in page
    assert "A budget in env steps" not in page


def test_the_console_says_why_too_few_seeds_give_no_verdict(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # (the page's intervals say it; the console said "too close to call" alone)
    study_file, cache, results = fake_cache(tmp_path)
    studies_cli.main([str(study_file), "--report-only", "--cache-dir", str(cache), "--results-dir", str(results)])
    output = capsys.readouterr().out
    assert "too close to call: n = 3 beats n = 1\n  2 seeds per variant: a verdict needs at least 5" in output, output


def test_the_error_rates_are_linked_where_they_lie_beside_the_results(tmp_path: Path) -> None:
    # A results folder of one's own has no error-control.md beside it: the link would be broken
    study_file, cache, results = fake_cache(tmp_path)
    command = [str(study_file), "--report-only", "--cache-dir", str(cache), "--results-dir", str(results)]
    studies_cli.main(command)
    index = (results / "STUDIES.md").read_text()
    assert "](error-control.md)" not in index
    assert "`benchmarks/results/studies/error-control.md` in sb3_classic's repository" in index
    (results / "error-control.md").write_text("# Error control\n")
    studies_cli.main(command)
    assert "[error-control.md](error-control.md)" in (results / "STUDIES.md").read_text()


def test_runs_without_an_episode_are_said_to_be(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # A budget of 5 env steps: a seed with no episode made every mean NaN, with NumPy's "Mean of empty slice" only
    study_file, cache, results = fake_cache(tmp_path, TINY.replace("budget: {episodes: 6}", "budget: {steps: 5}"))
    (load_study(study_file).runs()[0].spec.run_dir(cache) / "episodes.csv").write_text("return\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        command = [str(study_file), "--report-only", "--cache-dir", str(cache), "--results-dir", str(results)]
        assert studies_cli.main(command) == 0
    page = " ".join((results / "study.md").read_text().split())
    assert "**1 run completed no episode** in 5 env steps" in page
    assert "too close to call" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("damage", "expected"),
    [
        # Each was a bare traceback that named no run (a JSONDecodeError, "a seed has only 3 episodes") or a file
        (lambda run_dir: (run_dir / "run.json").write_text(""), "run.json: Expecting value"),
        (
            lambda run_dir: (run_dir / "episodes.csv").write_text("return\n1.0\n2.0\n3.0\n"),
            "episodes.csv has 3 rows, fewer than the 6",
        ),
        (lambda run_dir: (run_dir / "episodes.csv").unlink(), "episodes.csv: [Errno 2]"),
    ],
)
def test_a_damaged_cache_entry_names_its_folder(
    tmp_path: Path, damage: Any, expected: str, capsys: pytest.CaptureFixture[str]
) -> None:
    study_file, cache, results = fake_cache(tmp_path)
    runs = load_study(study_file).runs()
    command = [str(study_file), "--report-only", "--cache-dir", str(cache), "--results-dir", str(results)]
    assert studies_cli.main(command) == 0
    damaged = runs[1].spec.run_dir(cache)
    damage(damaged)
    (results / "STUDIES.md").unlink()
    assert studies_cli.main(command) == 2
    output = " ".join(capsys.readouterr().out.split())
    assert f"The cached run in {damaged} is damaged ({expected}" in output
    assert "delete that folder and run the command again to rerun it" in output
    assert not (results / "STUDIES.md").exists()


def test_the_compute_counts_each_shared_run_once(tmp_path: Path) -> None:
    # Two studies that share a run (the same settings, e.g. a report's baseline in two figures): STUDIES.md's compute
    # is that of the distinct runs; a study's own table still counts all of its runs
    def record(name: str, run_seconds: dict[str, float]) -> None:
        claim = {"text": "a beats b", "reading": STATED, "verdict": stats.SUPPORTED, "measured": "+1"}
        content: dict[str, Any] = {"study": name, "title": name, "source": name, "command": f"x {name}.yml", "claims": [claim]}
        content |= {"claim_texts": ["a beats b"], "runs": len(run_seconds), "run_seconds": run_seconds}
        (tmp_path / f"{name}.json").write_text(json.dumps(content))

    record("one", {"shared": 1800.0, "own-1": 3600.0})
    record("two", {"shared": 1800.0, "own-2": 1800.0})
    index = outputs.write_studies_index([], tmp_path).read_text()
    assert "Compute: 3 distinct runs, 2.0 CPU hours" in index
    assert index.startswith("# Studies\n")
    # A folder of full and reduced results (--results-dir given to both) says so, and counts both: it was titled
    # "(reduced runs)" by a reduced command, and counted only that command's kind; the commands show the budget
    record("one", {"quick": 360.0})
    (tmp_path / "one.json").write_text(json.dumps(json.loads((tmp_path / "one.json").read_text()) | {"reduced": True}))
    study = load_study(write_study(tmp_path, TINY, "one.yml"))
    mixed = outputs.write_studies_index([study], tmp_path, extra=["--seeds", "2"], reduced=True).read_text()
    assert mixed.startswith("# Studies (full and reduced runs: the reduced ones are marked)\n")
    assert "Compute: 3 distinct runs (1 of them of reduced runs), 1.1 CPU hours" in mixed
    assert "one.yml --seeds 2`" in mixed
    # One table in the studies' order, not the last command's study first ("two" re-run alone, "one" on record)
    study_two = load_study(write_study(tmp_path, TINY, "two.yml"))
    ordered = outputs.write_studies_index([study_two], tmp_path).read_text()
    assert ordered.index("x one.yml") < ordered.index("two.yml`")
    (tmp_path / "two.json").unlink()
    reduced = outputs.write_studies_index([study], tmp_path, extra=["--seeds", "2"], reduced=True).read_text()
    assert reduced.startswith("# Studies (reduced runs)\n")
    assert "Compute: 1 distinct run, 0.1 CPU hours" in reduced


def test_many_readings_are_summed_up_with_the_one_that_favours_the_claim_most(tmp_path: Path) -> None:
    # Five readings of one setting, each giving n3 another lead over n1: STUDIES.md groups the other readings by
    # verdict and names the best, the study's page says under which readings the claim holds, and the figure wraps
    # its five panels into rows of four (one row of five panels was 32 inches wide, of 20 readings 128)
    leads = {"as stated": -6.0, "lr_a": 0.0, "lr_b": 3.0, "lr_c": 12.0, "lr_d": 6.0}
    text = (
        TINY.replace("seeds: 2", "seeds: 6")
        + "readings:\n"
        + "".join(f"  {name}: {{learning_rate: {0.002 + index / 1000}}}\n" for index, name in enumerate(list(leads)[1:]))
    )
    study_file = write_study(tmp_path, text)
    cache, results = tmp_path / "cache", tmp_path / "results"
    rng = np.random.default_rng(0)
    for run in load_study(study_file).runs():
        run_dir = run.spec.run_dir(cache)
        run_dir.mkdir(parents=True)
        (run_dir / "run.json").write_text(json.dumps({"learn_time_s": 1.0, "eval_time_s": 0.0}))
        value = 50.0 + leads[run.reading] * (run.variant == "n3") + rng.normal(0.0, 0.5)
        (run_dir / "episodes.csv").write_text("return\n" + "\n".join([f"{value:.3f}"] * 6) + "\n")
    command = [str(study_file), "--report-only", "--cache-dir", str(cache), "--results-dir", str(results)]
    assert studies_cli.main(command) == 0
    (row,) = (line for line in (results / "STUDIES.md").read_text().splitlines() if "n = 3 beats n = 1" in line)
    assert "| reversed |" in row
    # (lr_a's lead of 0 is shown within CartPole-v1's default equivalence margin, 5% of its returns' range)
    assert "Other readings (4): not supported: alike within ±25 under lr_a; supported under lr_b, lr_c, lr_d." in row
    assert "Best reading: lr_c, mean return (all episodes): n3 − n1: +12." in row
    page = (results / "study.md").read_text()
    assert 'Best reading for "n = 3 beats n = 1": `lr_c` (supported;' in page
    assert "Supported under 3 of 5 readings: `lr_b`, `lr_c`, `lr_d`." in page
    height, width = plt.imread(results / "study.png").shape[:2]
    assert (round(width / 110 / 6.4), round(height / 110 / 4.4)) == (4, 2)
    # Up to three other readings, each is named with its verdict
    record = json.loads((results / "study.json").read_text())
    record["claims"] = [claim for claim in record["claims"] if claim["reading"] in ("as stated", "lr_a", "lr_c")]
    (results / "study.json").write_text(json.dumps(record))
    index = outputs.write_studies_index([load_study(study_file)], results).read_text()
    assert "Other readings: lr_a: not supported: alike within ±25; lr_c: supported." in index


def test_favour_is_how_far_a_measurement_goes_the_claims_way() -> None:
    def result(kind: str, estimates: list[float], **fields: object) -> stats.ClaimResult:
        comparisons = tuple(stats.Comparison(None, stats.Interval(value, value - 1, value + 1), "") for value in estimates)
        return stats.ClaimResult(claim(kind, **fields), "", comparisons, "")

    assert stats.favour(result("reaches", [400.0], value=475.0)) == -75.0
    assert stats.favour(result("below", [-120.0], value=-100.0)) == 20.0
    assert stats.favour(result("better", [30.0, 10.0])) == 10.0
    # Fewer episodes to threshold is better: a negative difference favours the claim
    assert stats.favour(result("better", [-30.0], metric="episodes_to_threshold")) == 30.0
    assert stats.favour(result("similar", [4.0, -7.0], margin=10.0)) == -7.0
    assert np.isnan(stats.favour(result("reaches", [float("nan")], value=1.0)))


# ---- the command, end to end ---------------------------------------------------------------------------------------


def test_a_tiny_study_runs_end_to_end(tmp_path: Path) -> None:
    study_file = write_study(tmp_path, TINY, "tiny.yml")
    cache, results = tmp_path / "cache", tmp_path / "results"
    command = [sys.executable, "-m", "benchmarks.studies", str(study_file), "--workers", "1"]
    command += ["--cache-dir", str(cache), "--results-dir", str(results)]
    done = subprocess.run(command, cwd=REPO_ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "4 runs: 0 cached, 4 to run" in done.stdout
    for name in ("tiny.png", "tiny.csv", "tiny.md", "tiny.json", "STUDIES.md"):
        assert (results / name).is_file(), name
    table = pd.read_csv(results / "tiny.csv")
    assert table["variant"].tolist() == ["n1", "n3"]
    assert table["seeds"].tolist() == [2, 2]
    assert table["episodes"].tolist() == [6, 6]
    assert (table["mean_return_low"] <= table["mean_return"]).all()
    record = json.loads((results / "tiny.json").read_text())
    assert record["runs"] == 4
    assert record["complete"]
    (verdict,) = record["claims"]
    assert verdict["verdict"] in (stats.SUPPORTED, stats.REVERSED, stats.TOO_CLOSE)
    index = (results / "STUDIES.md").read_text()
    assert "| n = 3 beats n = 1 |" in index
    assert verdict["verdict"] in index
    assert "Compute: 4 distinct runs" in index
    # Each run's episodes, exactly the budget
    for run_file in cache.rglob("episodes.csv"):
        assert len(pd.read_csv(run_file)) == 6
    # Again: everything cached, nothing run
    listed = subprocess.run([*command, "--list"], cwd=REPO_ROOT, capture_output=True, text=True, timeout=120)
    assert "4 runs, 4 cached" in listed.stdout, listed.stdout + listed.stderr
    # The command the outputs show re-runs the study from scratch, also when they were redrawn from the cache: the
    # file, without the options that change where and how it runs but not its results
    redrawn = subprocess.run([*command, "--report-only"], cwd=REPO_ROOT, capture_output=True, text=True, timeout=120)
    assert redrawn.returncode == 0, redrawn.stdout + redrawn.stderr
    expected = shlex.join(["python", "-m", "benchmarks.studies", str(study_file)])
    assert json.loads((results / "tiny.json").read_text())["command"] == expected
    assert f"`{expected}`" in (results / "STUDIES.md").read_text()


#: The metrics of a study without a threshold
METRICS_ON_RETURNS = ("mean_return", "last_100_return")

#: A study of an env of one's own (``tests/chain_env.py`` registers it when imported), with its env_kwargs; no
#: threshold (the env registers no reward_threshold, and no claim reads one)
CHAIN = """
title: Chain
env: chain_env:ShortChain-v0
algo: nstep_sarsa
seeds: 2
budget: {episodes: 4}
hyperparams:
  policy: MlpPolicy
  env_kwargs: {length: 3}
  learning_rate: lin_1e-3
  train_freq: 1
  gradient_steps: 1
  policy_kwargs: {net_arch: [8]}
vary: {n_steps: [1, 2]}
claim: {text: "n = 2 beats n = 1", kind: better, variant: n_steps=2, others: [n_steps=1]}
"""


def test_a_study_of_ones_own_env_runs_end_to_end(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # env: module:EnvId (Gymnasium's form) was refused as "not a registered Gymnasium env". The loader imports the
    # module, and so does each process that builds the env: the pool's workers are fresh interpreters (spawn). The
    # env_kwargs reach the training envs and the evaluation envs (the zoo gives a YAML's to the training envs only: a
    # chain of 3 states evaluated on one of 4 failed on the observation's shape)
    study_file = write_study(tmp_path, CHAIN, "chain.yml")
    cache, results = tmp_path / "cache", tmp_path / "results"
    command = [str(study_file), "--cache-dir", str(cache), "--results-dir", str(results)]
    assert studies_cli.main([*command, "--workers", "1"]) == 0, capsys.readouterr().out
    record = json.loads((results / "chain.json").read_text())
    assert (record["env_id"], record["runs"], record["complete"]) == ("chain_env:ShortChain-v0", 4, True)
    (verdict,) = record["claims"]
    assert verdict["verdict"] in (stats.SUPPORTED, stats.REVERSED, stats.TOO_CLOSE)
    for run in load_study(study_file).runs():
        run_dir = run.spec.run_dir(cache)
        # (no ':' in a folder's name)
        assert run_dir.relative_to(cache).parts[:2] == ("ShortChain-v0", "nstep_sarsa")
        assert len(pd.read_csv(run_dir / "episodes.csv")) == 4
        # A deterministic policy on a chain of 3 states: it reaches the end in 2 steps, or never in its 20
        assert set(pd.read_csv(run_dir / "evaluations.csv")["return"]) <= {-2.0, -20.0}
    page = (results / "chain.md").read_text()
    assert "A uniformly random policy's return on the env" in page
    # Without a threshold, no episodes to threshold: not measured, nor shown as if it were
    assert "- No threshold: no claim reads one, and episodes to threshold is not measured" in page
    (header,) = (line for line in page.splitlines() if line.startswith("| Variant |"))
    assert header == "| Variant | Seeds | Episodes | " + " | ".join(stats.METRIC_LABELS[m] for m in METRICS_ON_RETURNS) + " |"
    assert "Threshold:" not in page
    for table in ("chain.csv", "chain-seeds.csv"):
        columns = set(pd.read_csv(results / table).columns)
        assert "mean_return" in columns
        assert not {"episodes_to_threshold", "reached", "seeds_reaching"} & columns, table
    capsys.readouterr()
    assert studies_cli.main([*command, "--list"]) == 0
    assert "4 runs, 4 cached" in capsys.readouterr().out


def test_the_summary_and_the_page_say_how_each_variants_seeds_train(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # Only each run's run.json said "training": "alone" (a population covers Box observations, not FrozenLake-v1's
    # Discrete ones), and nothing said when seeds did train together. No run is needed to say it: the plan says it
    frozen = TINY.replace("env: CartPole-v1", "env: FrozenLake-v1").replace("title: Tiny", "title: Frozen")
    files = [write_study(tmp_path, TINY, "cart.yml"), write_study(tmp_path, frozen, "frozen.yml")]
    files.append(write_study(tmp_path, TINY.replace("seeds: 2", "seeds: [3]"), "one.yml"))
    mixed = TINY.replace("n1: {n_steps: 1}", "n1: {n_steps: 1, policy: LinearPolicy, policy_kwargs: {net_arch: []}}")
    files.append(write_study(tmp_path, mixed, "mixed.yml"))
    options = ["--report-only", "--cache-dir", str(tmp_path / "cache"), "--results-dir", str(tmp_path / "results")]
    studies_cli.main([*map(str, files), *options])
    printed = capsys.readouterr().out
    together = "each variant's 2 seeds trained together, as one population (lockstep)"
    discrete = (
        "each variant's seeds trained one by one: observation_space=Discrete(16): a population's stacked networks take "
        "flat Box observations; train this setting one model after the other (model.learn), or wrap the env to give "
        "Box observations"
    )
    one_seed = f"each variant's seeds trained one by one: {lockstep.ONE_SEED}"
    linear = "`n1`: seeds trained one by one: policy='LinearPolicy' has its own SGD update"
    expected = {"cart": together, "frozen": discrete, "one": one_seed, "mixed": linear}
    for name, how in expected.items():
        assert f"{name}: {how}" in printed, printed  # the summary
        assert f"- Training: {how}" in (tmp_path / "results" / f"{name}.md").read_text()  # the page
    assert "; `n3`: 2 seeds trained together, as one population (lockstep)" in (tmp_path / "results" / "mixed.md").read_text()
    studies_cli.main([str(files[0]), *options, "--separate"])
    assert f"cart: each variant's seeds trained one by one: {lockstep.SEPARATE}" in capsys.readouterr().out


def test_a_verdict_between_variants_that_did_not_learn_says_so(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # Two variants at a random policy's return (CartPole-v1: about 25) were judged "supported" without a word. Each
    # variant's 6 seeds: n1 at 20, n3 at 26 (n3 beats n1, but neither rose above chance), then n3 at 60
    def page(n3: float) -> str:
        text = TINY.replace("seeds: 2", "seeds: 6")
        folder = tmp_path / str(n3)
        folder.mkdir()
        study_file, cache, results = fake_cache(folder, text)
        for run in load_study(study_file).runs():
            value = (n3 if run.variant == "n3" else 20.0) + run.seed / 10
            (run.spec.run_dir(cache) / "episodes.csv").write_text("return\n" + f"{value}\n" * 6)
        command = [str(study_file), "--report-only", "--cache-dir", str(cache), "--results-dir", str(results)]
        assert studies_cli.main(command) == 0
        (row,) = (line for line in (results / "STUDIES.md").read_text().splitlines() if "n = 3 beats n = 1" in line)
        (claim,) = json.loads((results / "study.json").read_text())["claims"]
        assert claim["verdict"] == stats.SUPPORTED
        return "\n".join([(results / "study.md").read_text(), row, claim.get("untrained", ""), capsys.readouterr().out])

    returns = untrained.random_returns("CartPole-v1")
    assert returns is not None
    level = stats.interval(returns)
    # The premise: n1 below it, n3 within it
    assert level.low > 20.3, level
    assert 26.3 < level.high < 60, level
    said = " ".join(page(26.0).split())
    note = (
        "none of the 2 compared variants has a mean return over its last 100 episodes (all, in a shorter run) above a "
        f"uniformly random policy's ({level.format()}): the verdict compares runs that did not measurably learn"
    )
    assert "- **supported**: n = 3 beats n = 1. Measured: " in said
    assert f"**Not learned**: {note}." in said  # the study's page
    assert "| supported (not learned: no compared variant above a random policy's return) |" in said  # STUDIES.md
    assert said.count(note) == 3  # and the json's record, and the command's output
    assert f"A uniformly random policy's return on the env: {level.format()}" in said
    # One variant above it: no note
    learned = " ".join(page(60.0).split())
    assert "**Not learned**:" not in learned
    assert "not learned:" not in learned  # (STUDIES.md's row, the command's output)
    assert "| supported |" in learned


def test_the_threshold_defaults_to_gymnasiums(tmp_path: Path) -> None:
    """An env the harness has no threshold for takes its spec's ``reward_threshold``; one without any must say it."""
    mountain_car = load_study(write_study(tmp_path, TINY.replace("env: CartPole-v1", "env: MountainCar-v0")))
    assert mountain_car.threshold == -110.0  # MountainCar-v0's reward_threshold
    on_episodes = TINY.replace("env: CartPole-v1", "env: Pendulum-v1").replace("others: [n1]", "others: [n1], " + TO_THRESHOLD)
    needs = "threshold: missing: give the return that counts as solved on Pendulum-v1, a finite number (claim.metric"
    with pytest.raises(StudyError, match=re.escape(needs)):
        load_study(write_study(tmp_path, on_episodes, "pendulum.yml"))


#: A claim that reads the study's threshold
TO_THRESHOLD = "metric: episodes_to_threshold"


def test_a_threshold_is_needed_only_by_the_claims_that_read_it(tmp_path: Path) -> None:
    # A study of one's own env (no reward_threshold) that claims on returns was refused for lacking one
    chain = CHAIN
    assert math.isnan(load_study(write_study(tmp_path, chain, "returns.yml")).threshold)
    # A claim on episodes to threshold, or a level claim without its value, needs it: the message says what reads it
    # and, the env having no reward_threshold, a random policy's returns on it (CartPole-v1's 475 was suggested)
    cases = {
        "episodes.yml": (
            chain.replace("others: [n_steps=1]", f"others: [n_steps=1], {TO_THRESHOLD}"),
            "claim.metric episodes_to_threshold",
        ),
        "level.yml": (
            chain.replace("kind: better, variant: n_steps=2, others: [n_steps=1]", "kind: reaches, variant: n_steps=2"),
            "claim, a 'reaches' claim without value,",
        ),
    }
    for name, (text, reader) in cases.items():
        with pytest.raises(StudyError) as raised:
            load_study(write_study(tmp_path, text, name))
        message = str(raised.value)
        assert "threshold: missing: give the return that counts as solved on chain_env:ShortChain-v0" in message
        assert f"({reader} needs it); the env registers no reward_threshold" in message
        assert re.search(
            r"above a uniformly random policy's mean return on it, -[\d.]+ \(100 episodes, from -20 to -\d+\)", message
        )
        assert "475" not in message
        assert "None" not in message
        assert message.count("\n  ") == 1, message  # one problem (the level claim's value says nothing of its own)
