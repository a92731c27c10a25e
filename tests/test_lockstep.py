"""A population of NStepSARSA models trained in lockstep on one stacked q̂: each member as its own separate run."""

from collections.abc import Callable
from pathlib import Path
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import VecEnv

from sb3_classic import NStepSARSA
from sb3_classic.common.stacked import StackedAdam, StackedMLP, clip_grad_norms_per_member
from sb3_classic.sarsa import NStepSARSAPopulation

SETTING: dict[str, Any] = dict(
    policy_kwargs=dict(net_arch=[32, 32]),
    n_steps=4,
    learning_rate=5e-4,
    train_freq=1,
    gradient_steps=1,
    update_mode="per_step",
)


def make_member(seed: int, env: VecEnv | None = None, **kwargs: object) -> NStepSARSA:
    env = make_vec_env("CartPole-v1", n_envs=1, seed=seed) if env is None else env
    return NStepSARSA("MlpPolicy", env, seed=seed, **{**SETTING, **kwargs})


def max_difference(first: NStepSARSA, second: NStepSARSA) -> float:
    pairs = zip(first.policy.q_net.parameters(), second.policy.q_net.parameters(), strict=True)
    return max((a - b).abs().max().item() for a, b in pairs)


def test_member_trains_as_its_separate_run() -> None:
    # The separate run draws from the member's generator, so both see the same transitions of the same env. The
    # stacked layers' batched products may round differently from nn.Linear's in the last bits: close, not equal
    separate = []
    for seed in (0, 1):
        model = make_member(seed)
        model._action_rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(0,)))
        separate.append(model.learn(220))
    members = [make_member(seed) for seed in (0, 1)]
    before = [p.detach().clone() for p in members[1].policy.q_net.parameters()]
    NStepSARSAPopulation(members).learn(220)
    for member, model in zip(members, separate, strict=True):
        assert member._n_updates == model._n_updates >= 200
        assert member._completed_episodes == model._completed_episodes
        assert max_difference(member, model) < 1e-5
        # Its optimizer holds its slice's Adam state, as the separate run's
        state, own = member.policy.optimizer.state, model.policy.optimizer.state
        for p, q in zip(member.policy.q_net.parameters(), model.policy.q_net.parameters(), strict=True):
            assert int(state[p]["step"]) == int(own[q]["step"])
            th.testing.assert_close(state[p]["exp_avg"], own[q]["exp_avg"], atol=1e-5, rtol=1e-4)
    # It learned, and owns its weights again (no view into the stack)
    after = list(members[1].policy.q_net.parameters())
    assert all(not th.equal(a, b) for a, b in zip(before, after, strict=True))
    assert all(p.is_contiguous() and p.untyped_storage().nbytes() == p.numel() * 4 for p in after)


def learning_rate(progress_remaining: float) -> float:
    # One schedule object for every member (a setting they share), as the YAML's lin_2e-3
    return 2e-3 * progress_remaining


BATCH_SETTING: dict[str, Any] = dict(
    policy_kwargs=dict(net_arch=[32, 32], weight_init="default"),
    n_steps=3,
    learning_rate=learning_rate,
    train_freq=4,
    gradient_steps=3,
    update_mode="batch",
    max_grad_norm=1.0,
)
COPIES = dict(td_lambda=0.5, expected_sarsa=True, target_update_interval=1, tau=0.5, averaging_tau=0.05, gamma=0.999)


@pytest.mark.parametrize(
    ("n_envs", "kwargs"),
    [
        (1, BATCH_SETTING),
        (3, {**BATCH_SETTING, **COPIES, "max_grad_norm": None}),
        (2, {**SETTING, **COPIES, "train_freq": 3, "target_update_interval": 5}),
        (1, {**BATCH_SETTING, "policy_kwargs": dict(net_arch=[32, 32], layer_norm=True)}),
    ],
    ids=["batch", "batch-copies-envs", "per-step-copies-train-freq", "batch-layer-norm"],
)
def test_member_trains_as_its_separate_run_in_every_mode(n_envs: int, kwargs: dict[str, Any]) -> None:
    # Members' batches differ in size (their episodes end at other times): each takes the mean loss of its own, and its
    # copies of q̂ move after its own updates only
    def make(seed: int) -> NStepSARSA:
        return NStepSARSA("MlpPolicy", make_vec_env("CartPole-v1", n_envs=n_envs, seed=seed), seed=seed, **kwargs)

    steps = 75 * kwargs["train_freq"] * n_envs // 3
    separate = []
    for seed in (0, 1, 2):
        model = make(seed)
        model._action_rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(0,)))
        separate.append(model.learn(steps))
    members = [make(seed) for seed in (0, 1, 2)]
    NStepSARSAPopulation(members).learn(steps)
    for member, model in zip(members, separate, strict=True):
        assert member._n_updates == model._n_updates
        assert model.rollout_buffer.pos == member.rollout_buffer.pos
        assert member._completed_episodes == model._completed_episodes
        assert member.num_timesteps == model.num_timesteps == steps
        assert max_difference(member, model) < 1e-5
        for name in ("q_net_target", "q_net_average"):
            own, theirs = getattr(member.policy, name), getattr(model.policy, name)
            assert (own is None) == (theirs is None) == ("tau" not in kwargs)
            if own is not None:
                pairs = zip(own.parameters(), theirs.parameters(), strict=True)
                assert max((p - q).abs().max().item() for p, q in pairs) < 1e-5
                assert all(p.is_contiguous() and not p.requires_grad for p in own.parameters())
    updates = members[0]._n_updates // kwargs["gradient_steps"]
    assert updates >= (20 if kwargs["update_mode"] == "batch" else 60)
    # (their episodes ended at other steps: their batches differed in size)
    assert len({model._completed_episodes for model in members}) > 1


class Recorder(BaseCallback):
    """What a callback sees of the rollout loop: its calls, the steps and the locals SB3's callbacks read."""

    def __init__(self) -> None:
        super().__init__()
        self.events: list[tuple[Any, ...]] = []

    def _on_rollout_start(self) -> None:
        self.events.append(("start", self.model.num_timesteps))

    def _on_step(self) -> bool:
        keys = ("n_steps", "actions", "rewards", "dones", "new_obs")
        self.events.append(("step", self.n_calls, self.num_timesteps, *(np.array(self.locals[key]).tolist() for key in keys)))
        self.events.append(("infos", [sorted(info) for info in self.locals["infos"]], self.locals["self"] is self.model))
        return True

    def _on_rollout_end(self) -> None:
        self.events.append(("end", self.model.num_timesteps, self.locals["n_steps"]))


def test_a_member_steps_its_envs_as_its_separate_run() -> None:
    # The population's rollout step has collect_rollouts' effects: callbacks, Monitor, counts, ε
    def make(seed: int) -> NStepSARSA:
        env = make_vec_env("CartPole-v1", n_envs=2, seed=seed)
        return NStepSARSA("MlpPolicy", env, seed=seed, **{**BATCH_SETTING, "train_freq": 3})

    separate, recorders = [], [Recorder() for _ in range(2)]
    for seed, recorder in zip((0, 1), recorders, strict=True):
        model = make(seed)
        model._action_rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(0,)))
        separate.append(model.learn(120, callback=recorder))
    members, own_recorders = [make(seed) for seed in (0, 1)], [Recorder() for _ in range(2)]
    NStepSARSAPopulation(members).learn(120, callback=own_recorders)
    for member, model, own, theirs in zip(members, separate, own_recorders, recorders, strict=True):
        assert own.events == theirs.events
        assert member.ep_info_buffer is not None
        assert model.ep_info_buffer is not None
        assert [(e["r"], e["l"]) for e in member.ep_info_buffer] == [(e["r"], e["l"]) for e in model.ep_info_buffer]
        assert member.exploration_rate == model.exploration_rate
        assert member._episodes_before_rollout == model._episodes_before_rollout
        assert np.array_equal(member._last_obs, model._last_obs)  # type: ignore[arg-type]
        assert np.array_equal(member._last_episode_starts, model._last_episode_starts)  # type: ignore[arg-type]


def test_a_population_repeats_itself_and_saves_ordinary_models(tmp_path: Path) -> None:
    runs = [NStepSARSAPopulation([make_member(seed) for seed in (3, 4)]).learn(60) for _ in range(2)]
    for first, second in zip(*runs, strict=True):
        assert max_difference(first, second) == 0.0
    runs[0][1].save(tmp_path / "member")
    loaded = NStepSARSA.load(tmp_path / "member")
    assert max_difference(loaded, runs[0][1]) == 0.0
    obs = np.asarray(runs[0][1].env.reset())  # type: ignore[union-attr]
    assert np.array_equal(loaded.predict(obs, deterministic=True)[0], runs[0][1].predict(obs, deterministic=True)[0])


def test_members_are_independent() -> None:
    # Member 0 alone and beside members whose episodes end at other times: the same weights
    alone = NStepSARSAPopulation([make_member(0)]).learn(150)[0]
    beside = NStepSARSAPopulation([make_member(0), make_member(7), make_member(8)]).learn(150)
    assert beside[0]._completed_episodes == alone._completed_episodes
    assert (
        beside[1]._completed_episodes != alone._completed_episodes
        or beside[2]._completed_episodes != alone._completed_episodes
    )
    assert max_difference(beside[0], alone) < 1e-6


class NaNRewardAfter(gym.Wrapper):
    def __init__(self, env: gym.Env, steps: int) -> None:
        super().__init__(env)
        self.steps_left = steps

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.steps_left -= 1
        return obs, (float("nan") if self.steps_left <= 0 else reward), terminated, truncated, info


def test_a_non_finite_reward_stops_its_member_only() -> None:
    broken = make_vec_env(
        "CartPole-v1",
        n_envs=1,
        seed=1,
        wrapper_class=NaNRewardAfter,  # type: ignore[arg-type]
        wrapper_kwargs=dict(steps=30),
    )
    members = [make_member(0), make_member(1, broken), make_member(2)]
    with pytest.raises(ValueError, match=r"member 1 \(seed 1\) stopped.*reward"):
        NStepSARSAPopulation(members).learn(80)
    assert members[0].num_timesteps == members[2].num_timesteps == 80
    assert members[1].num_timesteps == 30
    # Every member owns its weights again
    assert all(p.is_contiguous() for member in members for p in member.policy.q_net.parameters())


def about_member(k: int) -> Callable[[str], str]:
    """:return: an ``assert_close`` message naming member k before the report it generates (which has the numbers)"""
    return lambda report: f"member {k}: {report}"


def three_networks_stacked_and_copied() -> tuple[list[th.nn.Sequential], list[th.nn.Sequential], StackedMLP]:
    """:return: three small MLPs (seeded), a copy of each to train alone, and the three stacked"""
    th.manual_seed(0)
    networks = [th.nn.Sequential(th.nn.Linear(3, 5), th.nn.Tanh(), th.nn.Linear(5, 2)) for _ in range(3)]
    copies = [th.nn.Sequential(th.nn.Linear(3, 5), th.nn.Tanh(), th.nn.Linear(5, 2)) for _ in range(3)]
    for network, copy in zip(networks, copies, strict=True):
        copy.load_state_dict(network.state_dict())
    stacked = StackedMLP.from_sequentials(networks)
    return networks, copies, stacked


def test_members_with_nothing_to_train_are_not_stepped() -> None:
    networks, copies, stacked = three_networks_stacked_and_copied()
    optimizer = StackedAdam(list(stacked.parameters()), 3, fused=False, foreach=False)
    references = [th.optim.Adam(copy.parameters(), lr=1e-2, foreach=False) for copy in copies]
    x = th.randn(3, 4, 3)
    learning_rates = np.full(3, 1e-2)
    for step in range(5):
        # (in any order: StackedAdam does not need them ascending)
        members = np.array([2, 0]) if step % 2 else np.array([1, 0, 2])
        optimizer.zero_grad()
        stacked(x)[members].square().sum().backward()
        optimizer.step(members, learning_rates)
        for k in members:
            references[k].zero_grad()
            copies[k](x[k]).square().sum().backward()
            references[k].step()
    assert list(optimizer.steps) == [5, 3, 5]
    stacked.share_with(networks)
    for network, copy in zip(networks, copies, strict=True):
        for p, q in zip(network.parameters(), copy.parameters(), strict=True):
            th.testing.assert_close(p, q, atol=1e-6, rtol=1e-5)
    # A step of member 0 alone leaves member 1's weights and Adam state as they were
    weights = [p.detach()[1].clone() for p in stacked.parameters()]
    moments = [m[1].clone() for m in optimizer.exp_avgs]
    optimizer.zero_grad()
    stacked(x)[0].sum().backward()
    optimizer.step(np.array([0]), learning_rates)
    assert list(optimizer.steps) == [6, 3, 5]
    assert all(th.equal(p.detach()[1], w) for p, w in zip(stacked.parameters(), weights, strict=True))
    assert all(th.equal(m[1], w) for m, w in zip(optimizer.exp_avgs, moments, strict=True))


@pytest.mark.parametrize("fused", [True, False])
def test_stacked_adam_steps_each_member_as_its_own_adam(fused: bool) -> None:
    # Members at other step counts and learning rates, subsets, and whole-stack steps (every member at one count) at
    # t > 1 with a common learning rate that moved: each member's slices take the steps of its own torch.optim.Adam
    networks, copies, stacked = three_networks_stacked_and_copied()
    foreach = None if fused else False
    optimizer = StackedAdam(list(stacked.parameters()), 3, fused=fused, foreach=foreach)
    references = [th.optim.Adam(copy.parameters(), lr=1e-2, fused=fused, foreach=foreach) for copy in copies]
    x = th.randn(3, 4, 3)
    schedule = [[0, 1, 2], [0, 1, 2], [2, 0], [1], [1, 0, 2], [0, 1, 2], [0, 1, 2], [1, 2], [2, 1, 0]]
    whole_stack = 0
    for step, members in enumerate(schedule):
        # Member 1's learning rate parts from the others' at the fourth step; all three move to 3e-3 at the sixth
        learning_rates = np.array([1e-2, 1e-2 if step < 3 else 4e-3, 1e-2]) if step < 5 else np.full(3, 3e-3)
        counts = optimizer.steps[members]
        whole_stack += len(members) == 3 and (counts == counts[0]).all() and (learning_rates == learning_rates[0]).all()
        optimizer.zero_grad()
        stacked(x)[members].square().sum().backward()
        optimizer.step(np.array(members), learning_rates)
        for k in members:
            references[k].param_groups[0]["lr"] = float(learning_rates[k])
            references[k].zero_grad()
            copies[k](x[k]).square().sum().backward()
            references[k].step()
    # (steps 0, 1, 5 and 6 are whole-stack steps, at counts 0, 1, 4 and 5; step 4 has every member at count 3 but two
    # learning rates)
    assert whole_stack == 4
    assert list(optimizer.steps) == [7, 8, 8]
    stacked.share_with(networks)
    for k, (network, copy) in enumerate(zip(networks, copies, strict=True)):
        # Close, not equal: the stacked baddbmm and nn.Linear's addmm sum their products in other orders on some CPUs
        # (gradients 2.4e-7 apart on an AVX-512 Xeon, weights 3e-8 after these 9 steps), and the fused kernel rounds an
        # element by its place in the tensor (a slice is the layer's weight transposed); a learning rate 0.1% off
        # moves them 5e-5
        for p, q in zip(network.parameters(), copy.parameters(), strict=True):
            th.testing.assert_close(p, q, atol=1e-6, rtol=1e-5, msg=about_member(k))
        states = [references[k].state[q] for q in copy.parameters()]
        assert [float(state["step"]) for state in states] == [float(optimizer.steps[k])] * len(states)
        moments = [m[k] if m.dim() == 3 and m.shape[1] == 1 else m[k].T for m in optimizer.exp_avg_sqs]
        for moment, state in zip(moments, states, strict=True):
            expected = state["exp_avg_sq"].reshape(-1)
            th.testing.assert_close(moment.reshape(-1), expected, atol=1e-9, rtol=1e-5, msg=about_member(k))


def test_flushing_denormals_changes_no_normal_value() -> None:
    th.manual_seed(0)
    parameters = [th.randn(3, 4, 5, requires_grad=True), th.randn(3, 1, 5, requires_grad=True)]
    copies = [p.detach().clone().requires_grad_() for p in parameters]
    optimizers = [StackedAdam(ps, 3, flush_denormal=flush) for ps, flush in ((parameters, True), (copies, False))]
    for step in range(20):
        grads = [th.randn_like(p) * (1e-3 if step % 2 else 1.0) for p in parameters]
        for ps, optimizer in zip((parameters, copies), optimizers, strict=True):
            for p, g in zip(ps, grads, strict=True):
                p.grad = g.clone()
            optimizer.step(np.array([0, 2]) if step % 3 else np.arange(3), np.full(3, 1e-2))
    assert all(th.equal(p, q) for p, q in zip(parameters, copies, strict=True))
    # (and off again after a step: torch's default)
    assert (th.tensor(1e-38) * 0.1).item() != 0.0


def test_a_stacked_network_computes_its_members_networks() -> None:
    networks = [th.nn.Sequential(th.nn.Linear(3, 5), th.nn.Tanh(), th.nn.Linear(5, 2, bias=False)) for _ in range(3)]
    stacked = StackedMLP.from_sequentials(networks)
    x = th.randn(3, 4, 3)
    outputs = stacked.inference(x)
    assert not outputs.requires_grad
    assert th.equal(outputs, stacked(x).detach())
    for k, network in enumerate(networks):
        th.testing.assert_close(outputs[k], network(x[k]).detach())


def test_gradients_are_clipped_per_member() -> None:
    grads = [th.randn(3, 4, 5) * th.tensor([0.01, 1.0, 100.0]).view(3, 1, 1), th.randn(3, 1, 5)]
    parameters = [th.zeros_like(grad, requires_grad=True) for grad in grads]
    for parameter, grad in zip(parameters, grads, strict=True):
        parameter.grad = grad.clone()
    clip_grad_norms_per_member(parameters, 1.0)
    for k in range(3):
        own = [th.zeros_like(grad[k], requires_grad=True) for grad in grads]
        for parameter, grad in zip(own, grads, strict=True):
            parameter.grad = grad[k].clone()
        th.nn.utils.clip_grad_norm_(own, 1.0)
        for parameter, expected in zip(parameters, own, strict=True):
            th.testing.assert_close(parameter.grad[k], expected.grad)  # type: ignore[index]


def test_settings_not_covered_are_refused() -> None:
    env = make_vec_env("CartPole-v1", n_envs=1, seed=0)
    model = NStepSARSA("LinearPolicy", env, seed=0, **{**SETTING, "policy_kwargs": None})
    with pytest.raises(TypeError, match="LinearPolicy"):
        NStepSARSAPopulation([model])
    dropout = NStepSARSA("MlpPolicy", make_vec_env("CartPole-v1", n_envs=1, seed=0), seed=0, **SETTING)
    dropout.policy.q_net.q_net.insert(1, th.nn.Dropout(0.1))
    with pytest.raises(TypeError, match="Dropout"):
        NStepSARSAPopulation([dropout])


def test_members_of_different_settings_are_refused() -> None:
    with pytest.raises(ValueError, match=r"member 1's n_steps=5 differs from member 0's \(4\)"):
        NStepSARSAPopulation([make_member(0), make_member(1, n_steps=5)])
    with pytest.raises(ValueError, match="seed=None"):
        NStepSARSAPopulation([NStepSARSA("MlpPolicy", "CartPole-v1", **SETTING)])


def test_a_bad_use_masking_is_refused_before_anything_changes() -> None:
    members = [make_member(seed) for seed in (0, 1)]
    with pytest.raises(TypeError, match="use_masking"):
        NStepSARSAPopulation(members).learn(100, use_masking=None)  # type: ignore[arg-type]
    for member in members:
        assert member.num_timesteps == 0
        assert member._action_rng is None
        # (its own parameters, no view into a stack)
        assert all(p.is_contiguous() and p.untyped_storage().nbytes() == p.numel() * 4 for p in member.policy.parameters())


def test_a_negative_step_count_is_refused_before_anything_changes() -> None:
    members = [make_member(seed) for seed in (0, 1)]
    with pytest.raises(ValueError, match=r"total_timesteps=-5 must be >= 0"):
        NStepSARSAPopulation(members).learn(-5)
    assert all(member.num_timesteps == 0 and member._last_obs is None for member in members)


def test_a_member_is_saved_after_learn_not_during_it(tmp_path: Path) -> None:
    """While the population trains, a member's Adam state is the population's: a save then is refused, not stale."""
    from stable_baselines3.common.callbacks import CheckpointCallback

    members = [make_member(seed) for seed in (0, 1)]
    checkpoints = CheckpointCallback(save_freq=50, save_path=str(tmp_path / "checkpoints"))
    with pytest.raises(RuntimeError, match="after learn"):
        NStepSARSAPopulation(members).learn(100, callback=[checkpoints, None])
    assert not list((tmp_path / "checkpoints").glob("*.zip"))
    # After learn, an ordinary model again: its save and load keep the weights
    members[0].save(tmp_path / "member")
    loaded = NStepSARSA.load(tmp_path / "member")
    assert max_difference(loaded, members[0]) == 0.0
