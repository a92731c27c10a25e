"""
What the algorithms log: TensorBoard curves of a short run, how often SARSA dumps, that each dump reports its own
update, SARSA's means of an update's predictions, targets and losses, ``log_interval``'s checks, and the last dump when
``learn()`` returns.
"""

import glob
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch as th
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.logger import configure
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
from test_contract import MODEL_LIST, make_model

from sb3_classic import REINFORCE, NStepSARSA


def scalars(log_dir: Path) -> dict[str, int]:
    """:return: the number of points of every scalar of the one run in ``log_dir``"""
    (run_dir,) = glob.glob(str(log_dir / "*"))
    accumulator = EventAccumulator(run_dir).Reload()
    return {tag: len(accumulator.Scalars(tag)) for tag in accumulator.Tags()["scalars"]}


@pytest.mark.parametrize(
    ("model_class", "own"),
    [(NStepSARSA, {"train/loss", "train/q_mean", "rollout/exploration_rate"}), (REINFORCE, {"train/policy_loss"})],
)
def test_a_short_run_shows_a_curve(tmp_path: Path, model_class: type[BaseAlgorithm], own: set[str]) -> None:
    """``learn(1500)`` on CartPole-v1 with one env and the defaults: the curves have points."""
    model_class("MlpPolicy", "CartPole-v1", tensorboard_log=str(tmp_path), seed=0, device="cpu").learn(1500)  # type: ignore[call-arg]
    points = scalars(tmp_path)
    assert {"rollout/ep_rew_mean", "train/learning_rate", *own} <= points.keys(), sorted(points)
    assert points["rollout/ep_rew_mean"] >= 5, points


@pytest.mark.parametrize(("train_freq", "points"), [(16, 1024 // 128), (1, 1024 // 128), (5, 1024 // 130)])
def test_sarsa_logs_every_128_env_steps_per_env_by_default(tmp_path: Path, train_freq: int, points: int) -> None:
    """
    The per-step mode (``train_freq=1``, an update per env step) wrote a TensorBoard point, and with ``verbose=1`` a
    table, every 8 env steps when the default counted 8 updates: 251 tables for 2,000 steps of the zoo's
    MountainCar-v0 entry. ``"auto"`` dumps every 128 env steps per env (whole updates: 130 with ``train_freq=5``).
    """
    model = make_model(NStepSARSA, seed=0, tensorboard_log=str(tmp_path), train_freq=train_freq, n_steps=1)
    model.learn(1024 - 1024 % train_freq)
    # The dumps during learn() and the one when it returns (none there if the last update was just dumped)
    assert scalars(tmp_path)["train/loss"] in (points, points + 1)


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_a_dump_reports_its_own_update_and_no_step_twice(model_class: type[BaseAlgorithm]) -> None:
    """
    Dumping before the update (SB3's on-policy order) logged the previous update's train/ values, and when the run
    ended on a dump, the final dump wrote the same step again.
    """
    model = make_model(model_class, seed=0)
    model.set_logger(configure(None, []))
    updates: list[tuple[int, int]] = []  # (env steps, n_updates) after each update
    dumps: list[tuple[int, int]] = []  # the same, as each dump wrote them
    train, dump = model.train, model.logger.dump

    def counted_train() -> None:
        train()
        updates.append((model.num_timesteps, model._n_updates))

    def recorded_dump(step: int = 0) -> None:
        dumps.append((step, model.logger.name_to_value["train/n_updates"]))
        dump(step)

    model.train = counted_train
    model.logger.dump = recorded_dump
    model.learn(1024, log_interval=2)
    assert len(updates) % 2 == 0, "the run must end on a dump for the second check"
    assert dumps == updates[1::2]


@pytest.mark.parametrize(("update_mode", "n_envs"), [("batch", 2), ("per_step", 1), ("per_step", 2)])
def test_sarsa_logs_the_means_of_its_updates_predictions_and_targets(update_mode: str, n_envs: int) -> None:
    """``train/q_mean`` and ``train/target_mean``: the means over an update's transitions, before its first step."""
    model = make_model(
        NStepSARSA, make_vec_env("CartPole-v1", n_envs=n_envs), seed=0, n_steps=2, train_freq=4, update_mode=update_mode
    )
    model.learn(64)  # past the first updates, whose batches can be shorter
    steps: list[tuple[np.ndarray, np.ndarray]] = []
    losses: list[float] = []
    gradient_step = model._gradient_step

    def recorded(
        observations: np.ndarray, actions: np.ndarray, targets: np.ndarray, episode_steps: np.ndarray
    ) -> tuple[np.ndarray, float]:
        q_predicted, loss = gradient_step(observations, actions, targets, episode_steps)
        steps.append((q_predicted, targets.copy()))
        losses.append(float(loss))
        return q_predicted, loss

    model._gradient_step = recorded
    model.learn(4 * n_envs, reset_num_timesteps=False, log_interval=None)  # no dumps: the values stay in the logger
    dumped = model.logger.name_to_value
    # The update's first pass (per step: one gradient step per transition, then the next passes)
    first_pass = steps[: len(steps) // model.gradient_steps]
    q_first = th.as_tensor(np.concatenate([q for q, _ in first_pass]))
    targets = th.as_tensor(np.concatenate([target for _, target in first_pass]))
    # (An episode end in the update's steps changes how many targets complete: 4 × n_envs without one)
    assert dumped["train/n_transitions"] == len(targets) >= 2
    assert dumped["train/q_mean"] == pytest.approx(float(q_first.double().mean()), rel=1e-6)
    assert dumped["train/target_mean"] == pytest.approx(float(targets.double().mean()), rel=1e-6)
    # The mean of every gradient step's loss, as SB3's DQN logs it (it was the last step's)
    assert len(losses) == model.gradient_steps * (len(targets) if update_mode == "per_step" else 1)
    assert dumped["train/loss"] == pytest.approx(math.fsum(losses) / len(losses), rel=1e-5)


@pytest.mark.parametrize("model_class", MODEL_LIST)
@pytest.mark.parametrize("log_interval", [0, -1, 2.5, "every"])
def test_a_log_interval_that_is_not_a_count_is_refused_before_training(
    model_class: type[BaseAlgorithm], log_interval: Any
) -> None:
    """SB3's loop would divide by it after the first rollout (REINFORCE: ZeroDivisionError), with the work done lost."""
    model = make_model(model_class, seed=0)
    expected = r'log_interval=.*"auto"' if model_class is NStepSARSA else r"log_interval=.* or None \(no dumps\)"
    with pytest.raises(ValueError, match=expected):
        model.learn(100, log_interval=log_interval)
    assert model.num_timesteps == 0


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_what_was_recorded_is_dumped_when_learn_returns(tmp_path: Path, model_class: type[BaseAlgorithm]) -> None:
    """Fewer updates than ``log_interval``: the last update's values are in the logs anyway."""
    model = make_model(model_class, seed=0, tensorboard_log=str(tmp_path))
    model.learn(300, log_interval=10_000)
    points = scalars(tmp_path)
    assert points.get("train/learning_rate") == 1, points
    assert "rollout/ep_rew_mean" in points
