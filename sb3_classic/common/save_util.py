"""
Saving and loading that leave no file or model half-changed: ``save`` replaces the file at once, ``set_parameters``
loads all or nothing, ``load`` checks the arguments it changes, naming one that would build other networks than the
saved ones, and a model loaded with ``force_reset=False`` continues its saved envs' episodes only where it can.
"""

import copy
import difflib
import io
import os
import pathlib
import shutil
import uuid
import warnings
from collections.abc import Callable, Iterable
from typing import Any, ClassVar, TypeVar

import numpy as np
import torch as th
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.save_util import load_from_zip_file, recursive_getattr
from stable_baselines3.common.type_aliases import GymEnv, TensorDict
from stable_baselines3.common.vec_env import VecEnv

from sb3_classic.common.arguments import LOADING, constructor_parameters

SelfSafeSaveLoad = TypeVar("SelfSafeSaveLoad", bound="SafeSaveLoadMixin")


class SafeSaveLoadMixin(BaseAlgorithm):
    """
    SB3's ``save``, ``load`` and ``set_parameters``, made safe against partial writes, partial loads and arguments
    that do nothing or do not fit the saved model. Put it before the SB3 algorithm class in the bases.
    """

    #: Constructor arguments that decide which networks the policy has (a bootstrap copy, a weight average, v̂), with
    #: whether a value builds that network: ``load()`` cannot put saved weights into other networks
    _network_arguments: ClassVar[dict[str, Callable[[Any], bool]]] = {}

    @classmethod
    def load(
        cls: type[SelfSafeSaveLoad],
        path: str | pathlib.Path | io.BufferedIOBase,
        env: GymEnv | None = None,
        device: th.device | str = "auto",
        custom_objects: dict[str, Any] | None = None,
        print_system_info: bool = False,
        force_reset: bool = True,
        **kwargs: Any,
    ) -> SelfSafeSaveLoad:
        """
        SB3's ``load``: the model saved in ``path``, with ``kwargs`` changing its arguments (rl-zoo3's ``-i`` passes the
        YAML entry's). What they change is checked as the constructor checks it, and an argument that would build
        other networks than the saved ones (``averaging_tau``, ``target_update_interval``, ``use_baseline``) is named,
        as SB3 names ``policy_kwargs`` that differ from the saved ones.

        :param path: the saved file (or a file-like object)
        :param env: the env to continue on (``None``: only to predict)
        :param device: where the networks go
        :param custom_objects: values to use instead of the saved ones (not deserialised)
        :param print_system_info: print the saved model's and this system's versions
        :param force_reset: reset the envs before training
        :param kwargs: arguments to change
        :return: the model
        :raise TypeError: for an argument the constructor does not have (SB3 sets it as an attribute, which nothing reads:
            a misspelt ``exploration_final_esp`` would be ignored)
        :raise ValueError: for an invalid value, or one that changes the networks (in ``kwargs`` or ``custom_objects``)
        """
        defaults = constructor_parameters(cls)
        arguments = [name for name in defaults if name not in ("self", "policy", "env", "_init_setup_model")]
        for key in kwargs:
            if key == "policy":
                raise TypeError(
                    f"{cls.__name__}.load() got policy={kwargs[key]!r}: a loaded model keeps its saved policy class "
                    "(its weights are of those networks); to train another policy, construct a new model"
                )
            if key not in arguments:
                close = difflib.get_close_matches(key, arguments, n=1)
                raise TypeError(
                    f"{cls.__name__}.load() got {key}={kwargs[key]!r}, which is not an argument of {cls.__name__}"
                    + (f" (did you mean {close[0]}?)" if close else "")
                    + ": load() changes the constructor's arguments only (set other attributes on the loaded model)"
                )
        token = LOADING.set(True)
        try:
            return super().load(path, env, device, custom_objects, print_system_info, force_reset, **kwargs)
        except ValueError as error:
            if not str(error).startswith(SPACES_DIFFER):
                raise
            if isinstance(path, io.BufferedIOBase):
                path.seek(0)
            data, _, _ = load_from_zip_file(path, load_data=True, device="cpu", custom_objects=custom_objects)
            raise ValueError(other_env_message(cls.__name__, (data or {}).get("_trained_env_id"), env, error)) from error
        except RuntimeError as error:
            # PyTorch's load_state_dict raises RuntimeError for weights of other networks; the arguments are checked
            # before the weights are loaded, so a RuntimeError with a network argument changed is of those weights
            # (custom_objects replace saved values as kwargs do, without the check of _setup_model's arguments)
            changes = {**(custom_objects or {}), **kwargs}
            if not set(changes) & set(cls._network_arguments):
                raise
            if isinstance(path, io.BufferedIOBase):
                path.seek(0)
            others = {key: value for key, value in (custom_objects or {}).items() if key not in cls._network_arguments}
            data, _, _ = load_from_zip_file(path, load_data=True, device="cpu", custom_objects=others)
            saved = {key: (data or {}).get(key, defaults[key].default) for key in cls._network_arguments}
            changed = [
                (key, changes[key], saved[key])
                for key, builds in cls._network_arguments.items()
                if key in changes and builds(changes[key]) != builds(saved[key])
            ]
            if not changed:
                raise
            key, given, saved_value = changed[0]
            raise ValueError(
                f"{cls.__name__}.load: {key}={given!r} builds other networks than those of the saved model, trained with "
                f"{key}={saved_value!r}, so its weights cannot be loaded. Pass {key}={saved_value!r} to continue it "
                f"(rl-zoo3's -i: -params {key}:{saved_value!r}), or train a new model with {key}={given!r}"
            ) from error
        finally:
            LOADING.reset(token)

    def save(
        self,
        path: str | pathlib.Path | io.BufferedIOBase,
        exclude: Iterable[str] | None = None,
        include: Iterable[str] | None = None,
    ) -> None:
        """
        SB3's ``save``, written to a temporary file beside the target and then renamed onto it (``os.replace``, atomic):
        a process killed while saving (a pre-empted job, a ``CheckpointCallback`` mid-write) leaves the earlier file
        whole, and a process loading it meanwhile reads the old or the new model, never a part (SB3 overwrites in
        place). A kill can leave the temporary file, ``.sb3_classic-<hex>.partial.zip``, beside the target. The target
        is SB3's: ``.zip`` is added to a path without a suffix, and missing folders are created; an existing file keeps
        its permission bits, a symbolic link is written through, and a read-only file is refused as SB3 refuses it.
        Where no file can be created beside the target (a read-only folder), SB3 writes the file in place.

        :param path: where to save (a file-like object is written directly)
        :param exclude: names of the attributes not to save, beside the default ones
        :param include: names of the attributes to save although excluded by default
        :raises PermissionError: if the target exists and is not writable
        """
        # The id of the env it trained on, for load()'s and set_env()'s error on an env of other spaces (SB3 saves none)
        self._trained_env_id = env_id(self.env) or getattr(self, "_trained_env_id", None)
        target = pathlib.Path(path) if isinstance(path, (str, os.PathLike)) else None
        if target is None or not target.name or target.is_dir():
            super().save(path, exclude, include)  # (a file object; SB3's own handling of "" and of a folder)
            return
        if target.suffix == "":
            target = target.with_name(f"{target.name}.zip")
        target = pathlib.Path(os.path.realpath(target))  # (through a symbolic link, as SB3's open() writes)
        if target.exists() and not os.access(target, os.W_OK):
            raise PermissionError(f"{target} is not writable: {type(self).__name__}.save keeps it (SB3 would not open it)")
        if not target.parent.exists():
            warnings.warn(f"Path '{target.parent}' does not exist. Will create it.", stacklevel=2)  # (SB3's warning)
            target.parent.mkdir(parents=True, exist_ok=True)
        temporary = target.with_name(f".sb3_classic-{uuid.uuid4().hex[:12]}.partial.zip")
        try:
            temporary.touch()
        except OSError:
            super().save(target, exclude, include)  # no file can be made here: SB3's write in place
            return
        try:
            super().save(temporary, exclude, include)
            if target.exists():
                shutil.copymode(target, temporary)
            os.replace(temporary, target)
        finally:
            temporary.unlink(missing_ok=True)

    def set_parameters(
        self,
        load_path_or_dict: str | TensorDict,
        exact_match: bool = True,
        device: th.device | str = "auto",
    ) -> None:
        """
        SB3's ``set_parameters``, all or nothing: if it raises, the networks and optimizers are left as they were (SB3's
        keeps what it loaded before the error: the weights of a dict whose other entries do not match, the first layer
        of another architecture). ``load()`` uses it.

        :param load_path_or_dict: a saved model's file, or a dict of ``get_parameters()``'s form
        :param exact_match: every network and optimizer must be given, with every parameter
        :param device: where the parameters go
        :raises ValueError: also for an optimizer's state of another optimizer class (its hyperparameters differ: SGD's
            state in Adam would make the next ``learn()`` fail on a missing ``betas``)
        """
        names, _ = self._get_torch_save_params()
        before = {name: copy.deepcopy(recursive_getattr(self, name).state_dict()) for name in names}
        try:
            super().set_parameters(load_path_or_dict, exact_match, device)
            for name in names:
                optimizer = recursive_getattr(self, name)
                if isinstance(optimizer, th.optim.Optimizer):
                    # Another class's state lacks some of this class's hyperparameters and has some of its own; a state
                    # of the same class can only lack some (those of another PyTorch version) or add some (a
                    # scheduler's initial_lr, another PyTorch version's)
                    given = set().union(*optimizer.param_groups) - {"params", "initial_lr"}
                    missing, foreign = sorted(set(optimizer.defaults) - given), sorted(given - set(optimizer.defaults))
                    if missing and foreign:
                        raise ValueError(
                            f"set_parameters: the state given for {name} ({type(optimizer).__name__}) is of another "
                            f"optimizer: it lacks the hyperparameters {', '.join(missing)} and has {', '.join(foreign)}. "
                            "Pass the state of the same optimizer class, or leave that entry out with exact_match=False"
                        )
        except BaseException:
            for name, state in before.items():
                recursive_getattr(self, name).load_state_dict(state)
            raise


def episodes_not_continued(model: BaseAlgorithm, episode_length: np.ndarray) -> str | None:
    """
    :param model: a model whose ``learn()`` would continue the envs' episodes (``reset_num_timesteps=False``, with the
        envs' last observations: ``load(..., force_reset=False)``)
    :param episode_length: the steps of each env's episode that its buffer holds
    :return: why ``learn()`` resets the envs instead, as a warning; ``None`` if it can continue them
    """
    saved_envs = None if model._last_episode_starts is None else len(model._last_episode_starts)
    algorithm = type(model).__name__
    if saved_envs not in (None, model.n_envs):
        # load(..., env=<another number of envs>, force_reset=False): the file's last observations are of other envs
        # (NumPy's "operands could not be broadcast" otherwise)
        reason = (
            f"This model's file holds the last observations of {saved_envs} envs, and its env has {model.n_envs}: "
            f"{algorithm} resets the envs. (load(..., force_reset=False) continues the saved envs' episodes only with the "
            "same number of envs"
        )
    elif model._last_episode_starts is None or np.any(
        ~np.asarray(model._last_episode_starts, dtype=bool) & (episode_length == 0)
    ):
        # An env is in the middle of an episode whose earlier steps the buffer does not hold (the file has the envs'
        # last observations but not the buffer): it would be trained from where the file left it as if it began there
        # (the wrong t in γ^t and in episode lengths, REINFORCE's returns of a part of an episode)
        reason = (
            "The episodes in progress when this model was saved are not in its file (the buffer is not saved): "
            f"{algorithm} resets the envs to train on whole episodes. (load(..., force_reset=False) cannot continue an "
            "episode here"
        )
    else:
        return None
    return f"{reason}; the learned parameters and counts are kept)"


#: The start of SB3's error for an env whose spaces differ from a model's (``check_for_correct_spaces``)
SPACES_DIFFER = ("Observation spaces do not match", "Action spaces do not match")


def env_id(env: GymEnv | str | None) -> str | None:
    """
    :param env: an env, a VecEnv (its first env's), or an env id
    :return: its Gymnasium id, if it has one (None for an env without a spec or none at all)
    """
    if env is None or isinstance(env, str):
        return env
    try:
        spec = env.get_attr("spec", [0])[0] if isinstance(env, VecEnv) else env.spec
    except Exception:  # (a description only: a VecEnv of the user's may not answer get_attr)
        return None
    return getattr(spec, "id", None)


def other_env_message(algorithm: str, trained_on: str | None, env: GymEnv | str | None, error: ValueError) -> str:
    """
    :param algorithm: the model's class name
    :param trained_on: the id of the env the model trained on, if known
    :param env: the env given, whose spaces differ from the model's
    :param error: SB3's error, which gives the two spaces
    :return: which env the model trained on, which env was given, and what to pass instead
    """
    given = env_id(env) or "the env given"
    model = f"trained on {trained_on}" if trained_on else "trained on another env"
    fit = f"{trained_on} or another env with its spaces" if trained_on else "an env with the model's spaces"
    return (
        f"this {algorithm} model was {model}, and {given} does not fit it ({error}). Pass env= {fit}; env=None loads it "
        f"to predict only; or train a new {algorithm} on {given}"
    )
