"""
Callbacks, as SB3's A2C, PPO and DQN run them: what a callback changes in ``self.locals`` in ``_on_step`` is what is
stored and trained on, and the policy can be copied wherever a callback runs.
"""

import copy
import pickle
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3 import A2C
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
from test_contract import MODEL_LIST, make_model, observations, parameters_equal

from sb3_classic import REINFORCE

CASES = [
    pytest.param(model_class, update_mode, n_envs, id=f"{model_class.__name__}-{update_mode}-{n_envs}envs")
    for model_class in MODEL_LIST
    for update_mode in ("batch", "per_step")
    for n_envs in (1, 3)
]
SHAPED = 0.25


class SetRewards(BaseCallback):
    """
    Sets every reward of each step to ``value`` in place, the usual way to shape or rescale rewards without a wrapper.

    :param value: the reward to store
    :param stop_at: return False at this call (after setting the rewards), if given
    """

    def __init__(self, value: float = SHAPED, stop_at: int | None = None) -> None:
        super().__init__()
        self.value = value
        self.stop_at = stop_at

    def _on_step(self) -> bool:
        self.locals["rewards"][:] = self.value
        return self.n_calls != self.stop_at


def vec_env(n_envs: int, **kwargs: Any) -> Any:
    return make_vec_env("CartPole-v1", n_envs=n_envs, seed=0, **kwargs)


def test_a2c_stores_the_rewards_a_callback_sets() -> None:
    """The behaviour this file holds the package to."""
    model = A2C("MlpPolicy", vec_env(3), n_steps=8, seed=0, device="cpu").learn(200, callback=SetRewards())
    np.testing.assert_array_equal(model.rollout_buffer.rewards, SHAPED)


@pytest.mark.parametrize(("model_class", "update_mode", "n_envs"), CASES)
def test_rewards_set_by_a_callback_are_trained_on(model_class: type[BaseAlgorithm], update_mode: str, n_envs: int) -> None:
    # Trained on as if the env itself returned them (a reward wrapper), to the bit
    by_callback = make_model(model_class, vec_env(n_envs), update_mode=update_mode, seed=0)
    by_callback.learn(300, callback=SetRewards())
    by_wrapper = make_model(
        model_class,
        vec_env(n_envs, wrapper_class=gym.wrappers.TransformReward, wrapper_kwargs=dict(func=lambda reward: SHAPED)),
        update_mode=update_mode,
        seed=0,
    )
    by_wrapper.learn(300)
    assert by_callback.num_timesteps == by_wrapper.num_timesteps
    assert parameters_equal(by_callback.get_parameters(), by_wrapper.get_parameters())
    unshaped = make_model(model_class, vec_env(n_envs), update_mode=update_mode, seed=0).learn(300)
    assert not parameters_equal(by_callback.get_parameters(), unshaped.get_parameters())


@pytest.mark.parametrize(("model_class", "update_mode", "n_envs"), CASES)
def test_a_callback_that_stops_training_at_the_step_it_shapes(
    model_class: type[BaseAlgorithm], update_mode: str, n_envs: int
) -> None:
    env = vec_env(n_envs)
    model = make_model(model_class, env, update_mode=update_mode, seed=0)
    model.learn(10_000, callback=SetRewards(stop_at=37))
    assert model.num_timesteps == 37 * n_envs
    buffer = model.rollout_buffer
    # The step it stopped at is stored, shaped, and so is every step not trained on yet
    for env_idx in range(n_envs):
        np.testing.assert_array_equal(buffer.rewards[buffer.start[env_idx] : buffer.pos, env_idx], SHAPED)
    assert buffer.pos > 0
    # The buffer and the envs are in step: each env's running episode has the length the buffer holds of it
    np.testing.assert_array_equal(buffer.episode_length, [len(monitor.rewards) for monitor in env.envs])
    np.testing.assert_array_equal(
        model._last_obs, np.array([monitor.unwrapped.state for monitor in env.envs], dtype=np.float32)
    )
    # ... so the next learn() goes on from there
    model.learn(200, reset_num_timesteps=False, callback=SetRewards())
    assert model.num_timesteps >= 37 * n_envs + 200


class NaNReward(BaseCallback):
    """Keeps the parameters at the start of each rollout, and writes a NaN reward into env 0's at call ``at``."""

    def __init__(self, at: int) -> None:
        super().__init__()
        self.at = at
        self.parameters: dict[str, Any] = {}

    def _on_rollout_start(self) -> None:
        self.parameters = copy.deepcopy(self.model.get_parameters())

    def _on_step(self) -> bool:
        if self.n_calls == self.at:
            self.locals["rewards"][0] = np.nan
        return True


@pytest.mark.parametrize(("model_class", "update_mode", "n_envs"), CASES)
def test_a_nan_reward_written_by_a_callback_is_refused_before_it_is_stored(
    model_class: type[BaseAlgorithm], update_mode: str, n_envs: int, tmp_path: Any
) -> None:
    model = make_model(model_class, vec_env(n_envs), update_mode=update_mode, seed=0)
    callback = NaNReward(at=120)
    with pytest.raises(ValueError, match=r"Env 0 returned a non-finite reward \(nan\) .* a callback changed them"):
        model.learn(10_000, callback=callback)
    assert model._n_updates > 0, "the NaN should come after an update"
    # The model is as the last update left it, and saves and loads
    assert parameters_equal(model.get_parameters(), callback.parameters)
    assert np.isfinite(model.rollout_buffer.rewards).all()
    model.save(tmp_path / "model.zip")
    loaded = type(model).load(tmp_path / "model.zip", device="cpu")
    obs = observations()
    np.testing.assert_array_equal(loaded.predict(obs, deterministic=True)[0], model.predict(obs, deterministic=True)[0])


class CopyPolicy(BaseCallback):
    """
    Deep-copies and pickles the policy (self-play and "keep the best policy" callbacks do), and checks that each copy
    acts as the policy does.

    :param everywhere: also at the start and end of rollouts (A2C's policy, which keeps its last update's
        distribution, can be copied in ``_on_step`` only)
    """

    def __init__(self, everywhere: bool = True) -> None:
        super().__init__()
        self.everywhere = everywhere
        self.copies = 0
        self.rollouts = 0
        self.obs = observations()

    def _copy(self) -> None:
        expected = self.model.policy.predict(self.obs, deterministic=True)[0]
        for policy in (copy.deepcopy(self.model.policy), pickle.loads(pickle.dumps(self.model.policy))):
            np.testing.assert_array_equal(policy.predict(self.obs, deterministic=True)[0], expected)
        self.copies += 1

    def _on_rollout_start(self) -> None:
        self.rollouts += 1
        if self.everywhere and self.rollouts % 4 == 2:
            self._copy()

    def _on_step(self) -> bool:
        if self.n_calls % 25 == 0:
            self._copy()
        return True

    def _on_rollout_end(self) -> None:
        if self.everywhere and self.rollouts % 4 == 3:
            self._copy()


def test_a2c_policy_can_be_copied_in_a_callback() -> None:
    """The behaviour this file holds the package to."""
    callback = CopyPolicy(everywhere=False)
    A2C("MlpPolicy", vec_env(3), n_steps=8, seed=0, device="cpu").learn(600, callback=callback)
    assert callback.copies > 5


@pytest.mark.parametrize(("model_class", "update_mode", "n_envs"), CASES)
def test_the_policy_can_be_copied_wherever_a_callback_runs(
    model_class: type[BaseAlgorithm], update_mode: str, n_envs: int
) -> None:
    callback = CopyPolicy()
    model = make_model(model_class, vec_env(n_envs), update_mode=update_mode, seed=0).learn(300, callback=callback)
    assert model._n_updates > 1
    assert callback.copies > 5
    # ... and right after learn(), where no graph of the last update is kept
    if model_class is REINFORCE:
        assert model.policy.action_dist.distribution is None
    callback._copy()
