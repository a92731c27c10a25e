"""
Saving, loading and resuming: a save replaces its file whole, ``set_parameters`` and ``load`` refuse what does not fit
before changing anything, a file of another algorithm is named as such, a model loaded without a reset starts new
episodes, and ``learn()`` in two calls is ``learn()`` in one.
"""

import copy
import warnings
from pathlib import Path
from typing import Any

import pytest
import torch as th
from stable_baselines3 import A2C, DQN, PPO
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
from test_contract import MODEL_LIST, make_model, parameters_equal

from sb3_classic import REINFORCE, NStepSARSA


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


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_learn_without_an_env_says_how_to_give_one(model_class: type[BaseAlgorithm], tmp_path: Path) -> None:
    make_model(model_class, seed=0).save(tmp_path / "model")
    loaded = model_class.load(tmp_path / "model")
    with pytest.raises(ValueError, match=r"no env to train on .*set_env"):  # (SB3: a bare AssertionError)
        loaded.learn(100)
    loaded.set_env(make_vec_env("CartPole-v1"))
    loaded.learn(100)


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_an_env_of_other_spaces_is_named_with_the_env_the_model_trained_on(
    model_class: type[BaseAlgorithm], tmp_path: Path
) -> None:
    # SB3 printed the two spaces, and neither the env the model trained on nor what to pass
    model = make_model(model_class, seed=0)
    model.save(tmp_path / "model")
    expected = rf"this {model_class.__name__} model was trained on CartPole-v1, and Acrobot-v1 does not fit it .*Pass env="
    with pytest.raises(ValueError, match=expected):
        model_class.load(tmp_path / "model", env=make_vec_env("Acrobot-v1"))
    with pytest.raises(ValueError, match=expected):
        model.set_env(make_vec_env("Acrobot-v1"))
    # A model loaded without an env and saved again still knows it
    model_class.load(tmp_path / "model").save(tmp_path / "again")
    with pytest.raises(ValueError, match=expected):
        model_class.load(tmp_path / "again", env=make_vec_env("Acrobot-v1"))
    assert model_class.load(tmp_path / "again", env=make_vec_env("CartPole-v1")).get_env() is not None


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
