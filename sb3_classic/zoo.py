"""
Registration of REINFORCE and n-step SARSA with rl-zoo3 (``python -m rl_zoo3.train --algo reinforce|nstep_sarsa``).

rl-zoo3 has no plug-in mechanism: its commands take ``--algo`` choices from ``rl_zoo3.utils.ALGOS``, Optuna
search spaces from ``rl_zoo3.hyperparams_opt``, and default hyperparameters from its own package folder.
``register()`` adds this package to each of them. It runs by itself when ``rl_zoo3`` is imported: the wheel installs
``_sb3_classic_zoo.pth``, whose start-up hook (``_sb3_classic_zoo.py``) calls it then, and imports nothing heavy
before. Call it yourself only where that hook does not run (``python -S``).

What ``register()`` changes in rl-zoo3, and nothing else:

- ``rl_zoo3.utils.ALGOS`` (also ``rl_zoo3.ALGOS``) gains ``"reinforce"`` and ``"nstep_sarsa"``;
- ``rl_zoo3.hyperparams_opt.HYPERPARAMS_SAMPLER`` and ``HYPERPARAMS_CONVERTER`` gain their Optuna search spaces
  (``-optimize``) and the conversion of a stored trial back into constructor arguments (``--trial-id``), both in
  ``sb3_classic.zoo_search``;
- ``ExperimentManager.objective``, for these two algorithms, lets those search spaces see the YAML entry a trial
  tunes (a streaming or ``LinearPolicy`` entry has its own space);
- ``ExperimentManager._load_pretrained_agent`` (``-i``), for these two algorithms, refuses a YAML entry whose
  ``policy_kwargs`` differ from the saved model's (the zoo drops them but passes the entry's other settings);
- ``ExperimentManager.__init__`` defaults ``config`` to this package's YAML for these two algorithms (``-conf``
  still wins), and, for them, sets PyTorch to one thread on the CPU unless the user chose a number: see
  ``one_thread_unless_chosen``;
- ``ExperimentManager._preprocess_schedules`` also reads ``value_learning_rate`` (REINFORCE's second learning rate)
  as the zoo reads ``learning_rate``: ``lin_0.01`` for a linear schedule; and it refuses a number that YAML read as a
  string (``learning_rate: 1e-3``, which needs ``!!float 1e-3``), naming the setting and the fix, where the zoo failed
  with "not enough values to unpack" (or passed the string on);
- ``ExperimentManager.create_callbacks``, for these two algorithms, builds sb3-contrib's ``MaskableEvalCallback``
  instead of SB3's ``EvalCallback`` when the evaluation env has action masks (``--eval-freq`` evaluates with them);
- ``rl_zoo3.create_test_env`` (the name ``enjoy`` imports) remembers an env it makes that has action masks, and a model
  of these two algorithms loaded after it predicts with ``action_masks=get_action_masks(env)`` of that env, unless
  given masks (``enjoy`` chooses legal actions): see ``_patch_enjoy``;
- the names a YAML's ``policy_kwargs`` string may use (the zoo evaluates it in ``rl_zoo3.exp_manager``'s namespace,
  which has ``th`` and ``nn``), and a ``-params`` value (evaluated in ``rl_zoo3.utils``'s), gain ``TileCoding``, the
  book's features (``features_extractor_class=TileCoding``), and ``ObGD``, the streaming optimizer (``optimizer_class=ObGD``).
"""

import argparse
import contextlib
import functools
import importlib
import inspect
import sys
import weakref
from collections.abc import Callable, Iterator
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import torch as th
from sb3_contrib.common.maskable.callbacks import MaskableEvalCallback
from stable_baselines3.common.callbacks import EvalCallback
from stable_baselines3.common.save_util import load_from_zip_file
from stable_baselines3.common.utils import get_device
from stable_baselines3.common.vec_env import VecEnv

from sb3_classic.common.masking import get_action_masks, is_masking_supported
from sb3_classic.common.obgd import ObGD
from sb3_classic.common.threads import threads_chosen
from sb3_classic.common.tile_coding import TileCoding
from sb3_classic.reinforce import REINFORCE
from sb3_classic.sarsa import NStepSARSA
from sb3_classic.zoo_search import CONVERTERS, SAMPLERS, searched_entry

#: The rl-zoo3 versions this module patches (the ``zoo`` extra's requirement)
SUPPORTED_RL_ZOO3 = ">=2.9,<3"

#: ``--algo`` names and their classes
ALGORITHMS: dict[str, type[REINFORCE] | type[NStepSARSA]] = {"reinforce": REINFORCE, "nstep_sarsa": NStepSARSA}

#: Names a YAML's ``policy_kwargs`` string may use besides the zoo's own (``th``, ``nn``, ...)
YAML_NAMES: dict[str, Any] = {"TileCoding": TileCoding, "ObGD": ObGD}

# Where the YAMLs are: inside the installed package (the wheel's force-include), else the source tree's hyperparams/
# (an editable install, or a checkout on sys.path)
_HYPERPARAMS_DIRS = (Path(__file__).parent / "hyperparams", Path(__file__).parent.parent / "hyperparams")

# Marks what register() has patched, so that it patches each thing once
_PATCHED = "_sb3_classic_zoo"
# True while register() imports rl_zoo3
_registering = False


class ZooCompatibilityError(ImportError):
    """The installed rl-zoo3 lacks something ``register()`` patches."""


def hyperparams_path(name: str) -> Path:
    """
    The package's rl-zoo3 YAMLs, in ``hyperparams/`` of a checkout and inside the installed package: the path for
    ``-conf`` from any folder (``-conf "$(python -m sb3_classic.zoo nstep_sarsa_streaming)"``).

    :param name: ``"reinforce"`` or ``"nstep_sarsa"`` (the default hyperparameters, which the zoo reads without
        ``-conf``), or ``"reinforce_streaming"``, ``"nstep_sarsa_streaming"`` (the streaming recipe's)
    :return: that YAML's path
    :raises ValueError: for another name
    """
    names = [*ALGORITHMS, *(f"{algo}_streaming" for algo in ALGORITHMS)]
    if name not in names:
        raise ValueError(f"{name!r} must be one of {', '.join(map(repr, names))}")
    for directory in _HYPERPARAMS_DIRS:
        path = directory / f"{name}.yml"
        if path.is_file():
            return path
    searched = " or ".join(str(directory) for directory in _HYPERPARAMS_DIRS)
    raise FileNotFoundError(f"{name}.yml is in neither {searched}: reinstall sb3_classic")


def _incompatible(version: str, problem: str) -> ZooCompatibilityError:
    return ZooCompatibilityError(
        f"sb3_classic cannot register reinforce and nstep_sarsa with the installed rl_zoo3 {version}: {problem}. "
        f"sb3_classic supports rl_zoo3{SUPPORTED_RL_ZOO3}: pip install 'rl_zoo3{SUPPORTED_RL_ZOO3}'"
    )


def _dict_attribute(module: ModuleType, name: str, version: str) -> dict[str, Any]:
    """
    :param module: a module of rl_zoo3
    :param name: the name of one of its dicts
    :param version: rl_zoo3's version, for the error message
    :return: the dict
    """
    table = getattr(module, name, None)
    if not isinstance(table, dict):
        raise _incompatible(version, f"{module.__name__}.{name} is not a dict")
    return table


def _zoo_targets() -> tuple[dict[str, Any], dict[str, Any], dict[str, Any], type, list[ModuleType]]:
    """
    Import what ``register()`` patches, checking that it is there and has the expected shape.

    :return: ``ALGOS``, ``HYPERPARAMS_SAMPLER``, ``HYPERPARAMS_CONVERTER``, ``ExperimentManager``, and the modules
        ``rl_zoo3.exp_manager`` (where the zoo evaluates a YAML's ``policy_kwargs`` string, and builds its
        ``EvalCallback``), ``rl_zoo3.utils`` (where it evaluates a ``-params`` value, in ``StoreDict``) and ``rl_zoo3``
        (whose ``create_test_env`` ``enjoy`` imports)
    """
    try:
        import rl_zoo3
    except ImportError as error:
        raise ImportError(f"rl_zoo3 is not installed ({error}): pip install 'sb3_classic[zoo]'") from error
    version = str(getattr(rl_zoo3, "__version__", "of unknown version"))
    try:
        utils, hyperparams_opt, exp_manager = (
            importlib.import_module(f"rl_zoo3.{name}") for name in ("utils", "hyperparams_opt", "exp_manager")
        )
    except ImportError as error:
        raise _incompatible(version, f"importing it failed ({error})") from None

    algos = _dict_attribute(utils, "ALGOS", version)
    samplers = _dict_attribute(hyperparams_opt, "HYPERPARAMS_SAMPLER", version)
    converters = _dict_attribute(hyperparams_opt, "HYPERPARAMS_CONVERTER", version)
    manager = getattr(exp_manager, "ExperimentManager", None)
    if not inspect.isclass(manager):
        raise _incompatible(version, "rl_zoo3.exp_manager.ExperimentManager is missing")
    parameters = inspect.signature(manager.__init__).parameters
    if not {"algo", "config"} <= parameters.keys():
        raise _incompatible(version, "ExperimentManager.__init__ has no 'algo' and 'config' arguments")
    if not isinstance(inspect.getattr_static(manager, "_preprocess_schedules", None), staticmethod):
        raise _incompatible(version, "ExperimentManager._preprocess_schedules is not a static method")
    if not callable(getattr(manager, "create_callbacks", None)) or getattr(exp_manager, "EvalCallback", None) is None:
        raise _incompatible(version, "ExperimentManager.create_callbacks or rl_zoo3.exp_manager.EvalCallback is missing")
    for method in ("objective", "_load_pretrained_agent"):
        if not callable(getattr(manager, method, None)):
            raise _incompatible(version, f"ExperimentManager.{method} is missing")
    if not callable(getattr(rl_zoo3, "create_test_env", None)):
        raise _incompatible(version, "rl_zoo3.create_test_env is missing")
    return algos, samplers, converters, manager, [exp_manager, utils, rl_zoo3]


def one_thread_unless_chosen(num_threads: int | None, device: th.device | str, verbose: int = 1) -> bool:
    """
    One PyTorch thread for the whole process of a zoo run on the CPU, unless the user chose a number (why:
    ``sb3_classic.common.threads``). A number is chosen by ``--num-threads N``, or as ``threads_chosen`` says (the
    environment's ``OMP_NUM_THREADS``, a call of ``torch.set_num_threads``); an ``ExperimentManager`` built in Python
    without the zoo's command-line arguments (no ``num_threads`` in them) leaves the threads alone.

    :param num_threads: the zoo's ``--num-threads`` (``-1``, its default: not chosen), or None outside its command line
    :param device: the zoo's ``--device``
    :param verbose: print what was set (0: nothing)
    :return: whether it set one thread
    """
    chosen = num_threads is None or num_threads > 0 or threads_chosen()
    if chosen or get_device(device).type != "cpu":
        return False
    th.set_num_threads(1)
    if verbose > 0:
        print("sb3_classic: one PyTorch thread on the CPU (faster for these small networks); --num-threads N for another")
    return True


def _patch_experiment_manager(manager: type) -> None:
    """
    Make ``ExperimentManager`` read this package's YAML for its algorithms when no ``config`` (``-conf``) is given,
    and train them with one PyTorch thread on the CPU unless a number was chosen (``one_thread_unless_chosen``).
    """
    original_init = manager.__init__  # type: ignore[misc]
    if getattr(original_init, _PATCHED, False):
        return
    signature = inspect.signature(original_init)

    @functools.wraps(original_init)
    def __init__(*args: Any, **kwargs: Any) -> None:
        bound = signature.bind(*args, **kwargs)
        algo = bound.arguments.get("algo")
        if algo in ALGORITHMS and bound.arguments.get("config") is None:
            bound.arguments["config"] = str(hyperparams_path(algo))
        original_init(*bound.args, **bound.kwargs)
        if algo in ALGORITHMS:
            one_thread_unless_chosen(
                getattr(bound.arguments.get("args"), "num_threads", None),
                bound.arguments.get("device", "auto"),
                bound.arguments.get("verbose", 1),
            )

    setattr(__init__, _PATCHED, True)
    manager.__init__ = __init__  # type: ignore[misc]


def _patch_objective(manager: type) -> None:
    """
    Let the search spaces of these two algorithms see the YAML entry a trial tunes (``zoo_search.searched_entry``):
    the zoo gives its samplers the trial, the size of a Box action space and the number of envs, not the entry, and a
    streaming or ``LinearPolicy`` entry trains with other settings than a network's.
    """
    original = manager.objective  # type: ignore[attr-defined]
    if getattr(original, _PATCHED, False):
        return

    @functools.wraps(original)
    def objective(self: Any, trial: Any) -> float:
        if self.algo not in ALGORITHMS:
            return original(self, trial)
        with searched_entry(self._hyperparams):
            return original(self, trial)

    setattr(objective, _PATCHED, True)
    manager.objective = objective  # type: ignore[attr-defined]


def _same_setting(first: Any, second: Any) -> bool:
    """
    :return: whether two values of a setting are the same, as a saved model gives them back: a tuple as a list (SB3
        saves JSON-able ``policy_kwargs`` as JSON), arrays by their elements
    """
    if isinstance(first, dict) and isinstance(second, dict):
        return first.keys() == second.keys() and all(_same_setting(first[key], second[key]) for key in first)
    if isinstance(first, list | tuple) and isinstance(second, list | tuple):
        return len(first) == len(second) and all(map(_same_setting, first, second))
    if isinstance(first, np.ndarray) or isinstance(second, np.ndarray):
        return np.shape(first) == np.shape(second) and bool(np.all(np.asarray(first) == np.asarray(second)))
    try:
        return bool(first == second)
    except (TypeError, ValueError):  # (a comparison without one truth value)
        return False


def policy_kwargs_differences(entry: dict[str, Any], saved: dict[str, Any]) -> list[str]:
    """
    :param entry: a YAML entry's ``policy_kwargs`` (evaluated)
    :param saved: a saved model's ``policy_kwargs``
    :return: each of the entry's settings that the model has otherwise (of a dict, such as ``optimizer_kwargs``, each
        key the entry sets), and the model's ``optimizer_class`` where the entry leaves it to the default, as "name:
        the entry's, the model's"
    """
    names = [*entry, *(["optimizer_class"] if "optimizer_class" in saved and "optimizer_class" not in entry else [])]
    differences = []
    for name in names:
        value, found = entry.get(name), saved.get(name)
        if isinstance(value, dict) and isinstance(found, dict):
            differences += [
                f"{name}[{key!r}]: {item!r} in the YAML, {found.get(key)!r} in the model"
                for key, item in value.items()
                if not _same_setting(item, found.get(key))
            ]
        elif not _same_setting(value, found):
            differences.append(f"{name}: {value!r} in the YAML, {found!r} in the model")
    return differences


def _patch_load_pretrained_agent(manager: type) -> None:
    """
    Refuse to continue a model (``-i``) with a YAML entry whose ``policy_kwargs`` differ from the model's. The zoo
    keeps the model's networks and optimizer and drops the entry's ``policy_kwargs``, but passes its other settings,
    chosen for that network and optimizer: a streaming entry's ``learning_rate: 1.0`` (ObGD's α) given to a model
    trained with Adam diverged without a word.
    """
    original = manager._load_pretrained_agent  # type: ignore[attr-defined]
    if getattr(original, _PATCHED, False):
        return

    @functools.wraps(original)
    def _load_pretrained_agent(self: Any, hyperparams: dict[str, Any], env: VecEnv) -> Any:
        entry = hyperparams.get("policy_kwargs")
        if self.algo in ALGORITHMS and isinstance(entry, dict) and entry:
            data, _, _ = load_from_zip_file(self.trained_agent, device="cpu")
            differences = policy_kwargs_differences(entry, (data or {}).get("policy_kwargs") or {})
            if differences:
                raise ValueError(
                    f"-i {self.trained_agent}: the YAML entry's policy_kwargs differ from the model's ("
                    + "; ".join(differences)
                    + "). The zoo continues a model with its own networks and optimizer, but with the entry's other "
                    "settings (learning rates among them), chosen for the entry's: continue with the settings the "
                    "model was trained with (its -conf, -params or --trial-id), or train a new model without -i"
                )
        return original(self, hyperparams, env)

    setattr(_load_pretrained_agent, _PATCHED, True)
    manager._load_pretrained_agent = _load_pretrained_agent  # type: ignore[attr-defined]


def yaml_float_string(value: Any) -> str | None:
    """
    :param value: a setting as PyYAML read it
    :return: for a number that PyYAML read as a string (``1e-3``: YAML 1.1's floats need a dot, ``1.0e-3``), what
        to write instead (``!!float 1e-3``, or ``0.001``); else None
    """
    if not isinstance(value, str):
        return None
    try:
        number = float(value)
    except ValueError:
        return None
    return f"{value!r} is read as a string by YAML: write !!float {value}, or {number!r}"


def _patch_preprocess_schedules(manager: type) -> None:
    """
    Make ``ExperimentManager`` read ``value_learning_rate`` as it reads ``learning_rate`` (``lin_0.01``), and refuse a
    number that YAML read as a string (``learning_rate: 1e-3``) with the setting's name and the fix
    (``yaml_float_string``): the zoo split it as a schedule's name (``not enough values to unpack``) or passed it on.
    """
    original = manager._preprocess_schedules  # type: ignore[attr-defined]
    if getattr(original, _PATCHED, False):
        return

    @functools.wraps(original)
    def _preprocess_schedules(hyperparams: dict[str, Any]) -> dict[str, Any]:
        # Every setting of the entry (the zoo's YAML and -params) passes here once, before the zoo reads any
        for key, value in hyperparams.items():
            fix = yaml_float_string(value)
            if fix is not None:
                raise ValueError(f"{key}: {fix} (in the hyperparameters of rl-zoo3's YAML or -params)")
        hyperparams = original(hyperparams)
        value = hyperparams.get("value_learning_rate")
        if isinstance(value, (str, int, float)):
            # The zoo's own parsing of learning_rate (a number, or "lin_<initial value>"), for REINFORCE's second one
            hyperparams["value_learning_rate"] = original({"learning_rate": value})["learning_rate"]
        return hyperparams

    setattr(_preprocess_schedules, _PATCHED, True)
    manager._preprocess_schedules = staticmethod(_preprocess_schedules)  # type: ignore[attr-defined]


def maskable_eval_callback(eval_env: VecEnv, *args: Any, **kwargs: Any) -> EvalCallback:
    """
    SB3's ``EvalCallback`` for an env without action masks, sb3-contrib's ``MaskableEvalCallback`` (which evaluates
    with ``action_masks=get_action_masks(eval_env)``) for one that has them.

    :param eval_env: the evaluation env
    :param args: ``EvalCallback``'s other arguments
    :param kwargs: ``EvalCallback``'s other arguments
    :return: the callback
    """
    if is_masking_supported(eval_env):
        return MaskableEvalCallback(eval_env, *args, **kwargs)
    return EvalCallback(eval_env, *args, **kwargs)


@contextlib.contextmanager
def _eval_callback_named(module: ModuleType, factory: Callable[..., EvalCallback]) -> Iterator[None]:
    """Make ``module``'s name ``EvalCallback`` build ``factory``'s callback while the block runs."""
    namespace = vars(module)
    original = namespace["EvalCallback"]
    namespace["EvalCallback"] = factory
    try:
        yield
    finally:
        namespace["EvalCallback"] = original


def _patch_eval_callback(manager: type, exp_manager: ModuleType) -> None:
    """
    Make ``ExperimentManager.create_callbacks`` build, for these algorithms, the evaluation callback of
    ``maskable_eval_callback`` instead of SB3's ``EvalCallback`` (the zoo's ``--eval-freq``): the same arguments, and
    evaluations with the masks of an env that has them. The zoo's other algorithms keep its ``EvalCallback``.
    """
    original = manager.create_callbacks  # type: ignore[attr-defined]
    if getattr(original, _PATCHED, False):
        return

    @functools.wraps(original)
    def create_callbacks(self: Any) -> None:
        if self.algo not in ALGORITHMS:
            return original(self)
        with _eval_callback_named(exp_manager, maskable_eval_callback):
            return original(self)

    setattr(create_callbacks, _PATCHED, True)
    manager.create_callbacks = create_callbacks  # type: ignore[attr-defined]


# The env with action masks that rl_zoo3.create_test_env made last (enjoy's), while it is alive
_test_env: "weakref.ref[VecEnv] | None" = None


def _predict_with_masks_of(model: Any, env: VecEnv) -> None:
    """
    Make ``model.predict`` pass ``action_masks=get_action_masks(env)`` when it is given no masks and the
    observations are ``env``'s (one per env).
    """
    original_predict = model.predict

    @functools.wraps(original_predict)
    def predict(
        observation: np.ndarray | dict[str, np.ndarray],
        state: tuple[np.ndarray, ...] | None = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = False,
        action_masks: np.ndarray | None = None,
    ) -> tuple[np.ndarray, tuple[np.ndarray, ...] | None]:
        first = next(iter(observation.values())) if isinstance(observation, dict) else observation
        if action_masks is None and len(np.asarray(first)) == env.num_envs:
            action_masks = get_action_masks(env)
        return original_predict(observation, state, episode_start, deterministic, action_masks=action_masks)

    model.predict = predict


def _patch_enjoy(zoo_package: ModuleType) -> None:
    """
    rl-zoo3's ``enjoy`` makes its env with ``rl_zoo3.create_test_env``, loads the model with ``ALGOS[algo].load`` and
    calls ``model.predict(obs, ...)`` without masks. Wrap that ``create_test_env`` (only ``enjoy`` imports it from the
    package; ``record_video`` and ``push_to_hub`` take ``rl_zoo3.utils``'s) so that it remembers an env it makes with
    action masks, and these algorithms' ``load`` so that a model loaded while that env is alive, with its action space,
    predicts with its masks (``_predict_with_masks_of``). Nothing changes for an env without masks, nor for a model
    loaded before such an env was made, nor for the zoo's other algorithms.
    """
    original_create = vars(zoo_package)["create_test_env"]
    if getattr(original_create, _PATCHED, False):
        return

    @functools.wraps(original_create)
    def create_test_env(*args: Any, **kwargs: Any) -> VecEnv:
        global _test_env
        env = original_create(*args, **kwargs)
        _test_env = weakref.ref(env) if is_masking_supported(env) else None
        return env

    setattr(create_test_env, _PATCHED, True)
    vars(zoo_package)["create_test_env"] = create_test_env

    for algo_class in ALGORITHMS.values():
        load = inspect.getattr_static(algo_class, "load")
        if not getattr(load.__func__, _PATCHED, False):
            algo_class.load = _loading_with_masks(load.__func__)  # type: ignore[assignment]


def _loading_with_masks(original_load: Callable[..., Any]) -> classmethod:
    """:return: ``original_load`` (a ``load`` classmethod's function) whose model predicts with the masks of the
    env ``rl_zoo3.create_test_env`` made last, while it is alive and has the model's action space"""

    @functools.wraps(original_load)
    def load(cls: type, *args: Any, **kwargs: Any) -> Any:
        model = original_load(cls, *args, **kwargs)
        env = _test_env() if _test_env is not None else None
        if env is not None and model.action_space == env.action_space:
            _predict_with_masks_of(model, env)
        return model

    setattr(load, _PATCHED, True)
    return classmethod(load)


def register() -> None:
    """
    Register ``reinforce`` and ``nstep_sarsa`` with rl-zoo3: algorithms, Optuna samplers and converters, default
    YAMLs, and the names their YAMLs' ``policy_kwargs`` may use (``TileCoding``, ``ObGD``). Idempotent; it checks the installed
    rl-zoo3 first and changes nothing if that lacks any of them.

    :raises ZooCompatibilityError: (an ``ImportError``) if the installed rl-zoo3 lacks what this patches; the
        message names its version and the supported range
    :raises ImportError: if rl-zoo3 is not installed
    """
    global _registering
    # The start-up hook calls register() when rl_zoo3 is imported, which _zoo_targets() may be doing: that nested call
    # leaves the work (and any error) to this one
    if _registering:
        return
    _registering = True
    try:
        algos, samplers, converters, manager, (exp_manager, utils, zoo_package) = _zoo_targets()
    finally:
        _registering = False
    # A name the zoo itself defines there is left alone
    for namespace in (vars(exp_manager), vars(utils)):
        for name, value in YAML_NAMES.items():
            namespace.setdefault(name, value)
    algos.update(ALGORITHMS)
    samplers.update(SAMPLERS)
    converters.update(CONVERTERS)
    _patch_experiment_manager(manager)
    _patch_objective(manager)
    _patch_load_pretrained_agent(manager)
    _patch_preprocess_schedules(manager)
    _patch_eval_callback(manager, exp_manager)
    _patch_enjoy(zoo_package)


def main(argv: list[str] | None = None) -> int:
    """
    ``python -m sb3_classic.zoo NAME``: print the path of the package's YAML ``NAME`` (``hyperparams_path``), for
    ``-conf`` from any folder.

    :param argv: the arguments (None: the command line's)
    :return: the exit status
    """
    parser = argparse.ArgumentParser(
        prog="python -m sb3_classic.zoo", description="Print the path of one of the package's rl-zoo3 YAMLs, for -conf."
    )
    parser.add_argument("name", help="reinforce, nstep_sarsa, reinforce_streaming or nstep_sarsa_streaming")
    args = parser.parse_args(argv)
    try:
        print(hyperparams_path(args.name))
    except ValueError as error:
        parser.error(str(error))
    return 0


if __name__ == "__main__":
    sys.exit(main())
