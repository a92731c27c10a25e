"""
Learning checks with the package's own hyperparameters (hyperparams/*.yml, as rl-zoo3 reads them).

The default run has one quick check per algorithm (a clearly learned CartPole); the ``slow`` ones hold the
algorithms to the target: a mean evaluation return of 475 on CartPole-v1 and −100 on Acrobot-v1 within
1000 episodes. Run them with ``python -m pytest -m slow``.
"""

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch as th
import yaml
from rl_zoo3.exp_manager import ExperimentManager
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy
from torch import nn

from sb3_classic import REINFORCE, NStepSARSA

HYPERPARAMS = Path(__file__).parents[1] / "hyperparams"
ALGOS = {"reinforce": REINFORCE, "nstep_sarsa": NStepSARSA}
THRESHOLDS = {"CartPole-v1": 475.0, "Acrobot-v1": -100.0}


def zoo_hyperparams(algo: str, env_id: str) -> tuple[dict[str, Any], int]:
    """
    The YAML entry as the zoo reads it: ``lin_`` learning rates as linear schedules, ``policy_kwargs`` evaluated
    with ``nn`` and ``th`` in scope.

    :return: the constructor arguments (``n_timesteps`` included) and ``n_envs``
    """
    hyperparams = dict(yaml.safe_load((HYPERPARAMS / f"{algo}.yml").read_text())[env_id])
    assert "normalize" not in hyperparams, "VecNormalize is not applied here"
    hyperparams.pop("policy")
    # The zoo's own parsing of learning rates (with sb3_classic.zoo's value_learning_rate)
    hyperparams = ExperimentManager._preprocess_schedules(hyperparams)
    if isinstance(hyperparams.get("policy_kwargs"), str):
        hyperparams["policy_kwargs"] = eval(hyperparams["policy_kwargs"], {"nn": nn, "th": th})
    return hyperparams, hyperparams.pop("n_envs", 1)


class EvaluateEvery(BaseCallback):
    """Deterministic evaluation every ``eval_every`` completed episodes; stops once ``threshold`` is reached."""

    def __init__(self, env_id: str, eval_every: int, threshold: float) -> None:
        super().__init__()
        self.eval_env = make_vec_env(env_id, n_envs=1, seed=1234)
        self.eval_every, self.threshold = eval_every, threshold
        self.next_eval = eval_every
        self.results: list[tuple[int, float]] = []

    def _on_step(self) -> bool:
        episodes = self.model._completed_episodes  # type: ignore[attr-defined]
        if episodes < self.next_eval:
            return True
        self.next_eval += self.eval_every
        returns, _ = evaluate_policy(self.model, self.eval_env, n_eval_episodes=10, return_episode_rewards=True)
        mean_return = float(np.mean(returns))
        self.results.append((episodes, mean_return))
        return mean_return < self.threshold


def train(algo: str, env_id: str, seed: int, max_episodes: int, eval_every: int = 25) -> EvaluateEvery:
    hyperparams, n_envs = zoo_hyperparams(algo, env_id)
    n_timesteps = int(hyperparams.pop("n_timesteps"))
    model = ALGOS[algo]("MlpPolicy", make_vec_env(env_id, n_envs=n_envs, seed=seed), seed=seed, device="cpu", **hyperparams)
    evaluation = EvaluateEvery(env_id, eval_every, THRESHOLDS[env_id])
    # The YAML's budget, as `python -m rl_zoo3.train` would train (linear schedules span it), or fewer episodes
    model.learn(n_timesteps, callback=[evaluation, StopAfterEpisodes(max_episodes)])
    return evaluation


class StopAfterEpisodes(BaseCallback):
    def __init__(self, max_episodes: int) -> None:
        super().__init__()
        self.max_episodes = max_episodes

    def _on_step(self) -> bool:
        return self.model._completed_episodes < self.max_episodes  # type: ignore[attr-defined]


@pytest.mark.parametrize("algo", ALGOS)
def test_cartpole_is_clearly_learned(algo: str) -> None:
    evaluation = train(algo, "CartPole-v1", seed=0, max_episodes=400)
    best = max(result for _, result in evaluation.results)
    # A random policy scores about 20
    assert best >= 300, evaluation.results


@pytest.mark.slow
@pytest.mark.parametrize("algo", ALGOS)
@pytest.mark.parametrize("env_id", THRESHOLDS)
def test_reaches_the_threshold_within_1000_episodes_on_most_seeds(algo: str, env_id: str) -> None:
    reached = [
        any(result >= THRESHOLDS[env_id] for _, result in train(algo, env_id, seed, max_episodes=1000).results)
        for seed in range(3)
    ]
    assert np.sum(reached) >= 2, reached
