"""
Inputs from the field that SB3 and rl-zoo3 users have reported as bugs over the years (issue 11), each with its
neighbours: action spaces with an offset, schedules past the end of training, short runs in TensorBoard, and NaN or
infinity from an env; and values a YAML or another library's habit gives that would be taken silently.
"""

import copy
import functools
import glob
import math
import re
import warnings
from pathlib import Path
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from gymnasium import spaces
from rl_zoo3.exp_manager import ExperimentManager
from stable_baselines3 import A2C, DQN, PPO
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.envs import FakeImageEnv
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.logger import configure
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.utils import FloatSchedule, LinearSchedule
from stable_baselines3.common.vec_env import DummyVecEnv
from stable_baselines3.dqn.policies import DQNPolicy, QNetwork
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
from test_contract import make_model, parameters_equal
from test_zoo import run
from torch import nn

from sb3_classic import REINFORCE, NStepSARSA, TileCoding
from sb3_classic.common.buffers import all_finite
from sb3_classic.reinforce.policies import REINFORCEPolicy
from sb3_classic.sarsa.policies import SARSAPolicy

MODEL_LIST = [REINFORCE, NStepSARSA]


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


class RecordLocal(BaseCallback):
    """Keeps a variable of the rollout loop at every step (``self.locals[name]``)."""

    def __init__(self, name: str) -> None:
        super().__init__()
        self.name = name
        self.values: list[Any] = []

    def _on_step(self) -> bool:
        self.values.append(np.copy(self.locals[self.name]))
        return True


class RecordAttribute(RecordLocal):
    """Keeps an attribute of the model at every step."""

    def _on_step(self) -> bool:
        self.values.append(getattr(self.model, self.name))
        return True


# --- 1. Action spaces with an offset --------------------------------------------------------------------------------

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
        np.testing.assert_array_equal(first.actions.numpy(), received)
    log_prob = model.policy.get_distribution(first.observations).log_prob(first.actions)
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


# --- 2. Schedules never evaluated past the end of training ----------------------------------------------------------


def record_learning_rates(optimizer: th.optim.Optimizer) -> list[float]:
    """:return: a list that gets the learning rate of every later ``optimizer.step()``"""
    seen: list[float] = []
    optimizer.register_step_pre_hook(lambda opt, args, kwargs: seen.append(opt.param_groups[0]["lr"]))
    return seen


def optimizers(model: Any) -> list[th.optim.Optimizer]:
    return [model.policy.optimizer] + ([model.policy.value_optimizer] if isinstance(model, REINFORCE) else [])


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_a_callable_learning_rate_never_goes_negative(model_class: type[BaseAlgorithm]) -> None:
    """The issue's case: the last rollout ends past ``total_timesteps``, where ``3e-3 * progress`` is negative."""
    schedule = lambda progress: 3e-3 * progress  # noqa: E731 (the user's input, as written in the issue)
    extra = dict(value_learning_rate=schedule) if model_class is REINFORCE else {}
    model = make_model(model_class, seed=0, learning_rate=schedule, **extra)
    seen = [record_learning_rates(optimizer) for optimizer in optimizers(model)]
    model.learn(1234)
    assert model.num_timesteps > 1234, "the overshoot this test is about did not happen"
    for rates in seen:
        assert rates, "no update"
        assert min(rates) >= 0.0, f"negative learning rate {min(rates)}"
        assert max(rates) <= 3e-3
        # The last update is past the end: the schedule's value at progress 0, not below it
        assert rates[-1] == pytest.approx(0.0, abs=1e-12) or rates[-1] > 0
    assert model._current_progress_remaining == 0.0


def test_the_packages_lin_entries_on_8_envs() -> None:
    """``lin_2e-3`` read by the zoo, 8 envs, train_freq 16: 1,000 steps is not a multiple of 128."""
    schedule = ExperimentManager._preprocess_schedules({"learning_rate": "lin_2e-3"})["learning_rate"]
    env = make_vec_env("CartPole-v1", n_envs=8, seed=0)
    model = make_model(NStepSARSA, env, seed=0, learning_rate=schedule, train_freq=16)
    seen = record_learning_rates(model.policy.optimizer)
    model.learn(1000)
    assert model.num_timesteps == 1024
    assert min(seen) == 0.0  # the last update, past the end, at the schedule's end value
    assert max(seen) <= 2e-3


@pytest.mark.parametrize(
    ("schedule", "low", "high"),
    [
        pytest.param(LinearSchedule(1e-3, 1e-4, 1.0), 1e-4, 1e-3, id="LinearSchedule"),
        pytest.param(FloatSchedule(5e-4), 5e-4, 5e-4, id="FloatSchedule"),
        pytest.param(5e-4, 5e-4, 5e-4, id="float"),
    ],
)
@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_sb3_schedules_stay_in_their_range(model_class: type[BaseAlgorithm], schedule: Any, low: float, high: float) -> None:
    extra = dict(value_learning_rate=schedule) if model_class is REINFORCE else {}
    model = make_model(model_class, seed=0, learning_rate=schedule, **extra)
    seen = [record_learning_rates(optimizer) for optimizer in optimizers(model)]
    model.learn(777)
    for rates in seen:
        assert low - 1e-12 <= min(rates) <= max(rates) <= high + 1e-12


def test_linear_epsilon_stays_in_its_range() -> None:
    class RecordEpsilon(BaseCallback):
        def __init__(self) -> None:
            super().__init__()
            self.values: list[float] = []

        def _on_step(self) -> bool:
            self.values.append(self.model.exploration_rate)  # type: ignore[attr-defined]
            return True

    callback = RecordEpsilon()
    env = make_vec_env("CartPole-v1", n_envs=8, seed=0)
    model = make_model(NStepSARSA, env, seed=0, exploration_schedule="linear", exploration_fraction=1.0, train_freq=16)
    # A schedule of the progress without a clamp of its own (SB3's LinearSchedule has one)
    model.exploration_schedule_fn = lambda progress: 1.0 - 0.9 * (1.0 - progress)
    model.learn(1000, callback=callback)
    assert min(callback.values) >= 0.1 - 1e-12
    assert model.exploration_rate == pytest.approx(0.1)


# --- 3. TensorBoard after a short run --------------------------------------------------------------------------------


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
    """The issue's case: ``learn(1500)`` on CartPole-v1 with one env and the defaults."""
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
    steps: list[tuple[th.Tensor, th.Tensor]] = []
    losses: list[float] = []
    gradient_step = model._gradient_step

    def recorded(observations: th.Tensor, actions: th.Tensor, targets: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
        q_predicted, loss = gradient_step(observations, actions, targets)
        steps.append((q_predicted, targets))
        losses.append(float(loss))
        return q_predicted, loss

    model._gradient_step = recorded
    model.learn(4 * n_envs, reset_num_timesteps=False, log_interval=None)  # no dumps: the values stay in the logger
    dumped = model.logger.name_to_value
    # The update's first pass (per step: one gradient step per transition, then the next passes)
    first_pass = steps[: len(steps) // model.gradient_steps]
    q_first = th.cat([q for q, _ in first_pass])
    targets = th.cat([target for _, target in first_pass])
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


# --- 4. NaN and infinity from an env --------------------------------------------------------------------------------


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


@pytest.mark.parametrize("model_class", MODEL_LIST)
@pytest.mark.parametrize("reset_num_timesteps", [True, False])
def test_learn_zero_steps_returns_the_model_unchanged(model_class: type[BaseAlgorithm], reset_num_timesteps: bool) -> None:
    # SB3's A2C and DQN return from learn(0); a ZeroDivisionError in the progress of a 0-step call was the bug
    model = make_model(model_class, seed=0)
    if not reset_num_timesteps:
        model.learn(64)
    before = copy.deepcopy(model.get_parameters())
    steps = model.num_timesteps
    assert model.learn(0, reset_num_timesteps=reset_num_timesteps) is model
    assert model.num_timesteps == (steps if not reset_num_timesteps else 0)
    assert parameters_equal(model.get_parameters(), before)
    model.learn(64, reset_num_timesteps=False)  # and it goes on training


# Values a YAML or a habit from another library gives, which would otherwise be taken silently or fail far from the
# cause: each is refused at construction with the argument's name
REFUSED_INPUTS = [
    (REINFORCE, dict(policy_kwargs=dict(net_arch=dict(qf=[32]))), ValueError, "unknown key(s) 'qf'"),
    (REINFORCE, dict(policy_kwargs=dict(net_arch=dict(pi=[32], vf=[0]))), ValueError, r"net_arch['vf']=[0]"),
    (NStepSARSA, dict(policy_kwargs=dict(net_arch=64)), ValueError, "net_arch=64 must be a list"),
    (NStepSARSA, dict(policy_kwargs=dict(net_arch=[-5])), ValueError, "integer >= 1"),
    (NStepSARSA, dict(policy_kwargs=dict(net_arch=[0])), ValueError, "integer >= 1"),
    (NStepSARSA, dict(policy_kwargs=dict(net_arch=[dict(pi=[32], vf=[32])])), ValueError, "integer >= 1"),
    (NStepSARSA, dict(policy_kwargs=dict(activation_fn="relu")), TypeError, "activation_fn='relu'"),
    (REINFORCE, dict(policy_kwargs=dict(activation_fn=th.nn.ReLU())), TypeError, "activation_fn=ReLU()"),
    (NStepSARSA, dict(tau=0.5), ValueError, "target_update_interval is None"),
    (NStepSARSA, dict(expected_sarsa="False"), TypeError, "expected_sarsa='False'"),
    (NStepSARSA, dict(policy_kwargs=dict(layer_norm="true")), TypeError, "layer_norm='true'"),
    (REINFORCE, dict(gamma_t_factor="no"), TypeError, "gamma_t_factor='no'"),
    (REINFORCE, dict(use_baseline=0), TypeError, "use_baseline=0"),
    (REINFORCE, dict(handle_timeout_termination="yes"), TypeError, "handle_timeout_termination='yes'"),
    (NStepSARSA, dict(policy_kwargs=dict(with_bias="False")), TypeError, "with_bias='False'"),
    (REINFORCE, dict(lr_decay_factor=0.5, lr_decay_milestones=[]), ValueError, "lr_decay_milestones=[] has no milestone"),
    (NStepSARSA, dict(gradient_steps=-1), ValueError, "DQN's -1"),
    # Passed to SB3, which takes their truth: share_features_extractor="False" shared it
    (REINFORCE, dict(policy_kwargs=dict(share_features_extractor="False")), TypeError, "share_features_extractor='False'"),
    (NStepSARSA, dict(policy_kwargs=dict(normalize_images="False")), TypeError, "normalize_images='False'"),
    # Infinity passed the "> 0" checks: NaN weights (SARSA) or a multinomial error deep in the first update (REINFORCE)
    (NStepSARSA, dict(learning_rate=math.inf), ValueError, "learning_rate=inf must be finite and > 0"),
    (REINFORCE, dict(value_learning_rate=math.inf), ValueError, "value_learning_rate=inf must be finite"),
    (REINFORCE, dict(ent_coef=math.inf), ValueError, "ent_coef=inf must be a number in [0.0, inf)"),
    # A constant initialisation of hidden layers: every hidden unit stays identical, only the output biases learn
    (REINFORCE, dict(policy_kwargs=dict(weight_init=0.0)), ValueError, "weight_init=0.0 sets every weight to one number"),
    (NStepSARSA, dict(policy_kwargs=dict(weight_init=0.1)), ValueError, "have 2 hidden layer(s) with weights in all"),
    # The actor's and the critic's: net_arch=[8] was said to have 2 hidden layers, unexplained
    (REINFORCE, dict(policy_kwargs=dict(net_arch=[8], weight_init=0.0)), ValueError, "counts the actor's and the critic's"),
    # The exponential schedule is max(ε_final, ...): it would run at ε_final from the start
    (NStepSARSA, dict(exploration_initial_eps=0.0), ValueError, "exploration_initial_eps=0.0 is below exploration_final_eps"),
    # Set by the algorithm from its own argument (Python's "got multiple values for keyword argument" before)
    (NStepSARSA, dict(policy_kwargs=dict(target_network=True)), TypeError, "pass target_update_interval=... to NStepSARSA"),
    (REINFORCE, dict(policy_kwargs=dict(use_baseline=False)), TypeError, "pass use_baseline=... to REINFORCE"),
    (REINFORCE, dict(max_grad_norm="0.5"), TypeError, "max_grad_norm='0.5' must be a number > 0"),
    # A switch that would do nothing: no hidden layer to normalise
    (NStepSARSA, dict(policy_kwargs=dict(net_arch=[], layer_norm=True)), ValueError, "net_arch=[] has none"),
    # Keyword arguments of the features extractor or the activation: the hint named the policy's arguments
    (
        NStepSARSA,
        dict(policy_kwargs=dict(features_extractor_kwargs=dict(n_tilings=8))),
        TypeError,
        "features_extractor_kwargs go to features_extractor_class, here the default FlattenExtractor",
    ),
    (
        NStepSARSA,
        dict(policy_kwargs=dict(features_extractor_class=TileCoding, features_extractor_kwargs=dict(tilings=8))),
        TypeError,
        "features_extractor_kwargs go to features_extractor_class=TileCoding: give that class's own arguments",
    ),
    (
        REINFORCE,
        dict(policy_kwargs=dict(activation_fn=th.nn.LeakyReLU, activation_kwargs=dict(slope=0.1))),
        TypeError,
        "activation_kwargs go to activation_fn=LeakyReLU",
    ),
    # ... and without activation_fn, to the default one (the hint listed the policy's arguments, activation_kwargs among
    # them); a partial instead names activation_kwargs
    (
        NStepSARSA,
        dict(policy_kwargs=dict(activation_kwargs=dict(negative_slope=0.1))),
        TypeError,
        "activation_kwargs go to activation_fn, here the default ReLU: pass the activation they belong to",
    ),
    (
        REINFORCE,
        dict(policy_kwargs=dict(activation_fn=functools.partial(th.nn.LeakyReLU, negative_slope=0.2))),
        TypeError,
        "(for its arguments: activation_fn=LeakyReLU, activation_kwargs={'negative_slope': 0.2})",
    ),
    (NStepSARSA, dict(policy_kwargs=dict(net_arch=np.array([16, 8]))), ValueError, "write it as a list, net_arch=[16, 8]"),
]


@pytest.mark.parametrize(("model_class", "kwargs", "error", "message"), REFUSED_INPUTS)
def test_inputs_that_would_be_taken_silently_are_refused(
    model_class: type[BaseAlgorithm], kwargs: dict[str, Any], error: type[Exception], message: str
) -> None:
    with pytest.raises(error, match=re.escape(message)):
        make_model(model_class, **kwargs)


@pytest.mark.parametrize(
    ("model_class", "kwargs"),
    [
        (REINFORCE, dict(policy_kwargs=dict(net_arch=dict(pi=[32], vf=[16])))),
        (REINFORCE, dict(policy_kwargs=dict(net_arch=[]), use_baseline=np.bool_(False))),
        (NStepSARSA, dict(policy_kwargs=dict(net_arch=(np.int64(16),), activation_fn=th.nn.Tanh))),
        (NStepSARSA, dict(target_update_interval=10, tau=0.5, expected_sarsa=np.True_)),
        (NStepSARSA, dict(policy_kwargs=dict(net_arch=[], weight_init=np.float32(0.0)))),
        (REINFORCE, dict(policy_kwargs=dict(net_arch=[], weight_init=0.5), max_grad_norm=np.float32(1.0))),
        (NStepSARSA, dict(exploration_initial_eps=0.0, exploration_final_eps=0.0)),
        (NStepSARSA, dict(exploration_initial_eps=0.0, exploration_final_eps=0.5, exploration_schedule="linear")),
    ],
)
def test_their_valid_neighbours_are_accepted(model_class: type[BaseAlgorithm], kwargs: dict[str, Any]) -> None:
    make_model(model_class, **kwargs).learn(32)


class StopAt(BaseCallback):
    """Stops ``learn()`` after ``steps`` env steps (a callback returning False, as a user's early stop does)."""

    def __init__(self, steps: int) -> None:
        super().__init__()
        self.steps = steps

    def _on_step(self) -> bool:
        return self.num_timesteps < self.steps


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_a_model_loaded_mid_episode_without_reset_starts_new_episodes(
    tmp_path: Path, model_class: type[BaseAlgorithm]
) -> None:
    # The file holds the envs' last observations but not the buffer: REINFORCE trained the rest of the episode as a
    # whole one from t = 0 (γ^t, its length), with its first steps gone
    env = make_vec_env("CartPole-v1", n_envs=1, seed=1)
    model = make_model(model_class, env, seed=1)
    model.learn(100, callback=StopAt(100))
    assert not model._last_episode_starts[0], "the test needs an episode in progress"
    model.save(tmp_path / "model.zip")
    saved_steps = model.num_timesteps
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # without a file the buffer holds the episode: it goes on
        model.learn(10, reset_num_timesteps=False)
    loaded: Any = model_class.load(tmp_path / "model.zip", env=env, force_reset=False, device="cpu")
    resets: list[int] = []
    reset = loaded.env.reset

    def counted_reset() -> Any:
        resets.append(1)
        return reset()

    loaded.env.reset = counted_reset
    with pytest.warns(UserWarning, match="not in its file"):
        loaded.learn(1, reset_num_timesteps=False)
    assert resets == [1]  # new episodes from their first step
    assert loaded.num_timesteps > saved_steps  # the counts go on


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_a_model_loaded_without_reset_into_other_envs_starts_new_episodes(
    tmp_path: Path, model_class: type[BaseAlgorithm]
) -> None:
    # load(env=<3 envs>, force_reset=False) of a model saved with 2: NumPy's "operands could not be broadcast together
    # with shapes (2,) (3,)" at learn()
    model = make_model(model_class, make_vec_env("CartPole-v1", n_envs=2, seed=0), seed=0)
    model.learn(64)
    model.save(tmp_path / "model.zip")
    loaded: Any = model_class.load(
        tmp_path / "model.zip", env=make_vec_env("CartPole-v1", n_envs=3, seed=1), force_reset=False, device="cpu"
    )
    with pytest.warns(UserWarning, match="last observations of 2 envs, and its env has 3"):
        loaded.learn(64, reset_num_timesteps=False)
    assert loaded.num_timesteps > model.num_timesteps
    assert loaded._last_obs.shape[0] == 3


class NoisyLinear(nn.Linear):
    """A NoisyNet-like output layer: noisy weights in train mode only (it reads ``self.training``)."""

    def forward(self, x: th.Tensor) -> th.Tensor:
        weight = self.weight + 0.5 * th.randn_like(self.weight) if self.training else self.weight
        return nn.functional.linear(x, weight, self.bias)


class NoisySARSAPolicy(SARSAPolicy):
    def make_q_net(self) -> QNetwork:
        q_net = super().make_q_net()
        output = q_net.q_net[-1]
        assert isinstance(output, nn.Linear)
        q_net.q_net[-1] = NoisyLinear(output.in_features, output.out_features)
        return q_net


def test_a_layer_of_the_users_is_put_in_eval_mode_for_predict() -> None:
    # set_training_mode only flipped the policy's and q_net's flags where no dropout or batch norm was found: the
    # NoisyNet layer stayed in train mode, and predict(deterministic=True) was random (DQN's is not)
    model = NStepSARSA(NoisySARSAPolicy, "CartPole-v1", seed=0, device="cpu")
    model.learn(100)
    obs = np.array([0.01, 0.0, 0.01, 0.0], dtype=np.float32)
    assert len({int(model.predict(obs, deterministic=True)[0]) for _ in range(30)}) == 1
    assert not model.policy.q_net.q_net[-1].training
    model.policy.set_training_mode(True)
    assert model.policy.q_net.q_net[-1].training
    # SB3's plain layers keep the shortcut; RReLU's slopes are random in train mode
    assert not NStepSARSA("MlpPolicy", "CartPole-v1", device="cpu").policy.mode_dependent
    rrelu = NStepSARSA("MlpPolicy", "CartPole-v1", policy_kwargs=dict(activation_fn=nn.RReLU), device="cpu")
    assert rrelu.policy.mode_dependent


def test_make_q_net_must_return_a_qnetwork() -> None:
    class Plain(SARSAPolicy):
        def make_q_net(self) -> Any:
            return nn.Sequential(nn.Linear(4, 2))

    # (AttributeError: 'Sequential' object has no attribute 'features_extractor')
    with pytest.raises(TypeError, match="make_q_net returned a Sequential: Plain needs an SB3 QNetwork"):
        NStepSARSA(Plain, "CartPole-v1", device="cpu")


def test_reinforce_acts_with_a_subclass_forward() -> None:
    # A2C's rollouts act with policy(obs)'s actions; REINFORCE drew from the distribution, ignoring the override
    class AlwaysOne(REINFORCEPolicy):
        def forward(self, obs: th.Tensor, deterministic: bool = False) -> tuple[th.Tensor, th.Tensor, th.Tensor]:
            actions, values, log_prob = super().forward(obs, deterministic)
            return th.ones_like(actions), values, log_prob

    actions = RecordLocal("actions")
    REINFORCE(AlwaysOne, "CartPole-v1", seed=0, device="cpu").learn(300, callback=actions)
    assert set(np.concatenate(actions.values).tolist()) == {1}


def test_an_exploration_schedule_of_the_users(tmp_path: Path) -> None:
    # SB3's DQN keeps its ε schedule as model.exploration_schedule: assigning one was ignored (ε went on decaying), and
    # the saved file then failed to load ("exploration_schedule=LinearSchedule(...) must be one of ...")
    model = NStepSARSA("MlpPolicy", "CartPole-v1", seed=0, device="cpu")
    model.exploration_schedule = LinearSchedule(0.3, 0.3, 1.0)
    model.learn(300)
    assert model.exploration_rate == pytest.approx(0.3)
    model.save(tmp_path / "model.zip")
    assert NStepSARSA.load(tmp_path / "model.zip", device="cpu").exploration_rate == pytest.approx(0.3)
    # ... or passed: ε follows the progress of each learn() call, as DQN's
    decaying = NStepSARSA("MlpPolicy", "CartPole-v1", exploration_schedule=LinearSchedule(1.0, 0.0, 1.0), device="cpu")
    rates = RecordAttribute("exploration_rate")
    decaying.learn(400, callback=rates)
    assert rates.values[0] > 0.9
    assert rates.values[-1] < 0.1
    with pytest.raises(ValueError, match=r"exploration_fraction=0.2 belongs to the 'linear' or 'exponential' ε schedule"):
        NStepSARSA("MlpPolicy", "CartPole-v1", exploration_schedule=FloatSchedule(0.1), exploration_fraction=0.2)
    with pytest.raises(ValueError, match=r"exploration_initial_eps=0.9 belongs to .* drop exploration_initial_eps"):
        NStepSARSA("MlpPolicy", "CartPole-v1", exploration_schedule=FloatSchedule(0.1), exploration_initial_eps=0.9)
    with pytest.raises(ValueError, match=r"gave ε = 2\.0 at progress remaining 1: ε is a probability"):
        NStepSARSA("MlpPolicy", "CartPole-v1", exploration_schedule=FloatSchedule(2.0), device="cpu")


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_a_constant_init_of_a_cnn_names_its_features_extractor(model_class: type[BaseAlgorithm]) -> None:
    # CnnPolicy with net_arch=[] was told to pass net_arch=[]: the hidden layers are NatureCNN's
    env = FakeImageEnv(screen_height=36, screen_width=36, n_channels=1, discrete=True)
    # REINFORCE's actor and critic have a NatureCNN each (the count said 4 of 8, one overwriting the other)
    count = 8 if model_class is REINFORCE else 4
    expected = rf"have {count} hidden layer\(s\) .* {count} of them are in the features extractor \(NatureCNN's {count}\)"
    with pytest.raises(ValueError, match=expected):
        model_class("CnnPolicy", env, policy_kwargs=dict(net_arch=[], weight_init=0.0), device="cpu")  # type: ignore[call-arg]


@pytest.mark.parametrize(("model_class", "policy"), [(REINFORCE, ActorCriticPolicy), (NStepSARSA, DQNPolicy)])
def test_a_policy_class_of_another_algorithm_is_named_as_such(model_class: type[BaseAlgorithm], policy: type) -> None:
    # It failed on this package's own policy_kwargs ("policy_kwargs: ... unexpected keyword argument 'weight_init'"),
    # which the user had not passed
    with pytest.raises(TypeError, match=rf"policy=.*{policy.__name__} is not one of {model_class.__name__}'s policies: "):
        model_class(policy, "CartPole-v1", device="cpu")  # type: ignore[call-arg]


@pytest.mark.parametrize(
    ("saved_class", "loading_class"),
    # DQN's file failed on its train_freq tuple ("train_freq=TrainFreq(...) must be an integer >= 1"), which the
    # arguments' checks read before the policy class
    [(REINFORCE, NStepSARSA), (NStepSARSA, REINFORCE), (DQN, NStepSARSA), (A2C, REINFORCE), (PPO, NStepSARSA)],
)
def test_a_file_of_the_other_algorithm_is_named_as_such(
    tmp_path: Path, saved_class: type[BaseAlgorithm], loading_class: type[BaseAlgorithm]
) -> None:
    if saved_class in (REINFORCE, NStepSARSA):
        make_model(saved_class).save(tmp_path / "model.zip")
    else:
        peer: Any = saved_class
        peer("MlpPolicy", "CartPole-v1", device="cpu").save(tmp_path / "model.zip")
    with pytest.raises(TypeError, match="saved by another algorithm") as error:
        loading_class.load(tmp_path / "model.zip")
    # ... naming the class to load it with (it said "REINFORCE.load or NStepSARSA.load" for SB3's files too)
    assert {DQN: "stable_baselines3.DQN.load", A2C: "A2C.load or PPO.load", PPO: "A2C.load or PPO.load"}.get(
        saved_class, f"({saved_class.__name__}.load)"
    ) in str(error.value)
    # ... and the file itself is intact
    assert isinstance(saved_class.load(tmp_path / "model.zip"), saved_class)


# --- Pre-empted jobs: checkpoints and resuming (a researcher's trial) ------------------------------------------------


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_save_replaces_the_file_whole(
    model_class: type[BaseAlgorithm], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """
    A save interrupted midway (a pre-empted job: here an error while writing) leaves the earlier file whole and loadable,
    and no temporary file; SB3 wrote over the file in place, and a job killed then lost its checkpoint.
    """
    model = make_model(model_class, seed=0).learn(200)
    model.save(tmp_path / "checkpoints" / "model")  # (the folder is created, .zip added, as SB3 does)
    saved = (tmp_path / "checkpoints" / "model.zip").read_bytes()
    model.learn(200, reset_num_timesteps=False)

    def interrupted(*args: Any, **kwargs: Any) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(th, "save", interrupted)  # (SB3 writes the data first, then each state dict with th.save)
    with pytest.raises(KeyboardInterrupt):
        model.save(tmp_path / "checkpoints" / "model")
    monkeypatch.undo()
    assert (tmp_path / "checkpoints" / "model.zip").read_bytes() == saved
    assert [path.name for path in (tmp_path / "checkpoints").iterdir()] == ["model.zip"]
    loaded = model_class.load(tmp_path / "checkpoints" / "model", device="cpu")
    assert loaded.num_timesteps < model.num_timesteps
    model.save(tmp_path / "checkpoints" / "model")
    assert model_class.load(tmp_path / "checkpoints" / "model.zip", device="cpu").num_timesteps == model.num_timesteps
    # As SB3's save: the file keeps its permission bits, and a symbolic link is written through, not replaced
    (tmp_path / "checkpoints" / "model.zip").chmod(0o640)
    (tmp_path / "latest.zip").symlink_to(tmp_path / "checkpoints" / "model.zip")
    model.learn(100, reset_num_timesteps=False)
    model.save(tmp_path / "latest.zip")
    assert (tmp_path / "latest.zip").is_symlink()
    assert (tmp_path / "checkpoints" / "model.zip").stat().st_mode & 0o777 == 0o640
    assert model_class.load(tmp_path / "latest.zip", device="cpu").num_timesteps == model.num_timesteps


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_set_parameters_that_fail_leave_the_model_as_it_was(model_class: type[BaseAlgorithm]) -> None:
    """SB3's set_parameters changed the model, then raised: a trained model was left with part of other weights."""
    model = make_model(model_class, seed=0).learn(200)
    before = copy.deepcopy(model.get_parameters())
    other = make_model(model_class, seed=1, policy_kwargs=dict(net_arch=[16, 8])).get_parameters()
    with pytest.raises(RuntimeError, match="size mismatch"):
        model.set_parameters(other)  # the first layer matches, the next ones do not
    assert parameters_equal(model.get_parameters(), before)
    with pytest.raises(ValueError, match="Names of parameters do not match"):
        model.set_parameters({"policy": make_model(model_class, seed=1).get_parameters()["policy"]})  # no optimizers
    assert parameters_equal(model.get_parameters(), before)
    # An optimizer's state of another class: refused (learn() then failed on a missing 'betas')
    sgd = make_model(model_class, seed=1, policy_kwargs=dict(net_arch=[16], optimizer_class=th.optim.SGD)).get_parameters()
    with pytest.raises(ValueError, match=r"policy\.optimizer .*lacks the hyperparameters .*betas"):
        model.set_parameters(sgd)
    assert parameters_equal(model.get_parameters(), before)
    model.set_parameters(make_model(model_class, seed=1).get_parameters())  # a matching one still loads
    assert not parameters_equal(model.get_parameters(), before)
    # So does one into an optimizer with a scheduler attached (its initial_lr is not in the state given)
    th.optim.lr_scheduler.StepLR(model.policy.optimizer, step_size=10)
    model.set_parameters(make_model(model_class, seed=2).get_parameters())
    model.learn(100)


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_load_refuses_what_is_not_an_argument(model_class: type[BaseAlgorithm], tmp_path: Path) -> None:
    """SB3 set a misspelt argument as an attribute, which nothing read: the run went on with the saved value."""
    make_model(model_class, seed=0).save(tmp_path / "model")
    misspelt = "exploration_final_esp" if model_class is NStepSARSA else "value_learning_rat"
    with pytest.raises(TypeError, match=rf"{misspelt}=0.01, which is not an argument .*did you mean {misspelt[:-3]}"):
        model_class.load(tmp_path / "model", **{misspelt: 0.01})  # type: ignore[arg-type]
    loaded: Any = model_class.load(tmp_path / "model", gamma=0.9, seed=3)
    assert loaded.gamma == 0.9  # (arguments still change)
    with pytest.raises(TypeError, match="keeps its saved policy class"):
        model_class.load(tmp_path / "model", policy="MlpPolicy")

    class Subclass(model_class):  # type: ignore[valid-type,misc]
        """A subclass passing its parent's arguments on through **kwargs: they are arguments too."""

        def __init__(self, *args: Any, bonus: float = 0.0, **kwargs: Any) -> None:
            self.bonus = bonus
            super().__init__(*args, **kwargs)

    Subclass("MlpPolicy", "CartPole-v1", policy_kwargs=dict(net_arch=[16]), seed=0, device="cpu").save(tmp_path / "subclass")
    assert Subclass.load(tmp_path / "subclass", gamma=0.9, bonus=1.0, verbose=0).gamma == 0.9
    with pytest.raises(TypeError, match="did you mean gamma"):
        Subclass.load(tmp_path / "subclass", gama=0.9)


@pytest.mark.parametrize(
    ("model_class", "change"),
    [
        (NStepSARSA, dict(target_update_interval=1)),
        (NStepSARSA, dict(averaging_tau=0.05)),
        (REINFORCE, dict(use_baseline=False)),
    ],
)
def test_custom_objects_that_change_the_networks_are_named(
    model_class: type[BaseAlgorithm], change: dict[str, Any], tmp_path: Path
) -> None:
    """As the same change through kwargs is (it gave PyTorch's "Missing key(s) in state_dict")."""
    make_model(model_class, seed=0).save(tmp_path / "model")
    (key, value), saved = next(iter(change.items())), model_class.load(tmp_path / "model").__dict__
    with pytest.raises(ValueError, match=rf"{key}={value!r} builds other networks .*Pass {key}={saved[key]!r}"):
        model_class.load(tmp_path / "model", custom_objects=change)


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_learn_without_an_env_says_how_to_give_one(model_class: type[BaseAlgorithm], tmp_path: Path) -> None:
    make_model(model_class, seed=0).save(tmp_path / "model")
    loaded = model_class.load(tmp_path / "model")
    with pytest.raises(ValueError, match=r"no env to train on .*set_env"):  # (SB3: a bare AssertionError)
        loaded.learn(100)
    loaded.set_env(make_vec_env("CartPole-v1"))
    loaded.learn(100)


@pytest.mark.parametrize(
    ("model_class", "settings", "n_envs"),
    [
        (model_class, settings, n_envs)
        for model_class in MODEL_LIST
        for settings in (dict(), dict(update_mode="per_step"))
        for n_envs in (1, 3)
        if not (model_class is REINFORCE and settings and n_envs > 1)  # (the slowest, and no other code path)
    ],
)
def test_learn_in_two_calls_is_learn_in_one(model_class: type[BaseAlgorithm], settings: dict[str, Any], n_envs: int) -> None:
    """The README's idiom for a run split in two (a resumed job): the parameters and optimizers of one call, to the bit."""
    if model_class is NStepSARSA and settings:
        settings = dict(settings, train_freq=1, gradient_steps=1)

    def model() -> Any:
        return make_model(model_class, make_vec_env("CartPole-v1", n_envs=n_envs, seed=0), seed=0, **settings)

    whole = model().learn(500)
    split = model().learn(200)
    split.learn(500 - split.num_timesteps, reset_num_timesteps=False)
    assert split.num_timesteps == whole.num_timesteps
    assert parameters_equal(split.get_parameters(), whole.get_parameters())
