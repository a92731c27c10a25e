"""Over 10 seeds (REINFORCE: 20), lockstep training learns as well as training each seed alone: their final returns are
not distinguishable."""

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
import torch as th
from scipy.stats import bootstrap
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy

from sb3_classic import REINFORCE, NStepSARSA


def sarsa(seed: int) -> NStepSARSA:
    """The seed report's per-step SARSA setting on CartPole-v1 (Fig 15's n = 10), a smaller q̂"""
    return NStepSARSA(
        "MlpPolicy",
        make_vec_env("CartPole-v1", n_envs=1, seed=seed),
        n_steps=10,
        learning_rate=5e-4,
        train_freq=1,
        gradient_steps=1,
        update_mode="per_step",
        exploration_schedule="exponential",
        exploration_decay_rate=0.99,
        exploration_final_eps=0.0,
        policy_kwargs=dict(net_arch=[64, 64]),
        seed=seed,
    )


def reinforce(seed: int) -> REINFORCE:
    """REINFORCE with baseline, one Adam step per episode, on CartPole-v1"""
    return REINFORCE(
        "MlpPolicy",
        make_vec_env("CartPole-v1", n_envs=1, seed=seed),
        learning_rate=3e-3,
        value_learning_rate=1e-2,
        policy_kwargs=dict(net_arch=[64, 64]),
        seed=seed,
    )


def final_returns(models: list[BaseAlgorithm]) -> np.ndarray:
    """:return: each model's mean return over 10 deterministic episodes on an env of its own seed + 100"""
    returns = []
    for model in models:
        seed = model.seed
        assert seed is not None
        env = make_vec_env("CartPole-v1", n_envs=1, seed=seed + 100)
        mean, _ = evaluate_policy(model, env, n_eval_episodes=10, deterministic=True)
        returns.append(mean)
    return np.array(returns)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("make", "population_name", "steps", "n_seeds"),
    [
        (sarsa, "NStepSARSAPopulation", 15_000, 10),
        # (REINFORCE's final evaluations after 30,000 steps are near 500 or far below it, seed by seed: 20 seeds, so
        # that the interval of the difference of means is not decided by two or three seeds' luck in their draws)
        (reinforce, "REINFORCEPopulation", 30_000, 20),
    ],
)
def test_lockstep_and_separate_runs_are_not_distinguishable(
    make: Callable[[int], Any], population_name: str, steps: int, n_seeds: int
) -> None:
    import sb3_classic.reinforce
    import sb3_classic.sarsa

    population = getattr(sb3_classic.sarsa, population_name, None) or getattr(sb3_classic.reinforce, population_name)
    th.set_num_threads(1)
    seeds = range(n_seeds)
    separate = final_returns([make(seed).learn(steps) for seed in seeds])
    members = population([make(seed) for seed in seeds]).learn(steps)
    lockstep = final_returns(members)
    # Both learned (a random CartPole policy returns about 20): the comparison is between trained models
    assert separate.mean() > 100
    assert lockstep.mean() > 100
    # The difference of the means over seeds, with SciPy's BCa bootstrap interval (as the studies' verdicts): 0 in it
    interval = bootstrap(
        (lockstep, separate),
        lambda a, b, axis=-1: np.mean(a, axis=axis) - np.mean(b, axis=axis),
        n_resamples=10_000,
        random_state=0,
    ).confidence_interval
    assert interval.low <= 0 <= interval.high, (lockstep.tolist(), separate.tolist(), interval)
