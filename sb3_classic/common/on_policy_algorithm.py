"""The base class of sb3_classic's algorithms: SB3's on-policy loop around a buffer that keeps whole trajectories."""

import contextvars
import copy
import difflib
import inspect
import io
import math
import numbers
import os
import pathlib
import re
import shutil
import uuid
import warnings
from abc import abstractmethod
from collections.abc import Callable, Iterable, Sequence
from typing import Any, ClassVar, TypeVar

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.save_util import load_from_zip_file, recursive_getattr
from stable_baselines3.common.type_aliases import GymEnv, MaybeCallback, Schedule, TensorDict
from stable_baselines3.common.utils import check_for_correct_spaces, update_learning_rate
from stable_baselines3.common.vec_env import VecEnv

from sb3_classic.common.buffers import Observations, TrajectoryBuffer, all_finite, non_finite_entries, select
from sb3_classic.common.policies import action_offset
from sb3_classic.common.schedules import StepDecay
from sb3_classic.common.utils import check_bool, check_choice, check_learning_rate, check_positive_int, check_range

SelfClassicOnPolicyAlgorithm = TypeVar("SelfClassicOnPolicyAlgorithm", bound="ClassicOnPolicyAlgorithm")

#: The advice of a non-finite value's error, for the values ``step()`` returns
FIND_NON_FINITE = (
    "To find where the value comes from, wrap the env in stable_baselines3.common.vec_env.VecCheckNan(env, "
    "raise_exception=True); if the env's values are finite, a callback changed them in place in its _on_step."
)
#: True while ``load()`` builds a model (its checks then accept a learning rate of 0)
LOADING: contextvars.ContextVar[bool] = contextvars.ContextVar("sb3_classic_loading", default=False)
#: The policy's arguments the algorithm passes itself (not ``policy_kwargs``)
_POLICY_ARGUMENTS = {
    "self",
    "observation_space",
    "action_space",
    "lr_schedule",
    "value_lr_schedule",
    "use_baseline",
    "target_network",
    "averaged_network",
}


class ClassicOnPolicyAlgorithm(OnPolicyAlgorithm):
    """
    Base of REINFORCE and n-step SARSA. What they share:

    - a ``TrajectoryBuffer`` that keeps each transition until its target is known, so an episode (REINFORCE) or an
      n-step window (SARSA) may span several rollouts and envs may end their episodes at different times;
    - the rollout loop, which stops when the algorithm says its update has what it needs
      (``_rollout_complete``); the time-limit bootstrap; an optional cap on episode length;
    - learning rates given as SB3 schedules (of the training progress) times a step decay (of the completed
      episodes or updates, like the seed report's ``StepLR``), and that training state kept across ``learn()``
      calls and ``save``/``load``;
    - ``set_env`` with another number of envs.

    :param policy: the policy model to use (``"MlpPolicy"``, ``"CnnPolicy"``, ``"MultiInputPolicy"`` or a class)
    :param env: the environment to learn from (if registered in Gymnasium, can be str)
    :param learning_rate: learning rate (a float or an SB3 schedule of the remaining progress)
    :param n_steps: passed to ``OnPolicyAlgorithm``; its meaning is the subclass's
    :param gamma: discount factor γ
    :param max_grad_norm: gradient-norm clipping threshold; ``None`` for no clipping
    :param lr_decay_factor: multiply the learning rate(s) by this at each decay (1.0: no decay)
    :param lr_decay_every: decay every this many ``lr_decay_unit`` (like PyTorch's ``StepLR(step_size=...)``)
    :param lr_decay_milestones: decay when the count of ``lr_decay_unit`` reaches each of these instead
        (like ``MultiStepLR``)
    :param lr_decay_unit: what the decay counts: ``"episode"`` (completed episodes, all envs together)
        or ``"update"`` (gradient steps, as SB3's ``train/n_updates`` counts them: a SARSA update of ``gradient_steps``
        steps counts ``gradient_steps``). The rate is set at the start of each update (``train()``, as SB3 sets its
        learning rates) from the count so far: every gradient step of one update uses the same rate, and the decays
        whose boundaries an update's steps pass apply together at the next update (REINFORCE's per-step mode: an
        episode's T updates are one ``train()``)
    :param handle_timeout_termination: bootstrap from the value of the final state when an episode is cut by a time
        limit (``TimeLimit.truncated``), treating the limit as not part of the task (SB3's default); if False,
        a truncation ends the return like a termination
    :param max_episode_length: cut any episode that reaches this many steps for training (with a warning), so an env
        that never ends cannot grow the buffer without bound: its return ends there, bootstrapped as at a time limit;
        the env is not reset (a VecEnv resets an env only when it ends), so the next episode trained on starts from
        the state reached, and the Monitor and callbacks do not count the cut; ``None`` for no cap
    :param stats_window_size: window size for the rollout logging, in episodes
    :param tensorboard_log: the log location for TensorBoard (if None, no logging)
    :param policy_kwargs: additional arguments to be passed to the policy on creation
    :param verbose: verbosity level: 0 no output, 1 info, 2 debug
    :param seed: seed for the pseudo random generators
    :param device: device (cpu, cuda, ...) on which the code should be run
    :param supported_action_spaces: the action spaces the subclass supports
    :param _init_setup_model: whether or not to build the network at the creation of the instance
    """

    rollout_buffer: TrajectoryBuffer  # type: ignore[assignment]
    policy: BasePolicy  # type: ignore[assignment]
    lr_decay: StepDecay
    #: ``"batch"`` or ``"per_step"``: how an update applies its transitions (set by each algorithm)
    update_mode: str

    def __init__(
        self,
        policy: str | type[BasePolicy],
        env: GymEnv | str,
        learning_rate: float | Schedule,
        n_steps: int,
        gamma: float,
        max_grad_norm: float | None,
        lr_decay_factor: float,
        lr_decay_every: int | None,
        lr_decay_milestones: Sequence[int] | None,
        lr_decay_unit: str,
        handle_timeout_termination: bool,
        max_episode_length: int | None,
        stats_window_size: int,
        tensorboard_log: str | None,
        policy_kwargs: dict[str, Any] | None,
        verbose: int,
        seed: int | None,
        device: th.device | str,
        supported_action_spaces: tuple[type[spaces.Space], ...],
        _init_setup_model: bool,
    ):
        super().__init__(
            policy,  # type: ignore[arg-type]
            env,
            learning_rate=learning_rate,
            n_steps=n_steps,
            gamma=gamma,
            # Unused: returns are Monte-Carlo (REINFORCE) or n-step (SARSA), not GAE
            gae_lambda=1.0,
            # Set by REINFORCE; a Q-network has no policy entropy
            ent_coef=0.0,
            # Unused: REINFORCE's value network has its own optimizer and learning rate, SARSA has no value network
            vf_coef=0.0,
            max_grad_norm=math.inf if max_grad_norm is None else max_grad_norm,
            # gSDE is for continuous actions of actor-critic methods
            use_sde=False,
            sde_sample_freq=-1,
            # Unused: the algorithms build their own TrajectoryBuffer
            rollout_buffer_class=None,
            rollout_buffer_kwargs=None,
            stats_window_size=stats_window_size,
            tensorboard_log=tensorboard_log,
            policy_kwargs=policy_kwargs,
            verbose=verbose,
            seed=seed,
            device=device,
            _init_setup_model=False,
            # Checked below with an error that says what to do (SB3 asserts)
            supported_action_spaces=None,
        )
        self.lr_decay_factor = lr_decay_factor
        self.lr_decay_every = lr_decay_every
        self.lr_decay_milestones = lr_decay_milestones
        self.lr_decay_unit = lr_decay_unit
        self.handle_timeout_termination = handle_timeout_termination
        self.max_episode_length = max_episode_length
        # Training state the count-driven schedules follow; unlike num_timesteps, learn() never resets it
        self._completed_episodes = 0
        # The episodes completed before the current rollout: an update's learning-rate decay counts those, as
        # PyTorch's StepLR stepped after each episode's updates (the episodes ending in the rollout decay the next one)
        self._episodes_before_rollout = 0
        if self.env is not None and not isinstance(self.action_space, supported_action_spaces):
            raise ValueError(self._unsupported_action_space_message(supported_action_spaces))

    def _unsupported_action_space_message(self, supported: tuple[type[spaces.Space], ...]) -> str:
        names = ", ".join(space.__name__ for space in supported)
        return f"{type(self).__name__} supports {names} action spaces, not {self.action_space}"

    #: Constructor arguments that decide which networks the policy has (a bootstrap copy, a weight average, v̂), with
    #: whether a value builds that network: ``load()`` cannot put saved weights into other networks
    _network_arguments: ClassVar[dict[str, Callable[[Any], bool]]] = {}

    @classmethod
    def load(
        cls: type[SelfClassicOnPolicyAlgorithm],
        path: str | pathlib.Path | io.BufferedIOBase,
        env: GymEnv | None = None,
        device: th.device | str = "auto",
        custom_objects: dict[str, Any] | None = None,
        print_system_info: bool = False,
        force_reset: bool = True,
        **kwargs: Any,
    ) -> SelfClassicOnPolicyAlgorithm:
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
        defaults = cls._constructor_parameters()
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
        except RuntimeError as error:
            # custom_objects replace saved values as kwargs do (without the check of _setup_model's arguments)
            changes = {**(custom_objects or {}), **kwargs}
            if "state_dict" not in str(error) or not set(changes) & set(cls._network_arguments):
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
            key, given, saved = changed[0]
            raise ValueError(
                f"{cls.__name__}.load: {key}={given!r} builds other networks than those of the saved model, trained with "
                f"{key}={saved!r}, so its weights cannot be loaded. Pass {key}={saved!r} to continue it (rl-zoo3's -i: "
                f"-params {key}:{saved!r}), or train a new model with {key}={given!r}"
            ) from error
        finally:
            LOADING.reset(token)

    @classmethod
    def _constructor_parameters(cls) -> dict[str, inspect.Parameter]:
        """
        :return: the constructor's parameters by name, with those of the parents' constructors that a subclass's passes
            on through ``**kwargs`` (``def __init__(self, *args, bonus=0.0, **kwargs)``), the subclass's first
        """
        parameters: dict[str, inspect.Parameter] = {}
        for klass in cls.__mro__:
            init = klass.__dict__.get("__init__")
            if init is None:
                continue
            own = inspect.signature(init).parameters
            for name, parameter in own.items():
                if parameter.kind not in (parameter.VAR_POSITIONAL, parameter.VAR_KEYWORD):
                    parameters.setdefault(name, parameter)
            if not any(parameter.kind is parameter.VAR_KEYWORD for parameter in own.values()):
                break
        return parameters

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
            into Adam made the next ``learn()`` fail on a missing ``betas``)
        """
        names, _ = self._get_torch_save_params()
        before = {name: copy.deepcopy(recursive_getattr(self, name).state_dict()) for name in names}
        try:
            super().set_parameters(load_path_or_dict, exact_match, device)
            for name in names:
                optimizer = recursive_getattr(self, name)
                if isinstance(optimizer, th.optim.Optimizer):
                    # Another class's state lacks some of this class's hyperparameters and has some of its own; one of
                    # the same class only lacks those added since it was saved, or has some added since (a scheduler's
                    # initial_lr, a newer torch's)
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

    def _check_arguments(self) -> None:
        """
        Raise a ValueError naming the argument for anything invalid; subclasses extend it. ``_setup_model`` calls it,
        so that ``load(..., **kwargs)`` (rl-zoo3's ``-i``) checks what it changes as the constructor does; a learning
        rate of 0 is accepted there (rl-zoo3's ``enjoy`` loads with ``learning_rate=0.0``, as SB3 allows).
        """
        check_learning_rate("learning_rate", self.learning_rate, allow_zero=LOADING.get())
        check_range("gamma", self.gamma, 0.0, 1.0, hint="0.99 is the usual choice")
        if isinstance(self.max_grad_norm, bool) or not isinstance(self.max_grad_norm, numbers.Real):
            raise TypeError(f"max_grad_norm={self.max_grad_norm!r} must be a number > 0, or None for no clipping")
        if not self.max_grad_norm > 0:
            raise ValueError(f"max_grad_norm={self.max_grad_norm!r} must be > 0, or None for no clipping")
        check_range("lr_decay_factor", self.lr_decay_factor, 0.0, 1.0, low_open=True, hint="1.0 means no decay")
        check_choice("lr_decay_unit", self.lr_decay_unit, ("episode", "update"))
        check_bool("handle_timeout_termination", self.handle_timeout_termination)
        if self.lr_decay_every is not None:
            check_positive_int("lr_decay_every", self.lr_decay_every)
            if self.lr_decay_milestones is not None:
                raise ValueError("Pass lr_decay_every or lr_decay_milestones, not both")
        if self.lr_decay_milestones is not None:
            if isinstance(self.lr_decay_milestones, (str, bytes)) or not isinstance(self.lr_decay_milestones, Sequence):
                raise TypeError(
                    f"lr_decay_milestones={self.lr_decay_milestones!r} must be a list of counts, e.g. [300, 500] (one "
                    "milestone: [300]); for a decay every k, pass lr_decay_every=k"
                )
            if len(self.lr_decay_milestones) == 0:
                raise ValueError(
                    "lr_decay_milestones=[] has no milestone: pass the counts to decay at, e.g. [300, 500], or None for "
                    "no decay"
                )
            for milestone in self.lr_decay_milestones:
                check_positive_int("lr_decay_milestones[...]", milestone)
        if self.lr_decay_factor != 1.0 and self.lr_decay_every is None and self.lr_decay_milestones is None:
            raise ValueError(
                f"lr_decay_factor={self.lr_decay_factor!r} has no effect without lr_decay_every (a decay every k "
                "episodes or updates, like StepLR) or lr_decay_milestones (like MultiStepLR): pass one of them"
            )
        if self.max_episode_length is not None:
            check_positive_int("max_episode_length", self.max_episode_length, hint="Pass None for no cap")

    @abstractmethod
    def _make_policy(self) -> BasePolicy:
        """Build the policy (networks and optimizers) for the current spaces and arguments."""

    def _initial_buffer_size(self) -> int:
        """:return: the buffer's initial capacity in steps per env (it grows when needed)"""
        return 1024

    def _setup_model(self) -> None:
        # First: a file saved by another algorithm (load() takes its policy class) would otherwise fail on the first of
        # that algorithm's arguments this one reads otherwise (DQN's train_freq tuple, say), with a misleading message
        own_policies = tuple(self.policy_aliases.values())
        if own_policies and not (isinstance(self.policy_class, type) and issubclass(self.policy_class, own_policies)):
            raise TypeError(self._foreign_policy_message())
        if self.max_grad_norm is None:
            # No clipping, as the constructor stores it (load(..., max_grad_norm=None) sets None: rl-zoo3's -i)
            self.max_grad_norm = math.inf
        self._check_arguments()
        self._setup_lr_schedule()
        self.lr_decay = StepDecay(self.lr_decay_factor, self.lr_decay_every, self.lr_decay_milestones)
        # The env's value of action index 0 (Discrete/MultiDiscrete `start`), added to what the envs are sent
        self._action_offset = action_offset(self.action_space)
        self.set_random_seed(self.seed)
        self._make_buffer()
        try:
            policy = self._make_policy()
        except TypeError as error:
            if "unexpected keyword argument" not in str(error):
                raise
            raise TypeError(f"policy_kwargs: {error}. {self._policy_kwargs_hint(str(error))}") from error
        self.policy = policy.to(self.device)

    def _refuse_policy_kwargs_set_here(self, **arguments: str) -> None:
        """
        :param arguments: the policy's arguments that ``_make_policy`` sets itself, each with the argument of the
            algorithm that sets it
        :raises TypeError: if ``policy_kwargs`` gives one of them (Python's "got multiple values" otherwise), naming
            the algorithm's argument to pass instead
        """
        for policy_argument, own_argument in arguments.items():
            if policy_argument in self.policy_kwargs:
                raise TypeError(
                    f"policy_kwargs={{{policy_argument!r}: {self.policy_kwargs[policy_argument]!r}}}: "
                    f"{type(self).__name__} sets the policy's {policy_argument} from its own {own_argument}: pass "
                    f"{own_argument}=... to {type(self).__name__} instead"
                )

    def _foreign_policy_message(self) -> str:
        """
        :return: the error of a policy class that is not one of this algorithm's (e.g. SB3's ``ActorCriticPolicy``
            passed to REINFORCE, or a file saved by another algorithm: ``load()`` takes the saved policy class)
        """
        name = getattr(self.policy_class, "__qualname__", repr(self.policy_class))
        module = getattr(self.policy_class, "__module__", "")
        aliases = ", ".join(repr(alias) for alias in self.policy_aliases)
        base = self.policy_aliases.get("MlpPolicy")  # the others subclass it
        own = base.__name__ if base is not None else ", ".join(policy.__name__ for policy in self.policy_aliases.values())
        # The class to load a file with, from its policy's module (stable_baselines3.dqn.policies: DQN)
        package = module.split(".")
        if package[0] in ("stable_baselines3", "sb3_contrib") and len(package) > 1 and package[1] != "common":
            loader = f"{package[0]}.{package[1].upper()}.load"
        elif module.startswith("stable_baselines3.common"):
            loader = "stable_baselines3.A2C.load or PPO.load, whichever saved it"
        else:
            loader = "REINFORCE.load" if type(self).__name__ == "NStepSARSA" else "NStepSARSA.load"
        return (
            f"policy={module}.{name} is not one of {type(self).__name__}'s policies: pass {aliases}, or a subclass of "
            f"{own}. If this model was loaded from a file, the file was saved by another algorithm; load it with that "
            f"algorithm's class ({loader})"
        )

    def _policy_kwargs_hint(self, error: str) -> str:
        """
        :param error: the error of an unknown keyword argument (``X.__init__() got an unexpected keyword argument``)
        :return: what takes it: the features extractor's or the activation's kwargs if ``X`` is one of them, else
            what ``policy_kwargs`` takes
        """
        failed = re.match(r"(\w+)\.__init__\(\)", error)
        extractor = self.policy_kwargs.get("features_extractor_class")
        activation = self.policy_kwargs.get("activation_fn")
        if failed and failed.group(1) != self.policy_class.__name__:
            name = failed.group(1)
            if "features_extractor_kwargs" in self.policy_kwargs and getattr(extractor, "__name__", name) == name:
                if extractor is None:
                    return (
                        f"features_extractor_kwargs go to features_extractor_class, here the default {name}: pass the "
                        "class they belong to (e.g. features_extractor_class=TileCoding for n_tilings and "
                        "tiles_per_dim), or drop them"
                    )
                return f"features_extractor_kwargs go to features_extractor_class={name}: give that class's own arguments"
            if "activation_kwargs" in self.policy_kwargs and activation is not None and activation.__name__ == name:
                return f"activation_kwargs go to activation_fn={name}: give that class's own arguments"
            if "activation_kwargs" in self.policy_kwargs and activation is None:
                return (
                    f"activation_kwargs go to activation_fn, here the default {name}: pass the activation they belong "
                    "to (e.g. activation_fn=nn.LeakyReLU for negative_slope), or drop them"
                )
        parameters = [name for name in inspect.signature(self.policy_class).parameters if name not in _POLICY_ARGUMENTS]
        return (
            f"{type(self).__name__}'s policy takes {', '.join(parameters)} "
            "(A2C/PPO's ortho_init is weight_init='orthogonal' here, or weight_init='default' for PyTorch's)"
        )

    def _make_buffer(self) -> None:
        self.rollout_buffer = TrajectoryBuffer(
            self._initial_buffer_size(), self.observation_space, self.action_space, device=self.device, n_envs=self.n_envs
        )
        # Reused when no env is truncated (the common case of the per-step loop)
        self._no_truncation = np.zeros(self.n_envs, dtype=bool)

    def _update_current_progress_remaining(self, num_timesteps: int, total_timesteps: int) -> None:
        """
        SB3's remaining progress (1 at the start of ``learn()``, 0 at ``total_timesteps``), clamped to [0, 1]: a rollout
        can end past ``total_timesteps`` (REINFORCE waits for its episodes to end, SARSA collects ``train_freq`` steps
        of every env), and a schedule must never be evaluated outside its range (``lin_`` would give a negative
        learning rate).

        :param num_timesteps: env steps taken so far
        :param total_timesteps: env steps of this ``learn()`` call (``learn(0)``: 0, nothing to do, all of it remaining)
        """
        if total_timesteps <= 0:
            self._current_progress_remaining = 1.0
            return
        self._current_progress_remaining = min(1.0, max(0.0, 1.0 - float(num_timesteps) / float(total_timesteps)))

    def _lr_decay_count(self) -> int:
        # (a model saved before this attribute existed: the episodes completed)
        episodes = getattr(self, "_episodes_before_rollout", self._completed_episodes)
        return episodes if self.lr_decay_unit == "episode" else self._n_updates

    def _update_learning_rates(self, schedules: Sequence[tuple[th.optim.Optimizer, Schedule, str]]) -> None:
        """
        Set each optimizer's learning rate to its schedule's value at the current progress, times the step decay,
        and log it.

        :param schedules: (optimizer, learning-rate schedule, logger key) triples
        """
        decay = self.lr_decay(self._lr_decay_count())
        for optimizer, schedule, key in schedules:
            learning_rate = schedule(self._current_progress_remaining) * decay
            update_learning_rate(optimizer, learning_rate)
            self.logger.record(key, learning_rate)

    def _update_slices(self, n_transitions: int) -> list[slice]:
        """
        :param n_transitions: the transitions of an update, in time order
        :return: what each gradient step of the update takes: all of them at once (``update_mode="batch"``: one step on
            their mean), or one at a time in time order (``"per_step"``: the book's updates, each with the full step size)
        """
        if self.update_mode == "batch":
            return [slice(None)]
        return [slice(index, index + 1) for index in range(n_transitions)]

    def _clip_gradients(self, parameters: Any) -> None:
        # None (e.g. passed to load()) means no clipping, as inf does
        if self.max_grad_norm is not None and math.isfinite(self.max_grad_norm):
            th.nn.utils.clip_grad_norm_(parameters, self.max_grad_norm)

    @abstractmethod
    def _sample_actions(self, obs: np.ndarray | dict[str, np.ndarray]) -> np.ndarray:
        """
        The behaviour policy of the per-step loop: one action per env, as a NumPy array the env accepts. Called
        without gradient (``th.no_grad``).

        :param obs: the current observations of all envs, as the VecEnv returned them
        """

    @abstractmethod
    def _rollout_complete(self, n_steps: int, n_episodes: int) -> bool:
        """
        Whether the next update has what it needs.

        :param n_steps: steps taken per env in this rollout
        :param n_episodes: episodes that ended in this rollout (all envs together)
        """

    def _on_episodes_end(self, n_episodes: int) -> None:
        """
        Called after each step in which episodes ended.

        :param n_episodes: how many ended (all envs together)
        """
        self._completed_episodes += n_episodes

    def _episode_ends(
        self, new_obs: Observations, dones: np.ndarray, infos: list[dict[str, Any]]
    ) -> tuple[np.ndarray, np.ndarray, dict[int, Any]]:
        """
        :return: which episodes ended with this step, which of those to bootstrap from (time-limit truncations,
            and episodes cut at ``max_episode_length``), and the final observations to bootstrap from, by env
        :raises ValueError: if a final observation bootstrapped from (a truncation's) holds NaN or ±inf, or has another
            shape than the observation space's
        """
        ends, truncated = dones, self._no_truncation
        final_observations: dict[int, Any] = {}
        if self.handle_timeout_termination and dones.any():
            truncated = np.zeros_like(dones)
            for idx in np.flatnonzero(dones):
                # The VecEnv sets TimeLimit.truncated = truncated and not terminated
                if not infos[idx].get("TimeLimit.truncated", False):
                    continue  # a termination: nothing is bootstrapped from its final observation
                final_obs = infos[idx].get("terminal_observation")
                if final_obs is None:
                    self._warn_truncation_without_final_observation(int(idx))
                    continue
                # Bootstrapped from: checked as the observations are (A2C refuses a wrong shape in predict)
                self._check_final_observation(final_obs, int(idx))
                truncated[idx] = True
                final_observations[int(idx)] = final_obs
        if self.max_episode_length is not None:
            overlong = ~dones & (self.rollout_buffer.episode_length + 1 >= self.max_episode_length)
            if overlong.any():
                warnings.warn(
                    f"Episodes of envs {np.flatnonzero(overlong).tolist()} reached max_episode_length="
                    f"{self.max_episode_length} steps without ending: {type(self).__name__} cut them there for "
                    "training (their returns end there, bootstrapped as at a time limit), but the envs go on: the next "
                    "episodes trained on start where these stopped, and the Monitor and callbacks do not count the "
                    "cuts. Wrap the env in gymnasium.wrappers.TimeLimit (which resets it), or raise max_episode_length.",
                    stacklevel=3,
                )
                ends = dones | overlong
                truncated = truncated | (overlong & self.handle_timeout_termination)
                if self.handle_timeout_termination:
                    final_observations.update({int(idx): select(new_obs, idx) for idx in np.flatnonzero(overlong)})
        return ends, truncated, final_observations

    def _check_final_observation(self, final_obs: Any, env_idx: int) -> None:
        """
        :param final_obs: a truncated episode's final observation (``infos[i]['terminal_observation']``), which its
            target bootstraps from
        :param env_idx: its env
        :raises ValueError: naming the env and the step, if it does not have the observation space's shape (it was
            broadcast into the buffer: shape (1,) into (3,) became [x, x, x]) or holds NaN or ±inf
        """
        field = "final observation (infos[i]['terminal_observation'])"
        observation_space = self.observation_space
        space_of: dict[Any, spaces.Space] = (
            {**observation_space.spaces} if isinstance(observation_space, spaces.Dict) else {None: observation_space}
        )
        values: dict[Any, Any] = final_obs if isinstance(final_obs, dict) else {None: final_obs}
        for key, space in space_of.items():
            shape = np.shape(values[key]) if key in values else None
            if space.shape is not None and shape != space.shape:
                name = field if key is None else f"{field}[{key!r}]"
                step = int(self.rollout_buffer.episode_length[env_idx]) + 1
                raise ValueError(
                    f"Env {env_idx} returned a {name} of shape {shape} at step {step} of its episode, where "
                    f"{type(self).__name__} bootstraps from it: the observation space {space} has shape {space.shape}. "
                    "Make the env return final observations of the space's shape (a VecEnv of your own: the "
                    "observation before its automatic reset)"
                )
        if not all_finite(final_obs):
            batch = (
                {key: np.asarray(obs)[None] for key, obs in final_obs.items()}
                if isinstance(final_obs, dict)
                else np.asarray(final_obs)[None]
            )
            # (VecCheckNan checks what step() returns, not the infos)
            find = "It is the observation the env returned at that step, before the VecEnv reset it: check the env there."
            self._raise_non_finite(batch, field, env_indices=[env_idx], find=find)

    def _warn_truncation_without_final_observation(self, env_idx: int) -> None:
        """A truncation without ``terminal_observation`` (a VecEnv of the user's) has nothing to bootstrap from."""
        warnings.warn(
            f"Env {env_idx} reported a time-limit truncation (infos[i]['TimeLimit.truncated']) without its final "
            "observation (infos[i]['terminal_observation']): there is nothing to bootstrap from, so "
            f"{type(self).__name__} trains it as a termination. SB3's VecEnvs put it there; a VecEnv of your own should "
            "too (or pass handle_timeout_termination=False to treat every truncation as a termination)",
            stacklevel=4,
        )

    def _raise_non_finite(
        self,
        values: Observations,
        field: str,
        where: str = "",
        after_reset: np.ndarray | None = None,
        env_indices: Sequence[int] | None = None,
        find: str = FIND_NON_FINITE,
    ) -> None:
        """
        Raise a ValueError naming the env, the step and the field of a NaN or ±inf an env returned (an observation, a
        reward, or a final observation). The callers raise it before the step is stored, so no update ever sees the
        value and the model stays as its last update left it.

        :param values: the batch (first axis: envs) holding a non-finite entry
        :param field: what it is (``"observation"``, ``"reward"``, ...)
        :param where: when it was returned, if not at the current step of the env's episode
        :param after_reset: envs whose episode ended at this step (their observation is a new episode's first)
        :param env_indices: the env index of each row of ``values`` (default: row i is env i)
        :param find: how to find where the value comes from
        :raises ValueError: always
        """
        row, key, value = non_finite_entries(values)
        env_idx = int(env_indices[row]) if env_indices is not None else row
        if key is not None:
            field = f"{field}[{key!r}]"
        if not where:
            step = int(self.rollout_buffer.episode_length[env_idx]) + 1
            where = (
                f"the first observation of a new episode (after the reset that ended step {step} of the previous one)"
                if after_reset is not None and after_reset[env_idx]
                else f"step {step} of its episode"
            )
        raise ValueError(
            f"Env {env_idx} returned a non-finite {field} ({value}) at {where}, {self.num_timesteps} env steps into "
            f"training (all envs together). {type(self).__name__} stopped before storing or training on it: the "
            f"model's parameters are those of its last update, and it can be saved. {find}"
        )

    def collect_rollouts(  # type: ignore[override]
        self,
        env: VecEnv,
        callback: BaseCallback,
        rollout_buffer: TrajectoryBuffer,
        n_rollout_steps: int | None = None,
    ) -> bool:
        """
        Step the envs with the behaviour policy and append the transitions to ``rollout_buffer``, which keeps
        those of earlier rollouts not trained on yet.

        :param env: the training environment
        :param callback: callback called at each step (and at the beginning and end of the rollout)
        :param rollout_buffer: buffer to fill
        :param n_rollout_steps: steps per env to collect; ``None`` (what ``learn`` passes) stops when the
            algorithm's update has what it needs (``n_episodes`` episodes for REINFORCE, ``train_freq`` steps for
            SARSA)
        :return: False if the callback stopped training
        """
        assert self._last_obs is not None, "No previous observation was provided"
        self.policy.set_training_mode(False)
        self._episodes_before_rollout = self._completed_episodes
        callback.on_rollout_start()
        n_steps, n_episodes = 0, 0
        while True:
            if n_rollout_steps is None:
                if self._rollout_complete(n_steps, n_episodes):
                    break
            elif n_steps >= n_rollout_steps:
                break
            with th.no_grad():
                actions = self._sample_actions(self._last_obs)  # type: ignore[arg-type]
            env_actions = actions
            if self._action_offset is not None:
                # The buffer and the networks use indices 0..n-1, the env its own values start..start+n-1
                env_actions = actions + self._action_offset
            elif isinstance(self.action_space, spaces.Box):
                # The Gaussian is unbounded: clip what the env sees, store what was sampled
                env_actions = np.clip(actions, self.action_space.low, self.action_space.high)
            new_obs, rewards, dones, infos = env.step(env_actions)
            # A VecEnv of the user's may return 0/1 integers or floats: as an index, [1, 0] would select envs 1 and 0
            dones = np.asarray(dones, dtype=bool)
            self.num_timesteps += env.num_envs
            n_steps += 1

            # The callback runs before the step is stored, as in SB3's loops: one that changes rewards (or
            # observations) in place in _on_step, to shape or rescale them, changes what is trained on
            callback.update_locals(locals())
            continue_training = callback.on_step()

            # Nothing is stored or trained on if a value is NaN or ±inf: the model stays as its last update left it.
            # Checked after the callback, on the values that would be stored; final observations in _episode_ends
            if not (np.isfinite(rewards).all() and all_finite(new_obs)):  # type: ignore[arg-type]
                if not np.isfinite(rewards).all():
                    self._raise_non_finite(rewards, "reward")
                self._raise_non_finite(new_obs, "observation", after_reset=dones)  # type: ignore[arg-type]
            ends, truncated, final_observations = self._episode_ends(new_obs, dones, infos)  # type: ignore[arg-type]
            # Stored even when the callback stops training, so that the buffer and the envs stay in step: the next
            # learn() goes on from the step the envs are at
            rollout_buffer.add(self._last_obs, actions, rewards, ends, truncated, final_observations)  # type: ignore[arg-type]
            self._last_obs = new_obs  # type: ignore[assignment]
            # The training episodes' starts: an episode cut at max_episode_length starts a new one where the env goes on
            # (with the env's dones, the next learn() took the cut for the start of an episode missing from the buffer)
            self._last_episode_starts = ends
            self._update_info_buffer(infos, dones)
            if ends.any():
                n_episodes += int(ends.sum())
                self._on_episodes_end(int(ends.sum()))
            if not continue_training:
                return False

        callback.update_locals(locals())
        callback.on_rollout_end()
        return True

    def learn(
        self: SelfClassicOnPolicyAlgorithm,
        total_timesteps: int,
        callback: MaybeCallback = None,
        log_interval: int = 1,
        tb_log_name: str = "ClassicOnPolicyAlgorithm",
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
    ) -> SelfClassicOnPolicyAlgorithm:
        if log_interval is not None:
            # Before anything is set up: SB3's loop would divide by it after the first rollout
            check_positive_int(
                "log_interval",
                log_interval,
                hint=f"Pass the updates between two logger dumps{self._log_interval_choices()} or None (no dumps)",
            )
        if self.env is None:
            # (SB3 asserts, with no message)
            raise ValueError(
                f"{type(self).__name__}.learn: this model has no env to train on (it was loaded without one): pass env=... "
                f"to {type(self).__name__}.load, or call model.set_env(env) first"
            )
        iteration = 0
        total_timesteps, callback = self._setup_learn(
            total_timesteps, callback, reset_num_timesteps, tb_log_name, progress_bar
        )
        callback.on_training_start(locals(), globals())
        assert self.env is not None

        while self.num_timesteps < total_timesteps:
            if not self.collect_rollouts(self.env, callback, self.rollout_buffer):
                break
            iteration += 1
            self._update_current_progress_remaining(self.num_timesteps, total_timesteps)
            self.train()
            # After the update (SB3's on-policy algorithms dump before it): a dump's train/ values are those of the
            # rollout it reports, and no step is dumped twice
            if log_interval is not None and iteration % log_interval == 0:
                self.dump_logs(iteration)

        if log_interval is not None and self.logger.name_to_value:
            # What was recorded since the last dump is in the logs when learn() returns, however short the run
            # (log_interval=None: no dumps at all, as in SB3)
            self.dump_logs(iteration)
        callback.on_training_end()
        return self

    def dump_logs(self, iteration: int = 0) -> None:
        """
        SB3's ``OnPolicyAlgorithm.dump_logs``, with ``time/episodes``: the episodes completed so far, all envs
        together, as SB3's DQN logs it (the count the episode-based decays use).

        :param iteration: the rollouts so far in this ``learn()`` call (``time/iterations``)
        """
        self.logger.record("time/episodes", self._completed_episodes, exclude="tensorboard")
        super().dump_logs(iteration)

    def _log_interval_choices(self) -> str:
        """:return: the values of ``learn(log_interval=...)`` beyond a count and None, for its error message"""
        return ""

    def _setup_learn(
        self,
        total_timesteps: int,
        callback: MaybeCallback = None,
        reset_num_timesteps: bool = True,
        tb_log_name: str = "run",
        progress_bar: bool = False,
    ) -> tuple[int, BaseCallback]:
        saved_envs = None if self._last_episode_starts is None else len(self._last_episode_starts)
        reason = None
        if not reset_num_timesteps and self._last_obs is not None:
            if saved_envs not in (None, self.n_envs):
                # load(..., env=<another number of envs>, force_reset=False): the file's last observations are of
                # other envs (NumPy's "operands could not be broadcast" otherwise)
                reason = (
                    f"This model's file holds the last observations of {saved_envs} envs, and its env has {self.n_envs}: "
                    f"{type(self).__name__} resets the envs. (load(..., force_reset=False) continues the saved envs' "
                    "episodes only with the same number of envs"
                )
            elif self._episodes_missing_their_start():
                # A model loaded with force_reset=False: the file has the envs' last observations but not the buffer,
                # so the episodes in progress would be trained from where the file left them as if they began there
                # (the wrong t in γ^t and in episode lengths, REINFORCE's returns of a part of an episode)
                reason = (
                    "The episodes in progress when this model was saved are not in its file (the buffer is not saved): "
                    f"{type(self).__name__} resets the envs to train on whole episodes. (load(..., force_reset=False) "
                    "cannot continue an episode here"
                )
        if reason is not None:
            warnings.warn(f"{reason}; the learned parameters and counts are kept)", stacklevel=3)
            self._last_obs = None
        if reset_num_timesteps or self._last_obs is None:
            # The envs are about to be reset: the episodes in progress in the buffer cannot be continued
            self.rollout_buffer.reset()
        total_timesteps, callback = super()._setup_learn(
            total_timesteps, callback, reset_num_timesteps, tb_log_name, progress_bar
        )
        if not all_finite(self._last_obs):  # type: ignore[arg-type]
            self._raise_non_finite(self._last_obs, "observation", "the first observation after the reset")  # type: ignore[arg-type]
        # The progress of this learn() call from its first step (the schedules the rollout reads: a linear ε)
        self._update_current_progress_remaining(self.num_timesteps, total_timesteps)
        self._on_learn_start()
        return total_timesteps, callback

    def _episodes_missing_their_start(self) -> bool:
        """:return: whether an env is in the middle of an episode whose earlier steps the buffer does not hold"""
        starts = self._last_episode_starts
        if starts is None:
            return True
        return bool(np.any(~np.asarray(starts, dtype=bool) & (self.rollout_buffer.episode_length == 0)))

    def _on_learn_start(self) -> None:
        """Called by ``learn()`` once set up (``num_timesteps`` reset or not, the progress of this call at its start)."""

    def set_env(self, env: GymEnv, force_reset: bool = True) -> None:
        """
        Set the environment to learn from. Unlike SB3's on-policy algorithms, the number of envs may change:
        the buffer is rebuilt for it (the episodes in progress are dropped with the old envs).

        :param env: the new environment (same observation and action spaces)
        :param force_reset: reset the envs before training (required when the number of envs changes)
        """
        env = self._wrap_env(env, self.verbose)
        # Before anything changes: a model whose env was refused keeps its envs and buffer
        check_for_correct_spaces(env, self.observation_space, self.action_space)
        if env.num_envs != self.n_envs:
            if not force_reset:
                raise ValueError(
                    f"set_env(force_reset=False) needs the same number of envs ({self.n_envs}), got {env.num_envs}: "
                    "pass force_reset=True to start new episodes in the new envs"
                )
            self.n_envs = env.num_envs
            self._make_buffer()
        super().set_env(env, force_reset=force_reset)
