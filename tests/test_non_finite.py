"""
NaN and infinity from an env: refused before they reach an update, naming the env, the field and the step, with the
model left as its last update made it; a termination's final observation (nothing bootstraps from it) and integer
observations are not checked.
"""

import copy
import math
from pathlib import Path
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv
from test_contract import MODEL_LIST, make_model, parameters_equal

from sb3_classic.common.buffers import all_finite


class Corrupt(gym.Wrapper[np.ndarray, Any, np.ndarray, Any]):
    """
    Returns NaN or infinity in one field at one step of its life (counted over episodes).

    :param env: the env to wrap
    :param field: ``"observation"``, ``"reward"``, ``"final observation"`` (the step also truncates the episode, so
        that its target bootstraps from it), ``"terminal observation"`` (the step terminates it: nothing bootstraps from
        it) or ``"reset"`` (the first observation)
    :param at_step: the step (1-based, over the env's life) that returns the bad value
    :param value: NaN or ±inf
    """

    def __init__(self, env: gym.Env, field: str, at_step: int, value: float = math.nan) -> None:
        super().__init__(env)
        self.field, self.at_step, self.value = field, at_step, value
        self.steps = 0

    def reset(self, **kwargs: Any) -> tuple[np.ndarray, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        if self.field == "reset":
            obs = np.full_like(obs, self.value)
        return obs, info

    def step(self, action: Any) -> tuple[np.ndarray, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.steps += 1
        if self.steps == self.at_step:
            if self.field == "reward":
                reward = self.value
            elif self.field in ("observation", "final observation", "terminal observation"):
                obs = obs.copy()
                obs[1] = self.value
                truncated = truncated or self.field == "final observation"
                terminated = terminated or self.field == "terminal observation"
        return obs, reward, terminated, truncated, info


def corrupted_env(field: str, at_step: int, value: float = math.nan, bad_env: int = 1) -> DummyVecEnv:
    """Two CartPole-v1 envs, the second of which returns a bad value."""

    def make(idx: int) -> Any:
        return lambda: Corrupt(gym.make("CartPole-v1"), field if idx == bad_env else "", at_step, value)

    env = DummyVecEnv([make(0), make(1)])
    env.seed(0)
    return env


class SnapshotAfterEachUpdate(BaseCallback):
    """Keeps the model's parameters as every rollout starts (after the previous update)."""

    snapshot: dict[str, Any]

    def _on_rollout_start(self) -> None:
        self.snapshot = copy.deepcopy(self.model.get_parameters())

    def _on_step(self) -> bool:
        return True


def cloned_parameters(model: BaseAlgorithm) -> dict[str, Any]:
    """:return: a copy of the model's networks and optimizer states"""
    return copy.deepcopy(model.get_parameters())


@pytest.mark.parametrize("model_class", MODEL_LIST)
@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("observation", math.nan, r"Env 1 returned a non-finite observation \(nan\) at step 5 of its episode"),
        ("reward", math.inf, r"Env 1 returned a non-finite reward \(inf\) at step 5 of its episode"),
        ("final observation", -math.inf, r"Env 1 returned a non-finite final observation .*\(-inf\) at step 5 of its episode"),
    ],
)
def test_a_bad_value_stops_training_before_any_update(
    tmp_path: Path, model_class: type[BaseAlgorithm], field: str, value: float, message: str
) -> None:
    model = make_model(model_class, corrupted_env(field, at_step=5, value=value), seed=0)
    before = cloned_parameters(model)
    with pytest.raises(ValueError, match=message) as error:
        model.learn(2000)
    # VecCheckNan finds what step() returns, not a final observation in the infos (which it was told to use)
    assert ("VecCheckNan" in str(error.value)) == (field != "final observation")
    assert parameters_equal(model.get_parameters(), before)
    # The model can be saved, and trains on once the env is fixed
    model.save(tmp_path / "model")
    loaded = model_class.load(tmp_path / "model", env=make_vec_env("CartPole-v1", n_envs=2, seed=0), device="cpu")
    assert parameters_equal(loaded.get_parameters(), before)
    loaded.learn(200)


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_a_terminations_final_observation_is_not_bootstrapped_so_not_refused(model_class: type[BaseAlgorithm]) -> None:
    # A simulator that diverges into NaN as it terminates: no target uses that state, and A2C and DQN train on
    model = make_model(model_class, corrupted_env("terminal observation", at_step=5), seed=0)
    model.learn(300)
    assert model._n_updates > 0


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_a_bad_value_later_leaves_the_last_update_intact(model_class: type[BaseAlgorithm]) -> None:
    model = make_model(model_class, corrupted_env("observation", at_step=700), seed=0)
    callback = SnapshotAfterEachUpdate()
    with pytest.raises(ValueError, match="Env 1 returned a non-finite observation"):
        model.learn(5000, callback=callback)
    assert model._n_updates > 0, "the error came before any update: this test is about a later one"
    assert parameters_equal(model.get_parameters(), callback.snapshot)
    for module in model.get_parameters()["policy"].values():
        assert th.isfinite(module).all()


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_a_bad_first_observation_is_refused_at_the_start(model_class: type[BaseAlgorithm]) -> None:
    model = make_model(model_class, corrupted_env("reset", at_step=0), seed=0)
    before = cloned_parameters(model)
    with pytest.raises(ValueError, match=r"Env 1 returned a non-finite observation \(nan\) at the first observation"):
        model.learn(100)
    assert parameters_equal(model.get_parameters(), before)


def test_integer_observations_are_not_checked() -> None:
    """Images (uint8) cannot hold NaN: the check skips them instead of scanning every pixel."""
    assert all_finite(np.zeros((2, 84, 84, 1), dtype=np.uint8))
    assert all_finite({"image": np.zeros((2, 4), dtype=np.uint8), "vector": np.zeros((2, 3), dtype=np.float32)})
    assert not all_finite({"image": np.zeros((2, 4), dtype=np.uint8), "vector": np.array([[0.0, np.nan]])})
