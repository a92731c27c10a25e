"""The Stable-Baselines3 contract, for every algorithm of the package (as sb3-contrib's test_run/test_save_load)."""

import glob
import inspect
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback, CheckpointCallback, EvalCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.envs import (
    FakeImageEnv,
    IdentityEnv,
    IdentityEnvBox,
    IdentityEnvMultiBinary,
    IdentityEnvMultiDiscrete,
    SimpleMultiObsEnv,
)
from stable_baselines3.common.logger import configure
from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecNormalize
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from sb3_classic import REINFORCE, NStepSARSA

MODEL_LIST = [REINFORCE, NStepSARSA]
# Small networks and short rollouts: these tests check behaviour, not learning
SMALL: dict[type[BaseAlgorithm], dict[str, Any]] = {
    REINFORCE: dict(policy_kwargs=dict(net_arch=[16])),
    NStepSARSA: dict(policy_kwargs=dict(net_arch=[16]), n_steps=3, train_freq=8),
}


def make_model(model_class: type[BaseAlgorithm], env: Any = "CartPole-v1", **kwargs: Any) -> Any:
    return model_class("MlpPolicy", env, device="cpu", **{**SMALL[model_class], **kwargs})


def parameters_equal(a: dict[str, Any], b: dict[str, Any]) -> bool:
    """Whether two nested state dicts (networks and optimizers) hold the same values."""
    if isinstance(a, th.Tensor):
        return isinstance(b, th.Tensor) and th.equal(a, b)
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(parameters_equal(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(parameters_equal(x, y) for x, y in zip(a, b, strict=True))
    return a == b


def observations(env_id: str = "CartPole-v1", n: int = 20) -> np.ndarray:
    space = gym.make(env_id).observation_space
    space.seed(0)
    return np.array([space.sample() for _ in range(n)])


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_learn_and_predict(model_class: type[BaseAlgorithm]) -> None:
    model = make_model(model_class, seed=0).learn(300)
    assert isinstance(model, OnPolicyAlgorithm)
    assert model.num_timesteps >= 300
    # train() with nothing left to train (SB3's public method, called by a user) changes nothing
    before = [p.detach().clone() for p in model.policy.parameters()]
    model.train()
    assert all(th.equal(a, b) for a, b in zip(before, model.policy.parameters(), strict=True))
    obs = observations()
    for deterministic in (True, False):
        actions, state = model.predict(obs, deterministic=deterministic)
        assert actions.shape == (len(obs),)
        assert state is None
        assert all(model.action_space.contains(action) for action in actions)
        action, _ = model.predict(obs[0], deterministic=deterministic)
        assert action.shape == ()
        assert model.action_space.contains(int(action))
    # Deterministic predictions are repeatable
    np.testing.assert_array_equal(model.predict(obs, deterministic=True)[0], model.predict(obs, deterministic=True)[0])


def test_sarsa_predict_is_greedy_or_epsilon_greedy() -> None:
    model = make_model(NStepSARSA, seed=0)
    obs = observations(n=500)
    with th.no_grad():
        greedy = model.policy.q_net(th.as_tensor(obs)).argmax(dim=1).numpy()
    np.testing.assert_array_equal(model.predict(obs, deterministic=True)[0], greedy)
    model.exploration_rate = 0.5
    differs = (model.predict(obs, deterministic=False)[0] != greedy).mean()
    # A random action differs from the greedy one half the time: ε/2 = 0.25 of the observations
    assert 0.15 < differs < 0.35
    model.exploration_rate = 0.0
    np.testing.assert_array_equal(model.predict(obs, deterministic=False)[0], greedy)


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_save_load_restores_everything_and_training_continues_exactly(model_class: type[Any], tmp_path: Path) -> None:
    kwargs = dict(lr_decay_every=2, lr_decay_factor=0.5, seed=3)
    model = make_model(model_class, **kwargs).learn(700)
    model.save(tmp_path / "model.zip")
    loaded = model_class.load(tmp_path / "model.zip", device="cpu")

    # Networks, every optimizer (with its moments and decayed learning rate) and the training state
    saved_names = set(model.get_parameters())
    assert saved_names == set(model._get_torch_save_params()[0]) == set(loaded.get_parameters())
    assert parameters_equal(model.get_parameters(), loaded.get_parameters())
    for attribute in ("num_timesteps", "_n_updates", "_completed_episodes", "exploration_rate", "learning_rate"):
        assert getattr(loaded, attribute, None) == getattr(model, attribute, None)
    obs = observations()
    np.testing.assert_array_equal(model.predict(obs, deterministic=True)[0], loaded.predict(obs, deterministic=True)[0])

    # Both continue on the same fresh envs with the same random state: they must stay identical
    model.set_env(make_vec_env("CartPole-v1", n_envs=1, seed=7))
    loaded.set_env(make_vec_env("CartPole-v1", n_envs=1, seed=7))
    for continuing in (model, loaded):
        continuing.set_random_seed(11)
        continuing.learn(600, reset_num_timesteps=False)
    assert parameters_equal(model.get_parameters(), loaded.get_parameters())
    assert loaded._completed_episodes == model._completed_episodes > 0


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_load_takes_what_sb3_and_the_zoo_pass(model_class: type[Any], tmp_path: Path) -> None:
    make_model(model_class, seed=0).learn(300).save(tmp_path / "model.zip")
    # rl-zoo3's enjoy and record_video load with a zero learning rate
    frozen = model_class.load(tmp_path / "model.zip", custom_objects={"learning_rate": 0.0, "lr_schedule": 0.0})
    assert frozen.predict(observations(), deterministic=True)[0].shape == (20,)
    # rl-zoo3's -i passes hyperparameters again, None included
    loaded = model_class.load(tmp_path / "model.zip", env=make_vec_env("CartPole-v1"), max_grad_norm=None)
    loaded.learn(300)
    assert loaded._n_updates > frozen._n_updates


@pytest.mark.parametrize(
    ("model_class", "changes", "message"),
    [
        # Each was accepted by load() (rl-zoo3's -i -params ...): trained silently, or failed deep inside
        (NStepSARSA, dict(gamma=1.5), r"gamma=1.5"),
        (NStepSARSA, dict(n_steps=0), r"n_steps=0"),
        (NStepSARSA, dict(train_freq="x"), r"train_freq='x'"),
        (NStepSARSA, dict(exploration_schedule="cosine"), r"exploration_schedule='cosine'"),
        (NStepSARSA, dict(expected_sarsa="yes"), r"expected_sarsa='yes'"),
        (REINFORCE, dict(update_mode="xx"), r"update_mode='xx'"),
        (REINFORCE, dict(n_episodes=0), r"n_episodes=0"),
        (REINFORCE, dict(lr_decay_every=0), r"lr_decay_every=0"),
        (REINFORCE, dict(lr_decay_every=5, lr_decay_milestones=[10]), r"lr_decay_every or lr_decay_milestones"),
    ],
)
def test_load_checks_what_it_changes_as_the_constructor_does(
    model_class: type[Any], changes: dict[str, Any], message: str, tmp_path: Path
) -> None:
    make_model(model_class, seed=0).learn(200).save(tmp_path / "model.zip")
    with pytest.raises((ValueError, TypeError), match=message):
        model_class.load(tmp_path / "model.zip", env=make_vec_env("CartPole-v1"), **changes)
    with pytest.raises((ValueError, TypeError), match=message):
        model_class("MlpPolicy", "CartPole-v1", **changes)


@pytest.mark.parametrize(
    ("model_class", "trained_with", "loaded_with"),
    [
        (NStepSARSA, dict(averaging_tau=None), dict(averaging_tau=0.05)),
        (NStepSARSA, dict(averaging_tau=0.05), dict(averaging_tau=None)),
        (NStepSARSA, dict(), dict(target_update_interval=1)),
        (REINFORCE, dict(use_baseline=False), dict(use_baseline=True)),
        (REINFORCE, dict(), dict(use_baseline=False)),
    ],
)
def test_load_names_an_argument_that_changes_the_networks(
    model_class: type[Any], trained_with: dict[str, Any], loaded_with: dict[str, Any], tmp_path: Path
) -> None:
    # It failed in torch's load_state_dict ("Missing key(s) in state_dict: q_net_average..."), for a YAML entry's value
    make_model(model_class, seed=0, **trained_with).learn(200).save(tmp_path / "model.zip")
    ((key, value),) = loaded_with.items()
    saved = trained_with.get(key, inspect.signature(model_class.__init__).parameters[key].default)
    expected = f"{key}={value!r} builds other networks than those of the saved model, trained with {key}={saved!r}"
    with pytest.raises(ValueError, match=re.escape(expected)) as error:
        model_class.load(tmp_path / "model.zip", **loaded_with)
    assert f"-params {key}:{saved!r}" in str(error.value)
    # The saved value continues it; so does a value that builds the same networks (another τ)
    model_class.load(tmp_path / "model.zip", **{key: saved})
    if key == "averaging_tau" and saved is not None:
        model_class.load(tmp_path / "model.zip", averaging_tau=0.2)


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_get_and_set_parameters(model_class: type[BaseAlgorithm]) -> None:
    trained = make_model(model_class, seed=0).learn(500)
    fresh = make_model(model_class, seed=1)
    obs = observations()
    assert not parameters_equal(trained.get_parameters(), fresh.get_parameters())
    fresh.set_parameters(trained.get_parameters())
    assert parameters_equal(trained.get_parameters(), fresh.get_parameters())
    np.testing.assert_array_equal(trained.predict(obs, deterministic=True)[0], fresh.predict(obs, deterministic=True)[0])
    # An incomplete dict is refused, naming what is missing
    partial = {"policy": trained.get_parameters()["policy"]}
    with pytest.raises(ValueError, match="optimizer"):
        fresh.set_parameters(partial, exact_match=True)


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_set_env_and_load_with_another_number_of_envs(model_class: type[Any], tmp_path: Path) -> None:
    model = make_model(model_class, seed=0).learn(200)
    model.set_env(make_vec_env("CartPole-v1", n_envs=3, seed=1))
    assert model.n_envs == 3
    assert model.rollout_buffer.n_envs == 3
    model.learn(300)
    with pytest.raises(ValueError, match="force_reset=True"):
        model.set_env(make_vec_env("CartPole-v1", n_envs=2), force_reset=False)
    model.save(tmp_path / "model.zip")
    loaded = model_class.load(tmp_path / "model.zip", env=make_vec_env("CartPole-v1", n_envs=2, seed=2), device="cpu")
    assert loaded.n_envs == 2
    loaded.learn(300)


class CountingCallback(BaseCallback):
    def __init__(self, stop_after: int | None = None) -> None:
        super().__init__()
        self.steps = self.rollouts = 0
        self.stop_after = stop_after

    def _on_rollout_end(self) -> None:
        self.rollouts += 1

    def _on_step(self) -> bool:
        self.steps += 1
        assert {"actions", "rewards", "dones", "infos", "new_obs"} <= set(self.locals)
        return self.stop_after is None or self.steps < self.stop_after


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_callbacks(model_class: type[BaseAlgorithm], tmp_path: Path) -> None:
    env = make_vec_env("CartPole-v1", n_envs=2, seed=0)
    counting = CountingCallback()
    eval_callback = EvalCallback(
        make_vec_env("CartPole-v1", n_envs=1), eval_freq=100, n_eval_episodes=2, log_path=str(tmp_path)
    )
    checkpoints = CheckpointCallback(save_freq=150, save_path=str(tmp_path / "checkpoints"))
    model = make_model(model_class, env=env, seed=0).learn(600, callback=[counting, eval_callback, checkpoints])
    assert counting.steps == model.num_timesteps // 2
    assert counting.rollouts >= 1
    assert (tmp_path / "evaluations.npz").exists()
    assert len(np.load(tmp_path / "evaluations.npz")["results"]) >= 2
    assert len(list((tmp_path / "checkpoints").glob("*.zip"))) >= 2
    # A callback returning False stops training at once
    stopped = make_model(model_class, env=env, seed=0).learn(10_000, callback=CountingCallback(stop_after=37))
    assert stopped.num_timesteps == 37 * 2


EXPECTED_LOG_KEYS = {
    REINFORCE: {
        "train/policy_loss",
        "train/value_loss",
        "train/entropy_loss",
        "train/explained_variance",
        "train/learning_rate",
        "train/value_learning_rate",
        "train/n_episodes",
        "rollout/ep_rew_mean",
        "rollout/ep_len_mean",
        "time/fps",
    },
    NStepSARSA: {
        "train/loss",
        "train/q_mean",
        "train/target_mean",
        "train/learning_rate",
        "rollout/exploration_rate",
        "rollout/ep_rew_mean",
        "rollout/ep_len_mean",
        "time/fps",
    },
}


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_tensorboard_event_files_hold_the_logged_keys(model_class: type[BaseAlgorithm], tmp_path: Path) -> None:
    model = make_model(model_class, tensorboard_log=str(tmp_path), seed=0)
    model.learn(2000, log_interval=1, tb_log_name="run")
    event_files = glob.glob(str(tmp_path / "run_1" / "events.out.tfevents.*"))
    assert len(event_files) == 1
    tags = set(EventAccumulator(event_files[0]).Reload().Tags()["scalars"])
    assert EXPECTED_LOG_KEYS[model_class] <= tags
    assert "train/n_updates" not in tags  # excluded from TensorBoard, as in SB3


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_the_episode_count_is_logged_as_dqn_logs_it(model_class: type[BaseAlgorithm], tmp_path: Path) -> None:
    # time/episodes (SB3's DQN's key) was missing: a user switching from DQN got no curve
    model = make_model(model_class, env=make_vec_env("CartPole-v1", n_envs=2), seed=0)
    model.set_logger(configure(str(tmp_path), ["csv"]))
    model.learn(1500, log_interval=1)
    rows = (tmp_path / "progress.csv").read_text().splitlines()
    header, last = rows[0].split(","), rows[-1].split(",")
    assert int(float(last[header.index("time/episodes")])) == model._completed_episodes > 10


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_seeded_runs_are_reproducible(model_class: type[BaseAlgorithm]) -> None:
    def trained(seed: int) -> dict[str, Any]:
        return make_model(model_class, env=make_vec_env("CartPole-v1", n_envs=2), seed=seed).learn(600).get_parameters()

    assert parameters_equal(trained(5), trained(5))
    assert not parameters_equal(trained(5), trained(6))


@pytest.mark.parametrize("model_class", MODEL_LIST)
@pytest.mark.parametrize("vec_env_cls", [DummyVecEnv, SubprocVecEnv])
def test_vectorized_envs(model_class: type[BaseAlgorithm], vec_env_cls: type) -> None:
    env = make_vec_env("CartPole-v1", n_envs=2, seed=0, vec_env_cls=vec_env_cls)
    model = make_model(model_class, env=env, seed=0).learn(400)
    assert model.num_timesteps >= 400
    env.close()


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_vec_normalize(model_class: type[BaseAlgorithm]) -> None:
    env = VecNormalize(make_vec_env(lambda: gym.make("CartPole-v1", max_episode_steps=30), n_envs=2, seed=0))
    model = make_model(model_class, env=env, seed=0).learn(500)
    assert model.get_vec_normalize_env() is env


ACTION_SPACE_ENVS: dict[str, Callable[[], gym.Env]] = {
    "Discrete": lambda: IdentityEnv(dim=3, ep_length=20),
    "Box": lambda: IdentityEnvBox(ep_length=20),
    "MultiDiscrete": lambda: IdentityEnvMultiDiscrete(dim=3, ep_length=20),
    "MultiBinary": lambda: IdentityEnvMultiBinary(dim=3, ep_length=20),
}


@pytest.mark.parametrize("space", ACTION_SPACE_ENVS)
def test_reinforce_learns_on_every_supported_action_space(space: str) -> None:
    env = make_vec_env(ACTION_SPACE_ENVS[space], n_envs=2, seed=0)
    model = REINFORCE("MlpPolicy", env, policy_kwargs=dict(net_arch=[16]), seed=0, device="cpu").learn(400)
    actions, _ = model.predict(env.reset(), deterministic=False)  # type: ignore[arg-type]
    assert all(model.action_space.contains(action) for action in actions)
    assert model._n_updates > 0


@pytest.mark.parametrize("space", ["Box", "MultiDiscrete", "MultiBinary"])
def test_sarsa_refuses_non_discrete_actions_at_construction(space: str) -> None:
    env: Any = ACTION_SPACE_ENVS[space]()
    with pytest.raises(ValueError, match=r"NStepSARSA needs a Discrete action space.*use REINFORCE"):
        NStepSARSA("MlpPolicy", env)


@pytest.mark.parametrize("model_class", MODEL_LIST)
@pytest.mark.parametrize(
    ("policy", "env"),
    [
        ("CnnPolicy", lambda: FakeImageEnv(screen_height=36, screen_width=36, n_channels=1, discrete=True)),
        ("MultiInputPolicy", lambda: SimpleMultiObsEnv(random_start=True)),
    ],
)
def test_image_and_dict_observations(model_class: type[Any], policy: str, env: Any, tmp_path: Path) -> None:
    vec_env = make_vec_env(env, n_envs=2, seed=0)
    model = model_class(policy, vec_env, seed=0, device="cpu", **({} if model_class is REINFORCE else dict(train_freq=4)))
    model.learn(100)
    assert model._n_updates > 0
    model.save(tmp_path / "model.zip")
    loaded = model_class.load(tmp_path / "model.zip", device="cpu")
    obs: Any = vec_env.reset()
    np.testing.assert_array_equal(model.predict(obs, deterministic=True)[0], loaded.predict(obs, deterministic=True)[0])


INVALID_ARGUMENTS = [
    (REINFORCE, dict(learning_rate=-1.0), "learning_rate=-1.0 must be finite and > 0"),
    (REINFORCE, dict(value_learning_rate=0.0), "value_learning_rate=0.0 must be finite and > 0"),
    (REINFORCE, dict(learning_rate="fast"), "learning_rate='fast' must be a float or an SB3 schedule"),
    (REINFORCE, dict(gamma=1.5), r"gamma=1.5 must be a number in \[0.0, 1.0\]"),
    (REINFORCE, dict(n_episodes=0), "n_episodes=0 must be an integer >= 1"),
    (REINFORCE, dict(ent_coef=-0.1), "ent_coef=-0.1"),
    (REINFORCE, dict(max_episode_length=0), "max_episode_length=0"),
    (REINFORCE, dict(lr_decay_factor=0.0), "lr_decay_factor=0.0"),
    (REINFORCE, dict(lr_decay_every=10, lr_decay_milestones=[100]), "not both"),
    (REINFORCE, dict(lr_decay_unit="epoch"), "lr_decay_unit='epoch' must be one of 'episode', 'update'"),
    (REINFORCE, dict(max_grad_norm=0.0), "max_grad_norm=0.0 must be > 0, or None"),
    (REINFORCE, dict(policy_kwargs=dict(weight_init="he")), "weight_init='he' must be one of .*'kaiming' is He"),
    (NStepSARSA, dict(n_steps=0), "n_steps=0 must be an integer >= 1"),
    (NStepSARSA, dict(n_steps=2.5), "n_steps=2.5 must be an integer >= 1"),
    (NStepSARSA, dict(exploration_initial_eps=1.5), r"exploration_initial_eps=1.5 must be a number in \[0.0, 1.0\]"),
    (NStepSARSA, dict(exploration_final_eps=-0.1), "exploration_final_eps=-0.1"),
    (NStepSARSA, dict(exploration_decay_rate=0.0), "exploration_decay_rate=0.0"),
    (NStepSARSA, dict(exploration_schedule="cosine"), "exploration_schedule='cosine' must be one of"),
    # A DQN user's argument alone: the default exponential schedule would ignore it
    (NStepSARSA, dict(exploration_fraction=0.2), "exploration_fraction=0.2 .* exploration_schedule='linear'"),
    (NStepSARSA, dict(exploration_schedule="linear", exploration_fraction=0.0), "exploration_fraction=0.0"),
    # (silently ignored before: the linear schedule has no per-episode factor)
    (
        NStepSARSA,
        dict(exploration_schedule="linear", exploration_decay_rate=0.99),
        "exploration_decay_rate=0.99 .*exploration_schedule='exponential'",
    ),
    # (torch's "got multiple values for keyword argument 'lr'" before)
    (
        NStepSARSA,
        dict(policy_kwargs=dict(optimizer_kwargs=dict(lr=1e-3))),
        r"optimizer_kwargs=dict\(lr=0.001\).* learning_rate=",
    ),
    (
        REINFORCE,
        dict(policy_kwargs=dict(optimizer_kwargs=dict(lr=1e-3))),
        r"optimizer_kwargs=dict\(lr=0.001\).* value_learning_rate",
    ),
    # (Adam's "unexpected keyword argument 'learning_rate'" before, with a hint about the policy's arguments)
    (
        REINFORCE,
        dict(policy_kwargs=dict(optimizer_kwargs=dict(learning_rate=1e-3))),
        r"optimizer_kwargs=dict\(learning_rate=0.001\).* drop learning_rate",
    ),
    (NStepSARSA, dict(learning_rate=0.0), "learning_rate=0.0 must be finite and > 0"),
    (NStepSARSA, dict(gamma=-0.1), "gamma=-0.1"),
    (NStepSARSA, dict(train_freq=0), "train_freq=0"),
    (NStepSARSA, dict(train_freq=(4, "step")), r"train_freq=\(4, 'step'\) must be an integer >= 1.*tuple form"),
    (NStepSARSA, dict(loss_function="l1"), "loss_function='l1' must be one of 'mse', 'huber'"),
    (NStepSARSA, dict(td_lambda=1.5), r"td_lambda=1.5 must be a number in \[0.0, 1.0\]"),
    (NStepSARSA, dict(lr_decay_milestones=[300, -5]), r"lr_decay_milestones\[...\]=-5"),
    (NStepSARSA, dict(lr_decay_milestones=300), r"lr_decay_milestones=300 must be a list of counts, e.g. \[300, 500\]"),
    (
        REINFORCE,
        dict(lr_decay_factor=0.5),
        "lr_decay_factor=0.5 has no effect without lr_decay_every .* or lr_decay_milestones",
    ),
    (REINFORCE, dict(policy_kwargs=dict(ortho_init=False)), "policy_kwargs: .*'ortho_init'.*weight_init='orthogonal'"),
    (NStepSARSA, dict(policy_kwargs=dict(net_arch=dict(pi=[64], qf=[64]))), "takes a list of hidden layer sizes"),
]


def test_numpy_numbers_are_accepted() -> None:
    # What a sweep over np.arange / np.linspace passes
    numbers: dict[str, Any] = dict(n_steps=np.int64(5), gamma=np.float32(0.99), train_freq=np.int32(4))
    model = NStepSARSA("MlpPolicy", "CartPole-v1", **numbers)
    assert (model.n_steps, model.train_freq) == (5, 4)


@pytest.mark.parametrize(("model_class", "kwargs", "message"), INVALID_ARGUMENTS)
def test_invalid_arguments_are_refused_at_construction(model_class: type[Any], kwargs: dict[str, Any], message: str) -> None:
    with pytest.raises((ValueError, TypeError), match=message):
        model_class("MlpPolicy", "CartPole-v1", **kwargs)


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_logger_records_under_sb3_prefixes(model_class: type[BaseAlgorithm], tmp_path: Path) -> None:
    model = make_model(model_class, seed=0)
    model.set_logger(configure(str(tmp_path), ["csv"]))
    model.learn(1500, log_interval=1)
    header = (tmp_path / "progress.csv").read_text().splitlines()[0].split(",")
    assert EXPECTED_LOG_KEYS[model_class] <= set(header)
    assert all(key.split("/")[0] in {"train", "rollout", "time"} for key in header)


@pytest.mark.skipif(not th.cuda.is_available(), reason="needs a CUDA device")
@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_cuda(model_class: type[Any], tmp_path: Path) -> None:
    model = model_class("MlpPolicy", "CartPole-v1", device="cuda", seed=0, **SMALL[model_class]).learn(500)
    assert next(model.policy.parameters()).device.type == "cuda"
    model.save(tmp_path / "model.zip")
    loaded = model_class.load(tmp_path / "model.zip", device="cuda")
    obs = observations()
    np.testing.assert_array_equal(model.predict(obs, deterministic=True)[0], loaded.predict(obs, deterministic=True)[0])


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_a_refused_env_leaves_the_model_as_it_was(model_class: type[Any]) -> None:
    model = model_class("MlpPolicy", make_vec_env("CartPole-v1", n_envs=3), seed=0, **SMALL[model_class])
    with pytest.raises(ValueError, match="Observation spaces do not match"):
        model.set_env(make_vec_env("Acrobot-v1", n_envs=5))
    assert model.n_envs == model.env.num_envs == model.rollout_buffer.n_envs == 3
    model.learn(300, reset_num_timesteps=False)
