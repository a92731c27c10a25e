"""
Action and observation spaces: Discrete and MultiDiscrete actions with an offset (``start``) in the rollout loop,
``predict``, evaluation, save/load and the zoo; Box actions of any shape; Discrete observations returned as Python ints;
and final observations of another shape than their space's.
"""

import math
import re
from pathlib import Path
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from gymnasium import spaces
from recorders import RecordLocal
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv
from test_contract import MODEL_LIST, make_model
from test_zoo import run

from sb3_classic import REINFORCE, NStepSARSA
from sb3_classic.common.buffers import all_finite


class ActionRecordingEnv(gym.Env[np.ndarray, Any]):
    """
    Episodes of 6 steps with random observations; records every action it receives and refuses one outside its
    action space (as a real env with an offset would misbehave).

    :param action_space: the action space to declare
    """

    def __init__(self, action_space: spaces.Space) -> None:
        self.observation_space = spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32)
        self.action_space = action_space
        self.received: list[Any] = []
        self._steps = 0

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        self._steps = 0
        return self.observation_space.sample(), {}

    def step(self, action: Any) -> tuple[np.ndarray, SupportsFloat, bool, bool, dict[str, Any]]:
        if not self.action_space.contains(np.asarray(action, dtype=self.action_space.dtype)):
            raise ValueError(f"action {action!r} is not in {self.action_space}")
        self.received.append(np.array(action).tolist())
        self._steps += 1
        return self.observation_space.sample(), float(np.sum(action)), self._steps >= 6, False, {}


def all_values(space: spaces.Space) -> set[Any]:
    """Every action of a Discrete or MultiDiscrete space, as the env takes them."""
    if isinstance(space, spaces.Discrete):
        return set(range(int(space.start), int(space.start + space.n)))
    assert isinstance(space, spaces.MultiDiscrete)
    grids = np.meshgrid(*[np.arange(s, s + n) for s, n in zip(space.start, space.nvec, strict=True)], indexing="ij")
    return {tuple(int(v) for v in values) for values in np.stack([g.ravel() for g in grids], axis=1)}


def as_set(actions: list[Any]) -> set[Any]:
    return {tuple(a) if isinstance(a, list) else a for a in actions}


def exploring(model_class: type[BaseAlgorithm], space: spaces.Space, **kwargs: Any) -> Any:
    """A model that acts at random while it learns (ε = 1 for SARSA; REINFORCE's untrained policy is near-uniform)."""
    env = ActionRecordingEnv(space)
    extra = dict(exploration_initial_eps=1.0, exploration_final_eps=1.0) if model_class is NStepSARSA else {}
    return make_model(model_class, DummyVecEnv([lambda: Monitor(env)]), seed=0, **extra, **kwargs), env


OFFSET_SPACES = {
    "Discrete(3,start=1)": spaces.Discrete(3, start=1),
    "Discrete(4,start=-2)": spaces.Discrete(4, start=-2),
}


MULTI_OFFSET_SPACES = {
    "MultiDiscrete([3,2],start=[1,-1])": spaces.MultiDiscrete([3, 2], start=[1, -1]),
    "MultiDiscrete(3 dims, several starts)": spaces.MultiDiscrete([2, 3, 2], start=[5, 0, -3]),
}


OFFSET_CASES = [
    pytest.param(cls, space, id=f"{cls.__name__}-{name}")
    for cls, cases in ((REINFORCE, OFFSET_SPACES | MULTI_OFFSET_SPACES), (NStepSARSA, OFFSET_SPACES))
    for name, space in cases.items()
]


@pytest.mark.parametrize(("model_class", "space"), OFFSET_CASES)
def test_offset_action_spaces_act_in_the_envs_values(tmp_path: Path, model_class: type[BaseAlgorithm], space: Any) -> None:
    model, env = exploring(model_class, space)
    sampled_indices, sent = RecordLocal("actions"), RecordLocal("env_actions")
    model.learn(400, callback=[sampled_indices, sent])
    # Every action the env received is one of its own, and all of them were tried
    assert as_set(env.received) == all_values(space)
    # What the rollout loop stores in the buffer (and the networks see) are indices 0..n-1
    indices = np.concatenate(sampled_indices.values)
    assert indices.min() == 0
    assert (indices < np.asarray(space.nvec if isinstance(space, spaces.MultiDiscrete) else space.n)).all()
    # ... and a callback finds the env's values beside them (README)
    np.testing.assert_array_equal(np.concatenate(sent.values), indices + np.asarray(space.start))

    obs = np.stack([env.observation_space.sample() for _ in range(300)])
    for deterministic in (True, False):
        actions, _ = model.predict(obs, deterministic=deterministic)
        assert all(space.contains(np.asarray(a, dtype=space.dtype)) for a in actions), actions[:5]
    # predict(deterministic=False) explores over the env's values too (SARSA's ε is 1 here)
    sampled, _ = model.predict(obs, deterministic=False)
    assert as_set([np.asarray(a).tolist() for a in sampled]) == all_values(space)
    # The policy alone, as rl-zoo3 and users call it, agrees
    np.testing.assert_array_equal(model.policy.predict(obs, deterministic=True)[0], model.predict(obs, deterministic=True)[0])

    # Evaluation (EvalCallback, the zoo's evaluations) steps the env with predict's actions
    env.received.clear()
    evaluate_policy(model, model.get_env(), n_eval_episodes=3)
    assert as_set(env.received) <= all_values(space)

    # load(): the space, and so the offset, comes back with the model
    model.save(tmp_path / "model")
    loaded = model_class.load(tmp_path / "model", device="cpu")
    assert loaded.action_space == space
    np.testing.assert_array_equal(loaded.predict(obs, deterministic=True)[0], model.predict(obs, deterministic=True)[0])
    loaded.set_env(DummyVecEnv([lambda: Monitor(env)]))
    env.received.clear()
    loaded.learn(100)
    assert as_set(env.received) <= all_values(space)


def test_offset_greedy_action_is_the_index_plus_start() -> None:
    space = spaces.Discrete(3, start=-5)
    model, env = exploring(NStepSARSA, space)
    obs = np.stack([env.observation_space.sample() for _ in range(50)])
    with th.no_grad():
        indices = model.policy.q_net(th.as_tensor(obs)).argmax(dim=1).numpy()
    np.testing.assert_array_equal(model.predict(obs, deterministic=True)[0], indices - 5)


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_zero_start_is_unchanged(model_class: type[BaseAlgorithm]) -> None:
    """``start=0`` (the usual case) and ``Box`` actions have no offset: the loop sends what it samples."""
    model, env = exploring(model_class, spaces.Discrete(3))
    assert model._action_offset is None
    model.learn(100)
    assert as_set(env.received) == {0, 1, 2}


def test_box_actions_are_unchanged() -> None:
    space = spaces.Box(-0.5, 2.0, shape=(2,), dtype=np.float32)
    model, env = exploring(REINFORCE, space)
    assert model._action_offset is None
    model.learn(200)
    received = np.array(env.received)
    # Clipped to the bounds, never shifted: both bounds are reached by the unit Gaussian's clipped samples
    assert received.min() == pytest.approx(-0.5)
    assert received.max() <= 2.0
    obs = np.stack([env.observation_space.sample() for _ in range(20)])
    np.testing.assert_array_equal(model.predict(obs, deterministic=True)[0], model.policy.predict(obs, deterministic=True)[0])


@pytest.mark.parametrize("update_mode", ["batch", "per_step"])
@pytest.mark.parametrize("n_envs", [1, 2])
@pytest.mark.parametrize("shape", [(1, 1), (2, 3)])
def test_box_actions_of_several_dimensions_keep_their_shape(shape: tuple[int, ...], n_envs: int, update_mode: str) -> None:
    """
    A Box of shape (2, 3) (or (1, 1)) gets actions of that shape from the rollout loop and ``predict``, as from A2C.
    SB3's Gaussian draws them flat, (n_envs, 6): the env was sent (n_envs, 6) (or (1,) for (1, 1)), and with 2 envs
    the buffer refused them; training's log-probabilities are of the flat actions the env received.
    """
    space = spaces.Box(-100.0, 100.0, shape=shape, dtype=np.float32)  # wide: the unit Gaussian's draws are not clipped
    envs = [ActionRecordingEnv(space) for _ in range(n_envs)]
    vec_env = DummyVecEnv([lambda env=env: Monitor(env) for env in envs])  # type: ignore[misc]
    model = make_model(REINFORCE, vec_env, seed=0, update_mode=update_mode)
    batches = []
    training_batch = model._training_batch

    def recorded() -> Any:
        batch = training_batch()
        batches.append(batch)
        return batch

    model._training_batch = recorded
    model.learn(60)
    assert all(np.shape(action) == shape for env in envs for action in env.received)
    first = batches[0]
    assert first is not None
    # One env: the batch is its first episode(s), in the order the env received them, flattened as SB3's buffer does
    if n_envs == 1:
        received = np.array(envs[0].received[: len(first.actions)], dtype=np.float32).reshape(len(first.actions), -1)
        np.testing.assert_array_equal(first.actions, received)
    log_prob = model.policy.get_distribution(th.as_tensor(first.observations)).log_prob(th.as_tensor(first.actions))
    assert log_prob.shape == (len(first.targets),)
    observations = np.stack([envs[0].observation_space.sample() for _ in range(4)])
    assert model.predict(observations, deterministic=True)[0].shape == (4, *shape)
    assert model.predict(observations[0])[0].shape == shape


OFFSET_ENV_MODULE = """
import gymnasium as gym
import numpy as np
from gymnasium import spaces


class OffsetActions(gym.Env):
    \"\"\"Actions 1, 2, 3; anything else is an error. Reward 1 for action 3, episodes of 20 steps.\"\"\"

    def __init__(self):
        self.observation_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.action_space = spaces.Discrete(3, start=1)
        self._steps = 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self._steps = 0
        return self.observation_space.sample(), {}

    def step(self, action):
        if not self.action_space.contains(int(action)):
            raise ValueError(f"action {action!r} is not in {self.action_space}")
        self._steps += 1
        return self.observation_space.sample(), float(action == 3), self._steps >= 20, False, {}


gym.register("OffsetActions-v0", entry_point=OffsetActions)
"""


@pytest.mark.parametrize("algo", ["reinforce", "nstep_sarsa"])
def test_offset_actions_through_the_zoo(tmp_path: Path, algo: str) -> None:
    """``python -m rl_zoo3.train`` (with evaluations) and ``enjoy`` on an env whose actions are 1, 2, 3."""
    (tmp_path / "offset_env.py").write_text(OFFSET_ENV_MODULE)
    common = ["--algo", algo, "--env", "OffsetActions-v0", "--gym-packages", "offset_env"]
    env = {"PYTHONPATH": str(tmp_path)}
    train = run(
        tmp_path, "-m", "rl_zoo3.train", *common, "-n", "600", "--seed", "0", "--eval-freq", "200", "--eval-episodes", "2",
        env=env,
    )  # fmt: skip
    assert "Using 'default' hyperparameters" in train.stdout
    evaluations = np.load(tmp_path / "logs" / algo / "OffsetActions-v0_1" / "evaluations.npz")
    assert len(evaluations["timesteps"]) >= 2
    enjoy = run(tmp_path, "-m", "rl_zoo3.enjoy", *common, "-f", "logs", "--no-render", "-n", "100", env=env)
    assert "Episode Reward" in enjoy.stdout
    assert "not in Discrete" not in enjoy.stderr


class FinalObservationOfShape(gym.Wrapper[np.ndarray, Any, np.ndarray, Any]):
    """Truncates its 4th step with a final observation of another shape than its space's."""

    def __init__(self, env: gym.Env, shape: tuple[int, ...]) -> None:
        super().__init__(env)
        self.shape, self.steps = shape, 0

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.steps += 1
        if self.steps == 4:
            return np.full(self.shape, 0.5, dtype=np.float32), reward, False, True, info
        return obs, reward, terminated, truncated, info


@pytest.mark.parametrize("model_class", MODEL_LIST)
@pytest.mark.parametrize("shape", [(1,), (), (6,)])
def test_a_final_observation_of_another_shape_is_refused(model_class: type[BaseAlgorithm], shape: tuple[int, ...]) -> None:
    # (1,) and () were broadcast into CartPole's (4,) and bootstrapped from ([x, x, x, x]); (6,) was NumPy's "could not
    # broadcast input array" from the buffer; A2C refuses both in predict
    env = DummyVecEnv([lambda: FinalObservationOfShape(gym.make("CartPole-v1"), shape)])
    model = make_model(model_class, env, seed=0)
    expected = rf"Env 0 returned a final observation .* of shape {re.escape(str(shape))} at step 4 .* has shape \(4,\)"
    with pytest.raises(ValueError, match=expected):
        model.learn(200)


class DiscreteWalk(gym.Env[Any, np.int64]):
    """
    A walk on 5 states whose observations are what Gymnasium's tabular envs (FrozenLake, CliffWalking) return: the
    state as a plain Python int, or inside a Dict beside a Box; 3-step episodes end by a time limit (a truncation).

    :param as_dict: observe ``{"state": int, "noise": Box}`` instead of the int
    """

    def __init__(self, as_dict: bool = False) -> None:
        self.as_dict = as_dict
        state_space = spaces.Discrete(5)
        self.observation_space: spaces.Space[Any] = (
            spaces.Dict({"state": state_space, "noise": spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)})
            if as_dict
            else state_space
        )
        self.action_space = spaces.Discrete(2)
        self._state = 2

    def _obs(self) -> Any:
        return {"state": self._state, "noise": np.zeros(2, dtype=np.float32)} if self.as_dict else self._state

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        super().reset(seed=seed)
        self._state = 2
        return self._obs(), {}

    def step(self, action: np.int64) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        self._state = min(4, max(0, self._state + (1 if int(action) == 1 else -1)))
        return self._obs(), float(self._state == 4), False, False, {}


@pytest.mark.parametrize("model_class", MODEL_LIST)
@pytest.mark.parametrize("as_dict", [False, True])
def test_discrete_observations_returned_as_python_ints(model_class: type[BaseAlgorithm], as_dict: bool) -> None:
    # The VecEnv passes a truncated episode's last observation through as the env returned it (a Python int here),
    # and the check for NaN in it failed on the int ('int' object has no attribute 'dtype'), as A2C and DQN do not
    env = make_vec_env(lambda: gym.wrappers.TimeLimit(DiscreteWalk(as_dict), max_episode_steps=3), n_envs=2)
    policy = "MultiInputPolicy" if as_dict else "MlpPolicy"
    model: Any = model_class(policy, env, seed=0, device="cpu")  # type: ignore[call-arg]
    model.learn(60)
    assert model.num_timesteps >= 60
    assert all_finite(3)
    assert all_finite({"state": 3, "noise": np.zeros(2)})
    assert not all_finite(math.nan)
