"""VecEnvs of the user's: dones of another dtype than bool, and truncations without their final observation."""

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv
from test_contract import MODEL_LIST, make_model, parameters_equal


class IntegerDones(DummyVecEnv):
    """A VecEnv of the user's that returns its dones as 0/1 integers (or floats)."""

    dtype: type = np.int64

    def step_wait(self) -> Any:
        obs, rewards, dones, infos = super().step_wait()
        return obs, rewards, dones.astype(self.dtype), infos


@pytest.mark.parametrize("model_class", MODEL_LIST)
@pytest.mark.parametrize("dtype", [np.int64, np.float32])
def test_dones_of_another_dtype_are_read_as_booleans(model_class: type[BaseAlgorithm], dtype: type) -> None:
    # Integer dones indexed the envs ([1, 0] reset the episode lengths of envs 1 and 0): wrong γ^t and episode counts,
    # and max_episode_length never cut; float ones crashed in NumPy. A2C and DQN train on them
    def trained(vec_env: DummyVecEnv) -> Any:
        return make_model(model_class, vec_env, seed=0).learn(400)

    reference = trained(DummyVecEnv([lambda: Monitor(gym.make("CartPole-v1"))] * 2))
    IntegerDones.dtype = dtype
    other = trained(IntegerDones([lambda: Monitor(gym.make("CartPole-v1"))] * 2))
    assert other._completed_episodes == reference._completed_episodes
    assert parameters_equal(other.get_parameters(), reference.get_parameters())


class NoFinalObservation(DummyVecEnv):
    """A VecEnv of the user's that reports truncations without ``terminal_observation``."""

    def step_wait(self) -> Any:
        obs, rewards, dones, infos = super().step_wait()
        for info in infos:
            info.pop("terminal_observation", None)
        return obs, rewards, dones, infos


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_a_truncation_without_its_final_observation_warns(model_class: type[BaseAlgorithm]) -> None:
    env = NoFinalObservation([lambda: gym.wrappers.TimeLimit(gym.make("CartPole-v1").unwrapped, 5)])
    model = make_model(model_class, env, seed=0)
    with pytest.warns(UserWarning, match=r"truncation .* without its final observation .* trains it as a termination"):
        model.learn(100)
