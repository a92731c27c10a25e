"""Learning-rate decays and ε schedules: as pure functions, inside training, and across learn() calls and save/load."""

from pathlib import Path

import pytest
from stable_baselines3.common.utils import LinearSchedule

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


def optimizer_lrs(model: REINFORCE | NStepSARSA) -> list[float]:
    optimizers = [model.policy.optimizer, getattr(model.policy, "value_optimizer", None)]
    return [optimizer.param_groups[0]["lr"] for optimizer in optimizers if optimizer is not None]


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
