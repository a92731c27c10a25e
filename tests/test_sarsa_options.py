"""
NStepSARSA's options for neural networks that are not in the book: a bootstrap (target) network, a weight-averaged
greedy policy and LayerNorm.
"""

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch as th
from gymnasium import spaces
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn

from sb3_classic import NStepSARSA
from sb3_classic.common.returns import nstep_targets


def make(n_envs: Any = 2, **kwargs: Any) -> NStepSARSA:
    env = make_vec_env("CartPole-v1", n_envs=n_envs, seed=0)
    settings: dict[str, Any] = dict(policy_kwargs=dict(net_arch=[16]), n_steps=3, train_freq=8, seed=0, device="cpu")
    settings |= kwargs
    return NStepSARSA("MlpPolicy", env, **settings)


def flat(module: nn.Module) -> th.Tensor:
    return th.cat([p.detach().flatten() for p in module.parameters()])


def assert_frozen_copy_of_q(model: NStepSARSA, copy: nn.Module | None) -> None:
    """``copy`` is q̂ as built (same weights), without gradients and outside the optimizer."""
    assert copy is not None
    assert th.equal(flat(copy), flat(model.policy.q_net))
    assert not any(p.requires_grad for p in copy.parameters())
    trained = {id(p) for group in model.policy.optimizer.param_groups for p in group["params"]}
    assert not trained & {id(p) for p in copy.parameters()}


def test_no_target_network_by_default() -> None:
    model = make()
    assert model.policy.q_net_target is None
    assert model.policy.bootstrap_net is model.policy.q_net


def test_target_network_is_a_frozen_copy_outside_the_optimizer() -> None:
    model = make(target_update_interval=1000)
    assert_frozen_copy_of_q(model, model.policy.q_net_target)


def test_targets_bootstrap_from_the_target_network() -> None:
    model = make(target_update_interval=10**9)
    target = model.policy.q_net_target
    assert target is not None
    with th.no_grad():
        for p in target.parameters():
            p.zero_()  # q̂⁻ ≡ 0: every bootstrap term vanishes
    model.learn(16)  # one rollout of 8 steps per env, no target update (the interval is never reached)
    model.collect_rollouts(model.env, model._init_callback(None), model.rollout_buffer)  # type: ignore[arg-type]
    batch = model._training_batch()
    assert batch is not None
    data = model.rollout_buffer.get()
    expected, _ = nstep_targets(data.rewards, data.dones, np.zeros_like(data.rewards), model.gamma, model.n_steps)
    # The batch: each env's first n_trained pending transitions, in time order
    trained = data.pending & (np.cumsum(data.pending, axis=0) <= batch.n_trained)
    np.testing.assert_allclose(batch.targets, expected[trained], rtol=1e-6)
    # ... which the online network would not give
    assert th.equal(flat(target), th.zeros_like(flat(target)))
    assert flat(model.policy.q_net).abs().sum() > 0


@pytest.mark.parametrize("tau", [1.0, 0.5])
def test_target_network_moves_towards_q_every_interval(tau: float) -> None:
    model = make(target_update_interval=32, tau=tau)
    target = model.policy.q_net_target
    assert target is not None
    updates: list[tuple[int, th.Tensor, th.Tensor]] = []
    train = model.train

    def recorded_train() -> None:
        before = flat(target)
        train()
        updates.append((model.num_timesteps, before, flat(target)))

    model.train = recorded_train  # type: ignore[method-assign]
    model.learn(160)
    moved = [(steps, before, after) for steps, before, after in updates if not th.equal(before, after)]
    # 16 env steps per update (8 per env, 2 envs): the target moves every second update
    assert [steps for steps, _, _ in moved] == [32, 64, 96, 128, 160]
    _, before, after = moved[-1]
    # w⁻ ← τ w + (1 − τ) w⁻, with w the weights after the update
    np.testing.assert_allclose(
        after.numpy(), (tau * flat(model.policy.q_net) + (1 - tau) * before).numpy(), rtol=1e-5, atol=1e-7
    )


def test_target_network_is_saved_and_loaded(tmp_path: Path) -> None:
    model = make(target_update_interval=64, tau=0.1).learn(300)
    model.save(tmp_path / "model")
    loaded = NStepSARSA.load(tmp_path / "model", device="cpu")
    assert loaded.policy.q_net_target is not None
    assert model.policy.q_net_target is not None
    assert th.equal(flat(loaded.policy.q_net_target), flat(model.policy.q_net_target))
    assert loaded.target_update_interval == 64
    assert loaded._target_updated_at == model._target_updated_at


@pytest.mark.parametrize(("name", "value"), [("target_update_interval", 0), ("tau", 0.0), ("tau", 1.5)])
def test_bad_target_arguments(name: str, value: float) -> None:
    with pytest.raises(ValueError, match=name):
        make(**{name: value})


@pytest.mark.parametrize("update_mode", ["batch", "per_step"])
def test_the_average_follows_q_after_every_update_and_leaves_training_alone(update_mode: str) -> None:
    """w̄ ← τw + (1 − τ)w̄ after each update (both modes, the per-step loop's own update included), from q̂'s initial
    weights; the online weights and the ε-greedy actions are those of a run without the average, bit for bit."""
    # The book's loop: one env and train_freq=1
    tau = 0.2
    settings: dict[str, Any] = dict(update_mode=update_mode)
    if update_mode == "per_step":
        settings.update(n_envs=1, train_freq=1, gradient_steps=1)
    model = make(averaging_tau=tau, **settings)
    average = model.policy.q_net_average
    assert_frozen_copy_of_q(model, average)
    assert average is not None
    expected = flat(model.policy.q_net)
    n_updates = [0]
    move_copies = model._move_copies

    def recorded() -> None:
        nonlocal expected
        move_copies()
        expected = tau * flat(model.policy.q_net) + (1 - tau) * expected
        n_updates[0] += 1

    model._move_copies = recorded  # type: ignore[method-assign]
    model.learn(200)
    # batch: an update every 16 env steps (8 per env, 2 envs); per step: one after almost every env step
    assert n_updates[0] >= (10 if update_mode == "batch" else 150)
    np.testing.assert_allclose(flat(average).numpy(), expected.numpy(), rtol=1e-5, atol=1e-6)
    assert not th.equal(flat(average), flat(model.policy.q_net))
    plain = make(**settings).learn(200)
    assert th.equal(flat(plain.policy.q_net), flat(model.policy.q_net))


def test_predict_is_greedy_in_the_average(tmp_path: Path) -> None:
    """``predict(deterministic=True)`` (every evaluation) takes argmax of the average, and the average is saved."""
    model = make(averaging_tau=0.05).learn(100)
    average = model.policy.q_net_average
    assert average is not None
    obs = np.random.default_rng(0).normal(size=(64, 4)).astype(np.float32)
    with th.no_grad():
        # Make the two networks disagree: the average prefers action 1 everywhere, q̂ action 0
        average.q_net[-1].bias.copy_(th.tensor([-1e3, 1e3]))  # type: ignore[operator]
        model.policy.q_net.q_net[-1].bias.copy_(th.tensor([1e3, -1e3]))  # type: ignore[operator]
    np.testing.assert_array_equal(model.predict(obs, deterministic=True)[0], np.ones(64))
    # What an export wraps (README: SB3's recipes trace model.policy): the same greedy actions
    np.testing.assert_array_equal(model.policy(th.as_tensor(obs)).numpy(), np.ones(64))
    model.exploration_rate = 0.0
    with th.no_grad():  # as in the rollout loop
        np.testing.assert_array_equal(model._sample_actions(obs), np.zeros(64), "the behaviour policy is q̂'s")
    model.save(tmp_path / "model")
    loaded = NStepSARSA.load(tmp_path / "model", device="cpu")
    assert loaded.policy.q_net_average is not None
    assert th.equal(flat(loaded.policy.q_net_average), flat(average))
    np.testing.assert_array_equal(loaded.predict(obs, deterministic=True)[0], np.ones(64))


def test_no_average_by_default() -> None:
    model = make()
    assert model.policy.q_net_average is None
    assert model.policy.greedy_net is model.policy.q_net


@pytest.mark.parametrize("value", [0.0, 1.5, -0.1])
def test_bad_averaging_tau(value: float) -> None:
    with pytest.raises(ValueError, match="averaging_tau"):
        make(averaging_tau=value)


@pytest.mark.parametrize("with_bias", [True, False])
def test_layer_norm_after_every_hidden_layer(with_bias: bool) -> None:
    model = NStepSARSA(
        "MlpPolicy", "CartPole-v1", policy_kwargs=dict(net_arch=[32, 16], layer_norm=True, with_bias=with_bias), device="cpu"
    )
    layers = list(model.policy.q_net.q_net)
    kinds = [type(layer) for layer in layers]
    assert kinds == [nn.Linear, nn.LayerNorm, nn.ReLU, nn.Linear, nn.LayerNorm, nn.ReLU, nn.Linear]
    assert [layer.normalized_shape for layer in layers if isinstance(layer, nn.LayerNorm)] == [(32,), (16,)]
    assert all((layer.bias is not None) == with_bias for layer in layers if isinstance(layer, nn.Linear))
    model.learn(200)


def test_a_second_learn_keeps_copying_the_bootstrap_network() -> None:
    model = NStepSARSA("MlpPolicy", "CartPole-v1", target_update_interval=32, gradient_steps=1, seed=0)
    model.learn(400)
    first_copy = model._target_updated_at
    assert first_copy > 300
    # learn() resets num_timesteps (its default): the copies count from there, not from the first run's last copy
    model.learn(300)
    assert 0 < model._target_updated_at <= model.num_timesteps
    assert model.num_timesteps - model._target_updated_at < 32 + model.train_freq


def test_a_linear_epsilon_restarts_with_each_learn_from_its_first_step() -> None:
    model = NStepSARSA(
        "MlpPolicy", "CartPole-v1", exploration_schedule="linear", exploration_fraction=0.5, train_freq=16, seed=0
    )
    model.learn(400)
    assert model.exploration_rate == pytest.approx(model.exploration_final_eps)
    seen: list[float] = []

    class FirstSteps(BaseCallback):
        def _on_step(self) -> bool:
            seen.append(self.model.exploration_rate)  # type: ignore[attr-defined]
            return True

    model.learn(400, callback=FirstSteps())
    # The whole first rollout (16 steps) of the second call explores as the first call started, as SB3's DQN
    assert seen[:16] == [model.exploration_initial_eps] * 16


class BatchNormExtractor(BaseFeaturesExtractor):
    """A features extractor with running statistics (BatchNorm), which are buffers, not parameters."""

    def __init__(self, observation_space: spaces.Box) -> None:
        super().__init__(observation_space, features_dim=8)
        self.net = nn.Sequential(nn.Linear(4, 8), nn.BatchNorm1d(8), nn.ReLU())

    def forward(self, observations: th.Tensor) -> th.Tensor:
        return self.net(observations)


def test_the_bootstrap_copy_and_the_average_take_the_running_statistics() -> None:
    # They stayed at their initial 0 and 1 (the copies moved only the parameters), so that with τ = 1 the average,
    # which every evaluation uses, normalised otherwise than q̂; SB3's DQN copies them to its target network
    model = NStepSARSA(
        "MlpPolicy",
        "CartPole-v1",
        target_update_interval=1,
        averaging_tau=1.0,
        policy_kwargs=dict(features_extractor_class=BatchNormExtractor),
        seed=0,
        device="cpu",
    )
    model.learn(500)
    statistics = {name: value for name, value in model.policy.q_net.state_dict().items() if "running_" in name}
    assert statistics
    assert all(value.abs().sum() > 0 for name, value in statistics.items() if "mean" in name)
    for copy in (model.policy.q_net_target, model.policy.q_net_average):
        assert copy is not None
        copied = copy.state_dict()
        for name, value in statistics.items():
            th.testing.assert_close(copied[name], value, rtol=0, atol=0)
    obs = th.as_tensor(np.stack([model.observation_space.sample() for _ in range(5)]))
    model.policy.set_training_mode(False)
    average = model.policy.q_net_average
    assert average is not None
    with th.no_grad():
        th.testing.assert_close(average(obs), model.policy.q_net(obs))


@pytest.mark.parametrize("n_envs", [1, 3])
@pytest.mark.parametrize("own_generator", [False, True])
def test_epsilon_greedy_draws_as_the_book(n_envs: int, own_generator: bool) -> None:
    # S&B §2.2: with probability ε an action drawn uniformly, else the greedy one; every env's coin first, then the
    # uniform actions, from the model's generator (a population member's) or NumPy's global one (a model alone). One
    # env (the book's loop) takes a path of its own, which must draw the same numbers
    model = NStepSARSA("MlpPolicy", make_vec_env("Acrobot-v1", n_envs=n_envs), seed=0)
    model.exploration_rate = 0.4
    reference: Any  # (a Generator, or the RandomState of NumPy's global functions)
    if own_generator:
        model._action_rng, reference = np.random.default_rng(5), np.random.default_rng(5)
    else:
        np.random.seed(5)
        reference = np.random.RandomState(5)
    greedy = np.array([2, 0, 1][:n_envs], dtype=np.int64)
    for _ in range(300):
        actions = model._epsilon_greedy(greedy)
        explore = reference.random(n_envs) < 0.4
        expected = greedy
        if explore.any():  # (no uniform draws where no env explores)
            uniform = reference.integers(0, 3, n_envs) if own_generator else reference.randint(0, 3, n_envs)
            expected = np.where(explore, uniform, greedy)
        # Exact: integer actions from one seeded stream (NumPy's generators give the same numbers on every CPU)
        np.testing.assert_array_equal(actions, expected)
        assert actions.dtype == np.int64
        assert actions.shape == (n_envs,)
    # The same draws: the generators end in the same state
    next_draw = model._action_rng.random() if model._action_rng is not None else np.random.random()
    assert next_draw == reference.random()
