"""
Learning-rate decays and ε schedules: as pure functions, inside training, and across learn() calls and save/load;
callables, SB3's schedules, the zoo's ``lin_`` entries and an ε schedule of the user's stay in their range when the last
rollout ends past ``total_timesteps``.
"""

from pathlib import Path
from typing import Any

import pytest
import torch as th
from recorders import RecordAttribute
from rl_zoo3.exp_manager import ExperimentManager
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.utils import FloatSchedule, LinearSchedule
from test_contract import MODEL_LIST, make_model

from sb3_classic import REINFORCE, NStepSARSA
from sb3_classic.common.schedules import ExponentialDecay, StepDecay


def test_step_decay() -> None:
    every = StepDecay(factor=0.5, every=25)
    assert [every(count) for count in (0, 24, 25, 49, 50, 100)] == [1.0, 1.0, 0.5, 0.5, 0.25, 0.0625]
    milestones = StepDecay(factor=0.1, milestones=[500, 300])
    assert [milestones(count) for count in (0, 299, 300, 499, 500, 10_000)] == pytest.approx([1, 1, 0.1, 0.1, 0.01, 0.01])
    assert StepDecay()(1_000_000) == 1.0


def test_exponential_decay() -> None:
    decay = ExponentialDecay(start=1.0, end=0.05, decay_rate=0.99)
    assert decay(0) == 1.0
    assert decay(10) == pytest.approx(0.99**10)
    assert decay(10_000) == 0.05


def optimizers(model: Any) -> list[th.optim.Optimizer]:
    """:return: the policy's optimizer, and REINFORCE's of the baseline"""
    return [model.policy.optimizer] + ([model.policy.value_optimizer] if isinstance(model, REINFORCE) else [])


def optimizer_lrs(model: REINFORCE | NStepSARSA) -> list[float]:
    return [optimizer.param_groups[0]["lr"] for optimizer in optimizers(model)]


def test_reinforce_learning_rates_are_separate_and_decay_per_episode() -> None:
    model = REINFORCE(
        "MlpPolicy", "CartPole-v1", learning_rate=3e-3, value_learning_rate=1e-2, lr_decay_every=5, lr_decay_factor=0.5, seed=0
    )
    assert optimizer_lrs(model) == [3e-3, 1e-2]
    model.learn(1000)
    # The rates of the last update, set from the episodes completed before it
    decay = 0.5 ** ((model._completed_episodes - 1) // 5)
    assert model._completed_episodes > 20
    assert optimizer_lrs(model) == pytest.approx([3e-3 * decay, 1e-2 * decay])


def test_sarsa_learning_rate_decays_at_milestones_of_updates() -> None:
    model = NStepSARSA(
        "MlpPolicy",
        "CartPole-v1",
        learning_rate=1e-3,
        train_freq=10,
        gradient_steps=1,
        lr_decay_milestones=[10, 30],
        lr_decay_factor=0.1,
        lr_decay_unit="update",
    )
    model.learn(200)  # 20 updates; the last set its rate after 19: one milestone passed
    assert model._n_updates == 20
    assert optimizer_lrs(model) == pytest.approx([1e-4])
    model.learn(200, reset_num_timesteps=False)  # 40 updates: both passed
    assert optimizer_lrs(model) == pytest.approx([1e-5])


def test_learning_rate_schedule_times_decay() -> None:
    model = NStepSARSA(
        "MlpPolicy",
        "CartPole-v1",
        learning_rate=LinearSchedule(1e-3, 1e-4, 1.0),
        train_freq=10,
        gradient_steps=1,
        lr_decay_every=1,
        lr_decay_factor=0.5,
        lr_decay_unit="update",
    )
    model.learn(100)  # 10 updates; the last one after the last rollout (progress 0: 1e-4) and 9 decays
    assert optimizer_lrs(model) == pytest.approx([1e-4 * 0.5**9])


def test_exponential_epsilon_decays_per_episode_and_continues_across_learn_and_load(tmp_path: Path) -> None:
    model = NStepSARSA(
        "MlpPolicy", "CartPole-v1", exploration_initial_eps=1.0, exploration_final_eps=0.05, exploration_decay_rate=0.9, seed=0
    )
    model.learn(300)
    expected = max(0.05, 0.9**model._completed_episodes)
    assert model._completed_episodes > 5
    assert model.exploration_rate == pytest.approx(expected)
    model.save(tmp_path / "model.zip")
    # Loaded as rl-zoo3's -i does (hyperparameters passed again), then learn() with reset_num_timesteps=True
    loaded = NStepSARSA.load(tmp_path / "model.zip", env=model.get_env(), exploration_initial_eps=1.0)
    assert loaded.exploration_rate == pytest.approx(expected)
    episodes_before = loaded._completed_episodes
    loaded.learn(300)
    assert loaded._completed_episodes > episodes_before
    assert loaded.exploration_rate == pytest.approx(max(0.05, 0.9**loaded._completed_episodes))
    assert loaded.exploration_rate < expected


def test_linear_epsilon_follows_progress_like_dqn() -> None:
    model = NStepSARSA(
        "MlpPolicy",
        "CartPole-v1",
        exploration_schedule="linear",
        exploration_initial_eps=1.0,
        exploration_final_eps=0.1,
        exploration_fraction=0.5,
        train_freq=10,
    )
    assert model.exploration_rate == 1.0
    model.learn(100)
    # The last update saw progress 1 − 100/100 = 0 → past the fraction: the final value
    assert model.exploration_rate == pytest.approx(0.1)
    model.learn(200)
    assert model.exploration_rate == pytest.approx(0.1)
    model.exploration_fraction = 1.0
    model._setup_model()
    model.learn(100)
    assert model.exploration_rate == pytest.approx(0.1)


def test_an_episode_step_decay_steps_after_each_episodes_updates_as_steplr() -> None:
    # StepLR(step_size=2) stepped after each episode: episodes 1-2 at lr, 3-4 at lr/2, 5-6 at lr/4
    model = REINFORCE("MlpPolicy", "CartPole-v1", learning_rate=1.0, lr_decay_every=2, lr_decay_factor=0.5, seed=0)
    used: list[float] = []
    train = model.train

    def recording_train() -> None:
        train()
        used.append(model.policy.optimizer.param_groups[0]["lr"])

    model.train = recording_train  # type: ignore[method-assign]
    model.learn(400)
    assert model._completed_episodes >= 6
    assert used[:6] == [1.0, 1.0, 0.5, 0.5, 0.25, 0.25]


def test_sarsa_per_step_decay_counts_the_episodes_before_each_step() -> None:
    # The updates of an episode's last steps (the last n at its end) still use its learning rate; the next episode's
    # first update is decayed
    model = NStepSARSA(
        "MlpPolicy",
        "CartPole-v1",
        learning_rate=1.0,
        n_steps=3,
        train_freq=1,
        gradient_steps=1,
        update_mode="per_step",
        lr_decay_every=1,
        lr_decay_factor=0.5,
        seed=0,
    )
    used: list[tuple[int, float]] = []
    train = model.train

    def recording_train() -> None:
        before = model._episodes_before_rollout
        train()
        used.append((before, model.policy.optimizer.param_groups[0]["lr"]))

    model.train = recording_train  # type: ignore[method-assign]
    model.learn(100)
    assert model._completed_episodes >= 2
    for episodes_before, lr in used:
        assert lr == 0.5**episodes_before
    # The step that ended the first episode trained with the undecayed rate
    first_end = next(index for index, (episodes_before, _) in enumerate(used) if episodes_before == 1) - 1
    assert used[first_end] == (0, 1.0)


def record_learning_rates(optimizer: th.optim.Optimizer) -> list[float]:
    """:return: a list that gets the learning rate of every later ``optimizer.step()``"""
    seen: list[float] = []
    optimizer.register_step_pre_hook(lambda opt, args, kwargs: seen.append(opt.param_groups[0]["lr"]))
    return seen


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_a_callable_learning_rate_never_goes_negative(model_class: type[BaseAlgorithm]) -> None:
    """The last rollout ends past ``total_timesteps``, where ``3e-3 * progress`` is negative."""
    schedule = lambda progress: 3e-3 * progress  # noqa: E731 (a schedule as users write it)
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
