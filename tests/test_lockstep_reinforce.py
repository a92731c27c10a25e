"""A population of REINFORCE models trained in lockstep on stacked networks: each member as its own separate run."""

from pathlib import Path
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from stable_baselines3.common.callbacks import CheckpointCallback, StopTrainingOnMaxEpisodes
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.envs import FakeImageEnv, IdentityEnv, SimpleMultiObsEnv
from stable_baselines3.common.vec_env import VecEnv

from sb3_classic import REINFORCE
from sb3_classic.reinforce import REINFORCEPopulation
from sb3_classic.reinforce.reinforce import categorical_inverse_cdf

# Learning rates at which a run does not amplify the last bits the stacked products round differently (with
# value_learning_rate 1e-2 a per-step run's v̂ drifts by 1e-4 in 100 updates, a separate run against another ordering
# of the same sums as much)
SETTING: dict[str, Any] = dict(
    policy_kwargs=dict(net_arch=[32, 32]),
    learning_rate=1e-3,
    value_learning_rate=1e-3,
)


def make_member(seed: int, env: VecEnv | None = None, n_envs: int = 1, **kwargs: Any) -> REINFORCE:
    env = make_vec_env("CartPole-v1", n_envs=n_envs, seed=seed) if env is None else env
    return REINFORCE("MlpPolicy", env, seed=seed, **{**SETTING, **kwargs})


def member_rng(seed: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(0,)))


def separate_run(seed: int, steps: int, env: VecEnv | None = None, **kwargs: Any) -> REINFORCE:
    """:return: the member's separate run: the same seed, its actions drawn from the member's generator"""
    model = make_member(seed, env, **kwargs)
    model._action_rng = member_rng(seed)
    return model.learn(steps)


def max_difference(first: REINFORCE, second: REINFORCE) -> float:
    pairs = zip(first.policy.parameters(), second.policy.parameters(), strict=True)
    return max((a - b).abs().max().item() for a, b in pairs)


def assert_same_adam_states(member: REINFORCE, model: REINFORCE) -> None:
    optimizers = [(member.policy.optimizer, model.policy.optimizer)]
    if member.use_baseline:
        optimizers.append((member.policy.value_optimizer, model.policy.value_optimizer))  # type: ignore[arg-type]
    for mine, own in optimizers:
        for p, q in zip(mine.param_groups[0]["params"], own.param_groups[0]["params"], strict=True):
            assert int(mine.state[p]["step"]) == int(own.state[q]["step"])
            th.testing.assert_close(mine.state[p]["exp_avg"], own.state[q]["exp_avg"], atol=1e-5, rtol=1e-4)
            th.testing.assert_close(mine.state[p]["exp_avg_sq"], own.state[q]["exp_avg_sq"], atol=1e-6, rtol=1e-4)


@pytest.mark.parametrize(
    ("steps", "kwargs", "min_updates"),
    [
        (220, dict(update_mode="per_step"), 200),
        (220, dict(update_mode="per_step", use_baseline=False, gamma_t_factor=True, max_grad_norm=0.5), 200),
        (600, dict(update_mode="batch"), 20),
        (
            700,
            dict(update_mode="batch", normalize_advantage=True, max_grad_norm=0.5, ent_coef=0.01, n_episodes=2, n_envs=2),
            10,
        ),
    ],
    ids=["per-step", "per-step-no-baseline", "batch", "batch-options-2-envs"],
)
def test_member_trains_as_its_separate_run(steps: int, kwargs: dict[str, Any], min_updates: int) -> None:
    # The separate run draws from the member's generator, so both see the same transitions of the same env. The
    # stacked layers' batched products may round differently from nn.Linear's in the last bits: close, not equal
    separate = [separate_run(seed, steps, **kwargs) for seed in (0, 1)]
    members = [make_member(seed, **kwargs) for seed in (0, 1)]
    before = [p.detach().clone() for p in members[1].policy.parameters()]
    REINFORCEPopulation(members).learn(steps)
    for member, model in zip(members, separate, strict=True):
        assert member._n_updates == model._n_updates >= min_updates
        assert member._completed_episodes == model._completed_episodes
        assert member.num_timesteps == model.num_timesteps
        assert max_difference(member, model) < 1e-5
        # Its optimizers hold its slices' Adam states, as the separate run's
        assert_same_adam_states(member, model)
    # It learned, and owns its weights again (no view into the stack)
    after = list(members[1].policy.parameters())
    assert all(not th.equal(a, b) for a, b in zip(before, after, strict=True))
    assert all(p.is_contiguous() and p.untyped_storage().nbytes() == p.numel() * 4 for p in after)


def test_the_report_acrobot_model_with_one_step_per_episode_trains_as_its_separate_run() -> None:
    # The setting of Figs 20-22's 1×256 runs read with one Adam step per episode: Leaky ReLU, γ^t, a value lr of 0.1
    # (which amplifies the last bits most), and Acrobot-v1's 500-step episodes cut by its time limit (v̂ bootstrapped)
    kwargs: dict[str, Any] = dict(
        update_mode="batch",
        gamma_t_factor=True,
        learning_rate=1e-3,
        value_learning_rate=1e-1,
        policy_kwargs=dict(
            net_arch=[256], activation_fn=th.nn.LeakyReLU, activation_kwargs=dict(negative_slope=0.1), weight_init="default"
        ),
    )
    steps = 2000
    separate = separate_run(1, steps, make_vec_env("Acrobot-v1", n_envs=1, seed=1), **kwargs)
    members = [make_member(seed, make_vec_env("Acrobot-v1", n_envs=1, seed=seed), **kwargs) for seed in (0, 1)]
    REINFORCEPopulation(members).learn(steps)
    assert members[1]._n_updates == separate._n_updates >= 4  # (episodes of at most 500 steps)
    assert members[1]._completed_episodes == separate._completed_episodes
    assert max_difference(members[1], separate) < 1e-5
    assert_same_adam_states(members[1], separate)


def test_learning_rate_decays_are_each_members_own() -> None:
    # Episode-counted decays part the members' rates (they end episodes at different times): each gets its own
    kwargs: dict[str, Any] = dict(update_mode="batch", lr_decay_every=3, lr_decay_factor=0.5)
    separate = [separate_run(seed, 400, **kwargs) for seed in (0, 1)]
    members = REINFORCEPopulation([make_member(seed, **kwargs) for seed in (0, 1)]).learn(400)
    for member, model in zip(members, separate, strict=True):
        assert member.policy.optimizer.param_groups[0]["lr"] == model.policy.optimizer.param_groups[0]["lr"] < 1e-3
        assert max_difference(member, model) < 1e-5


def test_a_population_repeats_itself_and_saves_ordinary_models(tmp_path: Path) -> None:
    runs = [REINFORCEPopulation([make_member(seed, update_mode="per_step") for seed in (3, 4)]).learn(100) for _ in range(2)]
    for first, second in zip(*runs, strict=True):
        assert max_difference(first, second) == 0.0
    runs[0][1].save(tmp_path / "member")
    loaded = REINFORCE.load(tmp_path / "member")
    assert max_difference(loaded, runs[0][1]) == 0.0
    obs = np.asarray(runs[0][1].env.reset())  # type: ignore[union-attr]
    assert np.array_equal(loaded.predict(obs, deterministic=True)[0], runs[0][1].predict(obs, deterministic=True)[0])
    # A member learns on its own afterwards, from its own Adam state
    runs[0][0].learn(50, reset_num_timesteps=False)
    assert runs[0][0]._action_rng is None


def test_members_are_independent() -> None:
    # Member 0 alone and beside members whose episodes end at other times: the same weights, its own episodes
    alone = REINFORCEPopulation([make_member(0, update_mode="per_step")]).learn(150)[0]
    beside = REINFORCEPopulation([make_member(seed, update_mode="per_step") for seed in (0, 7, 8)]).learn(150)
    assert beside[0]._completed_episodes == alone._completed_episodes
    assert beside[0]._n_updates == alone._n_updates
    assert (beside[1]._n_updates, beside[2]._n_updates) != (alone._n_updates, alone._n_updates)
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
        wrapper_kwargs=dict(steps=60),
    )
    members = [make_member(k, broken if k == 1 else None, update_mode="per_step") for k in range(3)]
    with pytest.raises(ValueError, match=r"member 1 \(seed 1\) stopped.*reward"):
        REINFORCEPopulation(members).learn(150)
    assert members[1].num_timesteps == 60
    assert members[1]._n_updates > 0
    for k in (0, 2):
        model = separate_run(k, 150, update_mode="per_step")
        assert members[k].num_timesteps == model.num_timesteps >= 150
        assert max_difference(members[k], model) < 1e-5
    # Every member owns its weights again
    assert all(p.is_contiguous() for member in members for p in member.policy.parameters())


def test_a_member_is_saved_after_learn_not_during_it(tmp_path: Path) -> None:
    """While the population trains, a member's Adam states are the population's: a save then is refused, not stale."""
    members = [make_member(seed) for seed in (0, 1)]
    checkpoints = CheckpointCallback(save_freq=50, save_path=str(tmp_path / "checkpoints"))
    with pytest.raises(RuntimeError, match="after learn"):
        REINFORCEPopulation(members).learn(100, callback=[checkpoints, None])
    assert not list((tmp_path / "checkpoints").glob("*.zip"))
    members[0].save(tmp_path / "member")
    loaded = REINFORCE.load(tmp_path / "member")
    assert max_difference(loaded, members[0]) == 0.0


def test_the_inverse_cdf_draws_the_softmax_probabilities() -> None:
    # π = soft-max(0, ln 3) = (1/4, 3/4), and one uniform draw per row: u < 1/4 gives action 0
    logits = np.tile([0.0, np.log(3.0)], (10_000, 1))
    actions = categorical_inverse_cdf(logits, np.random.default_rng(0))
    u = np.random.default_rng(0).random(10_000)
    assert np.array_equal(actions, (u >= 0.25).astype(np.int64))
    assert abs(actions.mean() - 0.75) < 0.02


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: [make_member(0), make_member(1, n_episodes=2)], r"member 1's n_episodes=2 differs from member 0's \(1\)"),
        (lambda: [make_member(0), make_member(1, update_mode="per_step")], "member 1's update_mode='per_step' differs"),
        (lambda: [REINFORCE("MlpPolicy", "CartPole-v1", **SETTING)], "seed=None"),
        (lambda: [REINFORCE("MlpPolicy", "Pendulum-v1", seed=0)], r"Box.*Discrete actions"),
        (lambda: [REINFORCE("MlpPolicy", IdentityEnv(4), seed=0)], r"observation_space=Discrete\(4\).*one-hot"),
        (lambda: [REINFORCE("CnnPolicy", FakeImageEnv(discrete=True), seed=0)], "NatureCNN"),
        (lambda: [REINFORCE("MultiInputPolicy", SimpleMultiObsEnv(), seed=0)], "CombinedExtractor"),
        (
            lambda: [make_member(0, policy_kwargs=dict(net_arch=[32], optimizer_class=th.optim.SGD))],
            # (the optimizer alone: an SGD has no AMSGrad to report)
            "optimizer SGD: a population's optimizers are Adam",
        ),
        (
            lambda: [make_member(0, policy_kwargs=dict(net_arch=[32], optimizer_kwargs=dict(weight_decay=1e-4)))],
            "weight_decay=0.0001",
        ),
        (lambda: [make_member(0, policy_kwargs=dict(net_arch=[32], activation_fn=th.nn.PReLU))], "PReLU"),
    ],
    ids=["n-episodes", "update-mode", "no-seed", "box", "discrete-obs", "cnn", "dict", "sgd", "weight-decay", "prelu"],
)
def test_settings_not_covered_are_refused(make: Any, message: str) -> None:
    with pytest.raises((ValueError, TypeError), match=message):
        REINFORCEPopulation(make())


def test_a_model_once_and_a_callback_per_member() -> None:
    model = make_member(0)
    with pytest.raises(ValueError, match="more than once"):
        REINFORCEPopulation([model, model])
    with pytest.raises(ValueError, match="1 callbacks for 2 members"):
        REINFORCEPopulation([make_member(0), make_member(1)]).learn(10, callback=[None])


@pytest.mark.parametrize("update_mode", ["batch", "per_step"])
def test_a_second_learn_goes_on_as_the_separate_run_does(update_mode: str) -> None:
    # The members' Adam states and generators carry over from one learn() call to the next
    separate = []
    for seed in (0, 1):
        model = make_member(seed, update_mode=update_mode)
        model._action_rng = member_rng(seed)
        model.learn(150)
        separate.append(model.learn(150, reset_num_timesteps=False))
    members = [make_member(seed, update_mode=update_mode) for seed in (0, 1)]
    population = REINFORCEPopulation(members)
    population.learn(150)
    population.learn(150, reset_num_timesteps=False)
    for member, model in zip(members, separate, strict=True):
        assert member.num_timesteps == model.num_timesteps > 300
        assert member._n_updates == model._n_updates
        assert max_difference(member, model) < 1e-5
        assert_same_adam_states(member, model)


def test_a_callback_stops_its_member_only() -> None:
    separate = make_member(0)
    separate._action_rng = member_rng(0)
    separate.learn(1000, callback=StopTrainingOnMaxEpisodes(5))
    members = [make_member(0), make_member(1)]
    REINFORCEPopulation(members).learn(1000, callback=[StopTrainingOnMaxEpisodes(5), None])
    assert members[0].num_timesteps == separate.num_timesteps < 1000 <= members[1].num_timesteps
    assert members[0]._n_updates == separate._n_updates
    assert max_difference(members[0], separate) < 1e-5
