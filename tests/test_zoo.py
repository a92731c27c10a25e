"""
rl-zoo3 integration (sb3_classic/zoo.py and the start-up hook _sb3_classic_zoo.py).

The zoo's own commands run in subprocesses against the installed package, as rl-zoo3's tests do: no wrapper, no
flag, the working directory a temporary one (so that the checkout is not on ``sys.path``). They train for 1000 steps
or fewer: they check the integration, not learning. The search spaces, the YAMLs and the patches are also checked
in-process, where that is quicker.
"""

import argparse
import importlib
import inspect
import json
import os
import pickle
import re
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import optuna
import pytest
import torch as th
import yaml
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.utils import ConstantSchedule, FloatSchedule
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
from torch import nn

from sb3_classic import REINFORCE, NStepSARSA, ObGD
from sb3_classic.zoo import (
    ALGORITHMS,
    CONVERTERS,
    SAMPLERS,
    SUPPORTED_RL_ZOO3,
    YAML_NAMES,
    ZooCompatibilityError,
    hyperparams_path,
    maskable_eval_callback,
    one_thread_unless_chosen,
    policy_kwargs_differences,
    register,
)
from sb3_classic.zoo_search import LINEAR, NETWORK, STREAMING, entry_kind, searched_entry

ALGOS = list(ALGORITHMS)
ENV_IDS = ["CartPole-v1", "Acrobot-v1"]
# Keys of a zoo YAML entry that the zoo consumes instead of passing them to the constructor
ZOO_KEYS = {
    *("n_timesteps", "n_envs", "policy", "normalize", "frame_stack", "callback"),
    *("env_wrapper", "vec_env_wrapper", "env_kwargs", "monitor_kwargs"),
}
# The trial parameters of each search space (what a study stores), per kind of YAML entry
NETWORK_PARAMS = {"n_layers", "layer_size", "activation_fn", "weight_init"}
COMMON_SPACE = {"one_minus_gamma", "lr_decay_factor", "lr_decay_every"} | NETWORK_PARAMS
EXPLORATION_SPACE = {"exploration_schedule", "exploration_decay_rate", "exploration_fraction", "exploration_initial_eps"}
EXPLORATION_SPACE |= {"exploration_final_eps"}
SARSA_SPACE = COMMON_SPACE | {"n_steps", "learning_rate", "train_freq", "gradient_steps", "expected_sarsa", "td_lambda"}
SARSA_SPACE |= {"loss_function", "averaging_tau"} | EXPLORATION_SPACE
STREAMING_NETWORK_PARAMS = NETWORK_PARAMS - {"weight_init"} | {"kappa"}
SEARCH_SPACES = {
    "reinforce": {
        NETWORK: COMMON_SPACE | {"learning_rate", "value_learning_rate", "n_episodes", "normalize_advantage", "ent_coef"},
        STREAMING: STREAMING_NETWORK_PARAMS | {"value_kappa"},
    },
    "nstep_sarsa": {
        NETWORK: SARSA_SPACE,
        LINEAR: SARSA_SPACE - NETWORK_PARAMS - {"loss_function"},
        STREAMING: STREAMING_NETWORK_PARAMS | {"td_lambda", "expected_sarsa"} | EXPLORATION_SPACE,
    },
}

# One torch thread per command (the tests run two at a time on two cores); no display
ENV = {**os.environ, "OMP_NUM_THREADS": "1", "MPLBACKEND": "Agg", "SDL_VIDEODRIVER": "dummy"}


def run(cwd: Path, *args: str, env: dict[str, str] | None = None, check: bool = True) -> subprocess.CompletedProcess[str]:
    """
    Run ``python ARGS`` (the interpreter running the tests) in ``cwd``.

    :param cwd: the working directory (logs are written there)
    :param args: the interpreter's arguments, e.g. ``("-m", "rl_zoo3.train", ...)``
    :param env: extra environment variables
    :param check: assert that it exits with 0
    :return: the finished process, with its output
    """
    result = subprocess.run(
        [sys.executable, *args], cwd=cwd, env={**ENV, **(env or {})}, capture_output=True, text=True, timeout=300
    )
    if check:
        assert result.returncode == 0, (
            f"python {' '.join(args)} exited with {result.returncode}\n"
            f"--- stdout ---\n{result.stdout[-4000:]}\n--- stderr ---\n{result.stderr[-4000:]}"
        )
    return result


def zoo(cwd: Path, command: str, *args: str, check: bool = True) -> subprocess.CompletedProcess[str]:
    """Run ``python -m rl_zoo3.COMMAND ARGS`` in ``cwd``; a training command must not have made runpy warn."""
    result = run(cwd, "-m", f"rl_zoo3.{command}", *args, check=check)
    assert "found in sys.modules" not in result.stderr, result.stderr
    return result


def train(cwd: Path, algo: str, env_id: str, *args: str) -> subprocess.CompletedProcess[str]:
    """``python -m rl_zoo3.train`` for a few steps, seeded, without the default evaluation every 25k steps."""
    return zoo(cwd, "train", "--algo", algo, "--env", env_id, "--seed", "0", "--eval-freq", "-1", *args)


def assert_read_the_package_yaml(stdout: str, algo: str) -> None:
    """
    :param stdout: the output of a training command
    :param algo: the algorithm it trained, whose YAML in the installed package it must have read
    """
    (path,) = re.findall(r"^Loading hyperparameters from: (.+)$", stdout, flags=re.MULTILINE)
    # The installed copy (a wheel's), or the checkout's (an editable install)
    assert Path(path).parts[-2:] == ("hyperparams", f"{algo}.yml"), path
    assert "rl_zoo3" not in Path(path).parts, path
    assert Path(path).read_text() == hyperparams_path(algo).read_text()


def load(algo: str, path: Path) -> Any:
    assert path.is_file(), f"{path} was not saved; the folder has {sorted(p.name for p in path.parent.iterdir())}"
    return ALGORITHMS[algo].load(path, device="cpu")


def yaml_entry(algo: str, env_id: str) -> dict[str, Any]:
    entries = yaml.safe_load(hyperparams_path(algo).read_text())
    return dict(entries.get(env_id, entries["default"]))


def eval_policy_kwargs(policy_kwargs: Any) -> dict[str, Any]:
    """
    A YAML's ``policy_kwargs`` as the zoo reads it: a string is evaluated with ``nn``, ``th`` and the names
    ``register()`` adds (``TileCoding``) in scope.
    """
    namespace = {"nn": nn, "th": th, **YAML_NAMES}
    return eval(policy_kwargs, namespace) if isinstance(policy_kwargs, str) else dict(policy_kwargs)


def learning_rate(model: BaseAlgorithm, optimizer: th.optim.Optimizer | None = None) -> float:
    """The learning rate ``optimizer`` (the policy's by default) was last given."""
    return float((optimizer or model.policy.optimizer).param_groups[0]["lr"])


def scheduled(value: float | str, progress_remaining: float) -> float:
    """A YAML learning rate (a number, or the zoo's ``lin_<initial>``) at ``progress_remaining``."""
    if isinstance(value, str) and value.startswith("lin_"):
        return float(value.removeprefix("lin_")) * progress_remaining
    return float(value)


def expected_decay(entry: dict[str, Any], episodes: int) -> float:
    """The learning-rate step decay of a YAML entry after ``episodes`` completed episodes."""
    factor = entry.get("lr_decay_factor", 1.0)
    if "lr_decay_every" in entry:
        return factor ** (episodes // entry["lr_decay_every"])
    return factor ** sum(episodes >= milestone for milestone in entry.get("lr_decay_milestones", []))


# --- Start-up hook -------------------------------------------------------------------------------------------------

STARTUP_CHECK = """
import json, sys
heavy = ("torch", "numpy", "rl_zoo3", "sb3_classic", "stable_baselines3", "gymnasium", "optuna")
before = {
    "heavy": [name for name in heavy if name in sys.modules],
    "hook": "_sb3_classic_zoo" in sys.modules,
    "finders": sum(getattr(finder, "sb3_classic_zoo", False) for finder in sys.meta_path),
}
import importlib.resources
import rl_zoo3
import rl_zoo3.exp_manager, rl_zoo3.hyperparams_opt, rl_zoo3.utils
after = {
    "algos": {name: f"{cls.__module__}.{cls.__name__}" for name, cls in rl_zoo3.ALGOS.items()},
    "same_algos": rl_zoo3.ALGOS is rl_zoo3.utils.ALGOS,
    "samplers": sorted(rl_zoo3.hyperparams_opt.HYPERPARAMS_SAMPLER),
    "converters": sorted(rl_zoo3.hyperparams_opt.HYPERPARAMS_CONVERTER),
    "loader": type(rl_zoo3.__loader__).__name__,
    "spec_loader": type(rl_zoo3.__spec__.loader).__name__,
    "resources": importlib.resources.files("rl_zoo3").joinpath("hyperparams", "ppo.yml").is_file(),
}
print(json.dumps({"before": before, "after": after}))
"""


def test_startup_hook_imports_nothing_heavy_and_registers_with_rl_zoo3(tmp_path: Path) -> None:
    result = run(tmp_path, "-c", STARTUP_CHECK)
    state = json.loads(result.stdout)
    before, after = state["before"], state["after"]
    # The .pth ran the hook, which installed one finder and imported nothing heavy
    assert before == {"heavy": [], "hook": True, "finders": 1}, "is the package installed (pip install -e '.[tests]')?"
    # Importing rl_zoo3 registered both algorithms in the dict every command reads
    assert after["algos"]["reinforce"] == "sb3_classic.reinforce.reinforce.REINFORCE"
    assert after["algos"]["nstep_sarsa"] == "sb3_classic.sarsa.nstep_sarsa.NStepSARSA"
    assert after["algos"]["ppo"] == "stable_baselines3.ppo.ppo.PPO"
    assert after["same_algos"]
    assert {"reinforce", "nstep_sarsa", "ppo"} <= set(after["samplers"]) & set(after["converters"])
    # The real loader is put back once rl_zoo3 has executed
    assert after["loader"] == after["spec_loader"] == "SourceFileLoader"
    assert after["resources"]
    assert "sb3_classic" not in result.stderr


def test_incompatible_rl_zoo3_fails_clearly(tmp_path: Path) -> None:
    # An rl_zoo3 3.0 without what register() patches, ahead of the installed one on sys.path
    fake = tmp_path / "fake" / "rl_zoo3"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text('__version__ = "3.0.0"\n')
    (fake / "utils.py").write_text("ALGOS = {}\n")
    env = {"PYTHONPATH": str(tmp_path / "fake")}
    expected = (
        "rl_zoo3 3.0.0: importing it failed (No module named 'rl_zoo3.hyperparams_opt'). "
        f"sb3_classic supports rl_zoo3{SUPPORTED_RL_ZOO3}"
    )

    # The hook warns and leaves the zoo importable for its own algorithms
    hooked = run(tmp_path, "-c", "import rl_zoo3; print(rl_zoo3.__version__)", env=env)
    assert hooked.stdout.strip() == "3.0.0"
    assert "RuntimeWarning" in hooked.stderr
    assert expected in hooked.stderr

    # register() itself raises, once, with a short traceback (no frames of the zoo or of importlib)
    direct = run(tmp_path, "-c", "from sb3_classic.zoo import register; register()", env=env, check=False)
    assert direct.returncode == 1
    assert direct.stderr.strip().splitlines()[-1].startswith("sb3_classic.zoo.ZooCompatibilityError: ")
    assert expected in direct.stderr
    assert "RuntimeWarning" not in direct.stderr
    assert "importlib" not in direct.stderr


# --- register() in-process -----------------------------------------------------------------------------------------


def test_register_is_idempotent() -> None:
    import rl_zoo3
    from rl_zoo3.exp_manager import ExperimentManager
    from rl_zoo3.hyperparams_opt import HYPERPARAMS_CONVERTER, HYPERPARAMS_SAMPLER

    # The start-up hook registered when rl_zoo3 was imported; again changes nothing
    init, preprocess = ExperimentManager.__init__, ExperimentManager._preprocess_schedules
    n_algos = len(rl_zoo3.ALGOS)
    register()
    register()
    assert rl_zoo3.ALGOS["reinforce"] is REINFORCE
    assert rl_zoo3.ALGOS["nstep_sarsa"] is NStepSARSA
    assert len(rl_zoo3.ALGOS) == n_algos
    for algo in ALGOS:
        assert HYPERPARAMS_SAMPLER[algo] is SAMPLERS[algo]
        assert HYPERPARAMS_CONVERTER[algo] is CONVERTERS[algo]
    assert ExperimentManager.__init__ is init
    assert ExperimentManager._preprocess_schedules is preprocess
    # The names a YAML's policy_kwargs string and a -params value may use, where the zoo evaluates them
    import rl_zoo3.exp_manager
    import rl_zoo3.utils

    for name, value in YAML_NAMES.items():
        assert vars(rl_zoo3.exp_manager)[name] is value
        assert vars(rl_zoo3.utils)[name] is value
    # ... as the zoo's train.py parses -params (a NameError: name 'TileCoding' is not defined, before)
    parser = argparse.ArgumentParser()
    parser.add_argument("-params", nargs="+", action=rl_zoo3.utils.StoreDict)
    value = "dict(net_arch=[], features_extractor_class=TileCoding)"
    assert parser.parse_args(["-params", f"policy_kwargs:{value}"]).params["policy_kwargs"] == eval_policy_kwargs(value)
    # Each is wrapped once
    patched: Any
    for patched in (init, preprocess):
        assert not hasattr(patched.__wrapped__, "__wrapped__")
    assert "config" in inspect.signature(ExperimentManager.__init__).parameters


def test_experiment_manager_reads_the_package_yamls_unless_conf_is_given(tmp_path: Path) -> None:
    from rl_zoo3.exp_manager import ExperimentManager

    def config(algo: str, **kwargs: Any) -> str:
        return ExperimentManager(argparse.Namespace(), algo, "CartPole-v1", str(tmp_path), **kwargs).config

    for algo in ALGOS:
        assert config(algo) == str(hyperparams_path(algo))
        assert config(algo, config="mine.yml") == "mine.yml"
    assert Path(config("ppo")).parts[-3:] == ("rl_zoo3", "hyperparams", "ppo.yml")


def test_value_learning_rate_is_read_like_learning_rate() -> None:
    from rl_zoo3.exp_manager import ExperimentManager
    from rl_zoo3.utils import SimpleLinearSchedule

    hyperparams = ExperimentManager._preprocess_schedules({"learning_rate": 0.001, "value_learning_rate": "lin_0.02"})
    assert isinstance(hyperparams["learning_rate"], ConstantSchedule)
    assert isinstance(hyperparams["value_learning_rate"], SimpleLinearSchedule)
    assert hyperparams["value_learning_rate"](1.0) == pytest.approx(0.02)
    assert hyperparams["value_learning_rate"](0.5) == pytest.approx(0.01)
    assert ExperimentManager._preprocess_schedules({"value_learning_rate": 0.1})["value_learning_rate"](0.0) == 0.1
    assert "value_learning_rate" not in ExperimentManager._preprocess_schedules({"learning_rate": 0.1})


def test_a_number_yaml_reads_as_a_string_is_named_with_the_fix(tmp_path: Path) -> None:
    # learning_rate: 1e-3 (no dot) is a string to PyYAML: the zoo split it as a schedule's name, "not enough values to
    # unpack (expected 2, got 1)"
    from rl_zoo3.exp_manager import ExperimentManager

    fix = "'1e-3' is read as a string by YAML: write !!float 1e-3, or 0.001"
    with pytest.raises(ValueError, match=re.escape(f"learning_rate: {fix}")):
        ExperimentManager._preprocess_schedules({"learning_rate": "1e-3", "n_steps": 3})
    with pytest.raises(ValueError, match=re.escape("value_learning_rate: '5e-3' is read as a string by YAML")):
        ExperimentManager._preprocess_schedules({"value_learning_rate": "5e-3"})
    # The names of schedules and other strings are the zoo's to read
    assert ExperimentManager._preprocess_schedules({"learning_rate": "lin_1e-3"})["learning_rate"](0.5) == 5e-4
    conf = tmp_path / "mine.yml"
    conf.write_text("CartPole-v1:\n  n_timesteps: 64\n  policy: MlpPolicy\n  learning_rate: 1e-3\n")
    result = zoo(tmp_path, "train", "--algo", "reinforce", "--env", "CartPole-v1", "-conf", str(conf), check=False)
    assert result.returncode != 0
    last_line = result.stderr.splitlines()[-1]
    assert last_line.endswith(f"learning_rate: {fix} (in the hyperparameters of rl-zoo3's YAML or -params)"), last_line


def test_register_checks_the_zoo_before_changing_anything(monkeypatch: pytest.MonkeyPatch) -> None:
    import rl_zoo3
    import rl_zoo3.hyperparams_opt
    from rl_zoo3.exp_manager import ExperimentManager

    monkeypatch.delitem(rl_zoo3.ALGOS, "reinforce")
    monkeypatch.delattr(rl_zoo3.hyperparams_opt, "HYPERPARAMS_CONVERTER")
    with pytest.raises(ZooCompatibilityError) as error:
        register()
    message = str(error.value)
    assert f"installed rl_zoo3 {rl_zoo3.__version__}" in message
    assert "rl_zoo3.hyperparams_opt.HYPERPARAMS_CONVERTER is not a dict" in message
    assert f"supports rl_zoo3{SUPPORTED_RL_ZOO3}" in message
    assert "reinforce" not in rl_zoo3.ALGOS
    monkeypatch.undo()

    def old_init(self: Any, args: Any, algo: str, env_id: str) -> None: ...

    monkeypatch.setattr(ExperimentManager, "__init__", old_init)
    with pytest.raises(ZooCompatibilityError, match=r"ExperimentManager.__init__ has no 'algo' and 'config' arguments"):
        register()


# --- YAMLs and search spaces ---------------------------------------------------------------------------------------


def constructor_arguments(algo: str) -> set[str]:
    return set(inspect.signature(ALGORITHMS[algo].__init__).parameters) - {"self", "policy", "env"}


@pytest.mark.parametrize("algo", ALGOS)
def test_yaml_entries_are_constructor_arguments(algo: str) -> None:
    from rl_zoo3.exp_manager import ExperimentManager

    entries = yaml.safe_load(hyperparams_path(algo).read_text())
    assert {"default", *ENV_IDS} <= set(entries)
    for env_id, entry in entries.items():
        unknown = set(entry) - ZOO_KEYS - constructor_arguments(algo)
        assert not unknown, f"{algo}.yml, {env_id}: {sorted(unknown)} are not arguments of {ALGORITHMS[algo].__name__}"
        assert isinstance(entry["n_timesteps"], float | int), f"{algo}.yml, {env_id}: write n_timesteps as !!float"
        kwargs = {key: value for key, value in entry.items() if key not in ZOO_KEYS}
        if "policy_kwargs" in kwargs:
            kwargs["policy_kwargs"] = eval_policy_kwargs(kwargs["policy_kwargs"])
        # Learning rates as the zoo reads them: a number or lin_<number> (anything else raises)
        kwargs = ExperimentManager._preprocess_schedules(kwargs)
        env = env_id if env_id != "default" and env_id in gym.registry else "CartPole-v1"
        ALGORITHMS[algo](entry["policy"], env, device="cpu", **kwargs)


def shipped_entries() -> list[tuple[str, str, str]]:
    """:return: (algo, YAML file, env id) of every entry of the package's YAMLs, the streaming recipe's included"""
    entries = []
    for algo in ALGOS:
        for path in (hyperparams_path(algo), hyperparams_path(f"{algo}_streaming")):
            entries += [(algo, path.name, env_id) for env_id in yaml.safe_load(path.read_text())]
    return entries


@pytest.mark.parametrize(("algo", "yaml_name", "env_id"), shipped_entries())
@pytest.mark.parametrize("sampler", [optuna.samplers.RandomSampler, optuna.samplers.TPESampler])
def test_search_space(algo: str, yaml_name: str, env_id: str, sampler: Callable[..., optuna.samplers.BaseSampler]) -> None:
    entry = yaml.safe_load((hyperparams_path(algo).parent / yaml_name).read_text())[env_id]
    # The entry as the zoo's objective holds it (policy_kwargs evaluated), over which it puts a trial's values
    entry = {key: value for key, value in entry.items() if key == "policy" or key not in ZOO_KEYS | {"n_timesteps"}}
    if "policy_kwargs" in entry:
        entry["policy_kwargs"] = eval_policy_kwargs(entry["policy_kwargs"])
    kind = entry_kind(entry)
    assert kind == (STREAMING if "streaming" in yaml_name else LINEAR if entry["policy"] == "LinearPolicy" else NETWORK)

    def objective(trial: optuna.Trial) -> float:
        with searched_entry(entry):
            hyperparams = SAMPLERS[algo](trial, 0, 1, {})
        # rl-zoo3 converts a stored trial with the converter: it must give the same arguments
        assert CONVERTERS[algo](trial.params) == hyperparams
        assert set(hyperparams) <= constructor_arguments(algo)
        # rl-zoo3 puts them over the YAML entry's (``objective``: kwargs.update(sampled)): every entry the package
        # ships must give a model the algorithm accepts, or the zoo's study ends (MountainCar-v0's ε of 0.0 under a
        # sampled floor did, and its LinearPolicy under a sampled network); and they replace a decay that would
        # conflict with them
        from_yaml = {key: value for key, value in entry.items() if key != "policy"}
        if kind != STREAMING:
            from_yaml["lr_decay_milestones"] = [300, 500]
            # A YAML's (or -params') value of a setting the sampled ones exclude: each ended the study when drawn
            # against it (exploration_fraction with 'exponential', a decay rate with 'linear', per-step updates with
            # normalize_advantage)
            from_yaml |= (
                dict(exploration_schedule="linear", exploration_fraction=0.3, exploration_decay_rate=0.99)
                if algo == "nstep_sarsa"
                else dict(update_mode="per_step")
            )
        env = env_id if env_id != "default" and env_id in gym.registry else "CartPole-v1"
        model = ALGORITHMS[algo](entry["policy"], env, device="cpu", **{**from_yaml, **hyperparams})
        # The streaming recipe's trial trains with ObGD (the search had replaced its policy_kwargs by a network's,
        # Adam per step), a LinearPolicy's with the entry's features
        optimizer = model.policy.optimizer
        assert isinstance(optimizer, ObGD) == (kind == STREAMING), type(optimizer)
        if kind == STREAMING:
            assert optimizer.defaults["kappa"] == trial.params["kappa"]
            assert model.policy_kwargs["weight_init"] == "sparse"
        if kind == LINEAR:
            assert model.policy_kwargs == entry["policy_kwargs"]
        return float(sum(param.numel() for param in model.policy.parameters()))

    kwargs = {"n_startup_trials": 3, "multivariate": True} if sampler is optuna.samplers.TPESampler else {}
    study = optuna.create_study(sampler=sampler(seed=0, **kwargs))
    study.optimize(objective, n_trials=6)
    assert all(trial.state == optuna.trial.TrialState.COMPLETE for trial in study.trials)
    assert {frozenset(trial.params) for trial in study.trials} == {frozenset(SEARCH_SPACES[algo][kind])}
    # The zoo reports every sampled parameter: those a trial did not train with are named
    for trial in study.trials:
        params, unused = trial.params, set(trial.user_attrs.get("unused", "").split(", ")) - {""}
        expected = {"lr_decay_every"} if params.get("lr_decay_factor") == 1.0 else set()
        if algo == "nstep_sarsa":
            linear = params["exploration_schedule"] == "linear"
            expected.add("exploration_decay_rate" if linear else "exploration_fraction")
            expected |= {"td_lambda"} if params.get("n_steps") == 1 else set()
        assert unused == expected, (params, unused)


# --- The zoo's commands --------------------------------------------------------------------------------------------


# -i on CartPole only, where 1000 steps end enough episodes for the decays to show; MountainCar-v0's entry (SARSA's
# only: the book's tile coding, named in its policy_kwargs string) is the one whose string needs register()'s names
@pytest.mark.parametrize(
    ("algo", "env_id", "continue_with_i"),
    [(algo, env_id, env_id == "CartPole-v1") for env_id in ENV_IDS for algo in ALGOS]
    + [("nstep_sarsa", "MountainCar-v0", False)],
)
def test_train_with_the_package_yaml(tmp_path: Path, algo: str, env_id: str, continue_with_i: bool) -> None:
    entry = yaml_entry(algo, env_id)
    result = train(tmp_path, algo, env_id, "-n", "1000")
    assert_read_the_package_yaml(result.stdout, algo)
    first = load(algo, tmp_path / "logs" / algo / f"{env_id}_1" / f"{env_id}.zip")
    # The YAML's settings reached the model
    for key, value in entry.items():
        if key in ZOO_KEYS:
            continue
        if key == "policy_kwargs":
            assert first.policy_kwargs == eval_policy_kwargs(value)
        elif key.endswith("learning_rate"):
            schedule = FloatSchedule(getattr(first, key))
            assert [schedule(1.0), schedule(0.5)] == pytest.approx([scheduled(value, 1.0), scheduled(value, 0.5)]), key
        else:
            assert getattr(first, key) == value, key
    assert first.num_timesteps >= 1000
    if not continue_with_i:
        return

    # -i: the training state goes on (episode count, updates, and the ε and learning-rate decays that follow them)
    trained_agent = f"logs/{algo}/{env_id}_1/{env_id}.zip"
    result = train(tmp_path, algo, env_id, "-n", "500", "-i", trained_agent)
    assert "Loading pretrained agent" in result.stdout
    second = load(algo, tmp_path / "logs" / algo / f"{env_id}_2" / f"{env_id}.zip")
    assert second._completed_episodes > first._completed_episodes > 0
    assert second._n_updates > first._n_updates > 0
    episodes = second._completed_episodes
    # A lin_ learning rate follows the second run's progress, as it does for the zoo's own algorithms
    progress, decay = second._current_progress_remaining, expected_decay(entry, episodes)
    assert learning_rate(second) == pytest.approx(scheduled(entry["learning_rate"], progress) * decay)
    if algo == "reinforce":
        value_lr = scheduled(entry["value_learning_rate"], progress) * decay
        assert learning_rate(second, second.policy.value_optimizer) == pytest.approx(value_lr)
    else:
        assert second.exploration_schedule == "exponential"
        epsilon = second.exploration_initial_eps * second.exploration_decay_rate**episodes
        assert second.exploration_rate == pytest.approx(max(second.exploration_final_eps, epsilon))
        assert second.exploration_rate < first.exploration_rate


SHAPING_CALLBACK = """
import copy
import json
import pickle

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback


class ShapeAndCopy(BaseCallback):
    \"\"\"Sets every reward to 0.25 in place and copies the policy at every step; says what the buffer stored.\"\"\"

    def __init__(self):
        super().__init__()
        self.stored = set()
        self.copies = 0

    def _on_step(self):
        self.locals["rewards"][:] = 0.25
        pickle.loads(pickle.dumps(copy.deepcopy(self.model.policy)))
        self.copies += 1
        return True

    def _on_rollout_end(self):
        buffer = self.model.rollout_buffer
        self.stored.update(np.unique(buffer.rewards[: buffer.pos]).tolist())

    def _on_training_end(self):
        copy.deepcopy(self.model.policy)
        with open("callback.json", "w") as file:
            json.dump({"stored": sorted(self.stored), "copies": self.copies}, file)
"""
SMALL_ENTRIES: dict[str, dict[str, object]] = {
    "reinforce": {"policy": "MlpPolicy", "policy_kwargs": "dict(net_arch=[8])"},
    "nstep_sarsa": {"policy": "MlpPolicy", "policy_kwargs": "dict(net_arch=[8])", "n_steps": 2, "train_freq": 8},
}


@pytest.mark.parametrize("algo", ALGOS)
def test_a_callback_of_the_yaml_shapes_rewards_and_copies_the_policy(tmp_path: Path, algo: str) -> None:
    # rl-zoo3's `callback:` key, a class of the user's module (python -m puts the working directory on the path)
    (tmp_path / "shaping.py").write_text(SHAPING_CALLBACK)
    conf = tmp_path / "mine.yml"
    entry = {**SMALL_ENTRIES[algo], "n_timesteps": 1000, "callback": "shaping.ShapeAndCopy"}
    conf.write_text(yaml.safe_dump({"CartPole-v1": entry}))
    train(tmp_path, algo, "CartPole-v1", "-conf", str(conf))
    # As A2C's buffer holds them: the callback's rewards, not the env's 1.0
    seen = json.loads((tmp_path / "callback.json").read_text())
    assert seen["stored"] == [0.25]
    assert seen["copies"] >= 1000


def test_zoo_trains_with_one_thread_unless_a_number_is_chosen(tmp_path: Path) -> None:
    # The zoo's train without --num-threads: one PyTorch thread (the tests' other commands set OMP_NUM_THREADS=1)
    report = "import torch, atexit; atexit.register(lambda: print('threads:', torch.get_num_threads()))"
    (tmp_path / "sitecustomize.py").write_text(report + "\n")
    env = {key: value for key, value in ENV.items() if key != "OMP_NUM_THREADS"}
    env["PYTHONPATH"] = str(tmp_path)
    common = ["--algo", "reinforce", "--env", "CartPole-v1", "-n", "200", "--eval-freq", "-1", "--seed", "0"]

    def threads(*args: str) -> tuple[int, str]:
        result = subprocess.run(
            [sys.executable, "-m", "rl_zoo3.train", *common, *args], cwd=tmp_path, env=env, capture_output=True, text=True
        )
        assert result.returncode == 0, result.stderr[-4000:]
        (count,) = re.findall(r"^threads: (\d+)$", result.stdout, flags=re.MULTILINE)
        return int(count), result.stdout

    count, stdout = threads()
    assert count == 1
    assert "sb3_classic: one PyTorch thread on the CPU" in stdout
    count, stdout = threads("--num-threads", "2")
    assert count == 2
    assert "sb3_classic: one PyTorch thread" not in stdout


def test_one_thread_unless_chosen(monkeypatch: pytest.MonkeyPatch) -> None:
    import sb3_classic.common.threads as threads_module

    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    monkeypatch.delenv("MKL_NUM_THREADS", raising=False)
    monkeypatch.setattr(threads_module, "_STARTING_THREADS", 2)  # (PyTorch's count when the package was imported)
    before = th.get_num_threads()
    try:
        th.set_num_threads(2)
        assert one_thread_unless_chosen(-1, "cpu", verbose=0)
        assert th.get_num_threads() == 1
        # Chosen: --num-threads, an ExperimentManager without the zoo's arguments, the user's torch.set_num_threads
        for num_threads, threads in ((2, 2), (None, 2), (-1, 3)):
            th.set_num_threads(threads)
            assert not one_thread_unless_chosen(num_threads, "cpu", verbose=0)
            assert th.get_num_threads() == threads
        # ... or the environment
        th.set_num_threads(2)
        for variable in ("OMP_NUM_THREADS", "MKL_NUM_THREADS"):
            with monkeypatch.context() as env:
                env.setenv(variable, "2")
                assert not one_thread_unless_chosen(-1, "cpu", verbose=0)
            assert th.get_num_threads() == 2
    finally:
        th.set_num_threads(before)


def test_rl_zoo3_console_script(tmp_path: Path) -> None:
    script = Path(sys.executable).parent / "rl_zoo3"
    assert script.is_file(), f"rl_zoo3's console script is not beside {sys.executable}"
    args = ["train", "--algo", "nstep_sarsa", "--env", "Acrobot-v1", "-n", "500", "--eval-freq", "-1"]
    result = subprocess.run([str(script), *args], cwd=tmp_path, env=ENV, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-4000:]
    assert_read_the_package_yaml(result.stdout, "nstep_sarsa")
    model = load("nstep_sarsa", tmp_path / "logs" / "nstep_sarsa" / "Acrobot-v1_1" / "Acrobot-v1.zip")
    entry = yaml_entry("nstep_sarsa", "Acrobot-v1")
    assert (model.expected_sarsa, model.policy_kwargs) == (entry["expected_sarsa"], eval_policy_kwargs(entry["policy_kwargs"]))


# A matplotlib backend for plot_train: plt.show() saves the figures, and what their curves hold
SAVING_BACKEND = """
import json, os
from matplotlib._pylab_helpers import Gcf
from matplotlib.backends.backend_agg import FigureCanvasAgg as FigureCanvas


def show(*args, **kwargs):
    figures = []
    for manager in Gcf.get_all_fig_managers():
        figure = manager.canvas.figure
        figure.savefig(os.path.join(os.environ["PLOT_DIR"], f"figure_{manager.num}.png"))
        lines = [line for axes in figure.axes for line in axes.get_lines()]
        figures.append({line.get_label(): len(line.get_xdata()) for line in lines})
    with open(os.path.join(os.environ["PLOT_DIR"], "figures.json"), "w") as file:
        json.dump(figures, file)
"""


# Each plotting command runs once, on one algorithm's logs (they read the logs whatever the algorithm)
@pytest.mark.parametrize(("algo", "plot"), [("reinforce", "plot_train"), ("nstep_sarsa", "all_plots")])
def test_workflow(tmp_path: Path, algo: str, plot: str) -> None:
    """Train with TensorBoard, a progress bar, evaluations and checkpoints; plot; enjoy; record a video."""
    result = zoo(
        tmp_path,
        "train",
        *("--algo", algo, "--env", "CartPole-v1", "-n", "1000", "--seed", "0"),
        *("--tensorboard-log", "runs", "-P", "--log-interval", "5"),
        *("--eval-freq", "250", "--eval-episodes", "2", "--save-freq", "500"),
    )
    assert "━" in result.stdout, "no progress bar"
    run_dir = tmp_path / "logs" / algo / "CartPole-v1_1"
    evaluations = np.load(run_dir / "evaluations.npz")
    # The zoo counts --eval-freq and --save-freq in calls of all n_envs envs
    n_envs = yaml_entry(algo, "CartPole-v1").get("n_envs", 1)
    eval_steps, save_steps = 250 // n_envs * n_envs, 500 // n_envs * n_envs
    assert list(evaluations["timesteps"][:4]) == [eval_steps * k for k in (1, 2, 3, 4)]
    assert evaluations["results"].shape[1] == 2
    assert (run_dir / "best_model.zip").is_file()
    assert (run_dir / f"rl_model_{save_steps}_steps.zip").is_file()

    # TensorBoard: the algorithm's own scalars, and the evaluations
    (tb_dir,) = (tmp_path / "runs" / "CartPole-v1").iterdir()
    assert tb_dir.name == f"{ALGORITHMS[algo].__name__}_1"
    assert list(tb_dir.glob("events.out.tfevents.*"))
    scalars = set(EventAccumulator(str(tb_dir)).Reload().Tags()["scalars"])
    own = {"reinforce": {"train/value_learning_rate", "train/policy_loss"}, "nstep_sarsa": {"rollout/exploration_rate"}}
    assert {"train/learning_rate", "rollout/ep_rew_mean", "eval/mean_reward", *own[algo]} <= scalars, sorted(scalars)

    if plot == "plot_train":
        # SAVING_BACKEND saves the figure that plt.show() would display
        (tmp_path / "saving_backend.py").write_text(SAVING_BACKEND)
        plot_env = {"MPLBACKEND": "module://saving_backend", "PYTHONPATH": str(tmp_path), "PLOT_DIR": str(tmp_path)}
        run(tmp_path, "-m", "rl_zoo3.plots.plot_train", "-a", algo, "-e", "CartPole-v1", "-f", "logs", "-w", "5", env=plot_env)
        (figure,) = json.loads((tmp_path / "figures.json").read_text())
        assert figure.get("CartPole-v1_1", 0) > 0, figure
        assert (tmp_path / "figure_1.png").stat().st_size > 0
    else:
        run(
            tmp_path,
            "-m",
            "rl_zoo3.plots.all_plots",
            "-a",
            algo,
            "-e",
            "CartPole-v1",
            "-f",
            "logs",
            "--no-display",
            "-o",
            "all",
        )
        with (tmp_path / "all.pkl").open("rb") as file:
            results = pickle.load(file)["CartPole-v1"][f"{algo.upper()}-logs"]
        np.testing.assert_array_equal(results["timesteps"][:4], [eval_steps * k for k in (1, 2, 3, 4)])

    # enjoy (the best model for one algorithm, a checkpoint for the other) and record_video (the final model)
    load_flags = ["--load-best"] if algo == "reinforce" else ["--load-checkpoint", str(save_steps)]
    enjoy_args = ["--algo", algo, "--env", "CartPole-v1", "-f", "logs", "--no-render", "-n", "1000", *load_flags]
    enjoy = zoo(tmp_path, "enjoy", *enjoy_args, check=False)
    assert enjoy.returncode == 0, enjoy.stderr[-4000:]
    assert "Episode Reward" in enjoy.stdout
    pytest.importorskip("moviepy", reason="record_video writes its video with moviepy")
    zoo(tmp_path, "record_video", "--algo", algo, "--env", "CartPole-v1", "-f", "logs", "-n", "100", "-o", "videos")
    (video,) = (tmp_path / "videos").glob("*.mp4")
    assert video.name.startswith(f"final-model-{algo}-CartPole-v1")
    assert video.stat().st_size > 1000


# sb3-contrib's env with action masks, which refuses an illegal action: whatever predicts without its masks fails
STRICT_MASKED_ENV = """
import gymnasium as gym
from sb3_contrib.common.envs import InvalidActionEnvDiscrete


class StrictInvalidActionEnv(InvalidActionEnvDiscrete):
    def __init__(self):
        super().__init__(dim=20, ep_length=20, n_invalid_actions=15)

    def step(self, action):
        if int(action) in self.invalid_actions:
            raise RuntimeError(f"illegal action {int(action)} in state {self.state}")
        return super().step(action)


gym.register("StrictMasked-v0", entry_point=StrictInvalidActionEnv)
"""


@pytest.mark.parametrize("algo", ["reinforce", "nstep_sarsa"])
def test_train_evaluations_and_enjoy_use_the_envs_action_masks(tmp_path: Path, algo: str) -> None:
    (tmp_path / "strict_masked_env.py").write_text(STRICT_MASKED_ENV)
    # The env's module importable by --gym-packages, after the sb3_classic under test
    env = {"PYTHONPATH": os.pathsep.join(filter(None, [os.environ.get("PYTHONPATH"), str(tmp_path)]))}
    common = ["--algo", algo, "--env", "StrictMasked-v0", "--gym-packages", "strict_masked_env"]
    result = run(
        tmp_path,
        *("-m", "rl_zoo3.train", *common, "-n", "400", "--seed", "0", "--eval-freq", "100", "--eval-episodes", "2"),
        env=env,
    )
    assert "Using 'default' hyperparameters" in result.stdout
    evaluations = np.load(tmp_path / "logs" / algo / "StrictMasked-v0_1" / "evaluations.npz")
    assert list(evaluations["timesteps"]) == [100, 200, 300, 400]
    assert evaluations["results"].shape == (4, 2)
    enjoy = run(tmp_path, "-m", "rl_zoo3.enjoy", *common, "-f", "logs", "--no-render", "-n", "100", env=env)
    assert enjoy.stdout.count("Episode Reward") == 5


def test_zoo_evaluations_are_maskable_only_for_these_algorithms_and_envs_with_masks() -> None:
    from rl_zoo3.exp_manager import ExperimentManager
    from sb3_contrib.common.envs import InvalidActionEnvDiscrete
    from sb3_contrib.common.maskable.callbacks import MaskableEvalCallback
    from stable_baselines3.common.callbacks import EvalCallback
    from stable_baselines3.common.vec_env import DummyVecEnv

    register()
    masked = DummyVecEnv([lambda: InvalidActionEnvDiscrete(dim=4, n_invalid_actions=2)])
    unmasked = DummyVecEnv([lambda: gym.make("CartPole-v1")])
    assert type(maskable_eval_callback(masked, eval_freq=10)) is MaskableEvalCallback
    assert type(maskable_eval_callback(unmasked, eval_freq=10)) is EvalCallback

    def callbacks(algo: str) -> list[Any]:
        manager = ExperimentManager(argparse.Namespace(), algo, "CartPole-v1", "logs", eval_freq=10)
        manager.n_envs, manager.deterministic_eval = 1, True
        manager.create_envs = lambda n_envs, eval_env=False, no_log=False: masked  # type: ignore[method-assign]
        manager.create_callbacks()
        return [type(callback) for callback in manager.callbacks]

    assert callbacks("reinforce") == callbacks("nstep_sarsa") == [MaskableEvalCallback]
    assert callbacks("ppo") == [EvalCallback]
    # The zoo's module is left with its own EvalCallback
    assert vars(importlib.import_module("rl_zoo3.exp_manager"))["EvalCallback"] is EvalCallback


PARAMS: dict[str, dict[str, Any]] = {
    "reinforce": {
        "n_episodes": 3,
        "learning_rate": 0.01,
        "lr_decay_every": None,
        "value_learning_rate": "lin_0.02",
        "lr_decay_milestones": [5, 10],
        "lr_decay_factor": 0.5,
        "normalize_advantage": True,
        "policy_kwargs": "dict(net_arch=dict(pi=[16], vf=[8]), activation_fn=nn.ELU)",
    },
    "nstep_sarsa": {
        "n_steps": 7,
        "learning_rate": 0.01,
        "train_freq": 4,
        "expected_sarsa": True,
        "exploration_schedule": "linear",
        "exploration_fraction": 0.5,
        "lr_decay_every": None,
        "lr_decay_milestones": [5, 10],
        "policy_kwargs": "dict(net_arch=[16], weight_init='orthogonal')",
    },
}


# SubprocVecEnv starts an interpreter per env: once is enough
@pytest.mark.parametrize(("algo", "vec_env"), [("reinforce", "subproc"), ("nstep_sarsa", "dummy")])
def test_params_override_the_yaml(tmp_path: Path, algo: str, vec_env: str) -> None:
    params = {"n_envs": 2, **PARAMS[algo]}
    # -params values are Python expressions: strings are quoted, except policy_kwargs, which the zoo evaluates itself
    args = [
        f"{key}:{value!r}" if isinstance(value, str) and key != "policy_kwargs" else f"{key}:{value}"
        for key, value in params.items()
    ]
    result = train(tmp_path, algo, "CartPole-v1", "-n", "1000", "--vec-env", vec_env, "-params", *args)
    assert "Using 2 environments" in result.stdout
    run_dir = tmp_path / "logs" / algo / "CartPole-v1_1"
    assert (run_dir / "0.monitor.csv").is_file()
    assert (run_dir / "1.monitor.csv").is_file()
    args_yml = yaml.load((run_dir / "CartPole-v1" / "args.yml").read_text(), Loader=yaml.UnsafeLoader)
    assert args_yml["vec_env"] == vec_env
    model = load(algo, run_dir / "CartPole-v1.zip")
    assert model.n_envs == 2
    for key, value in params.items():
        if key == "n_envs":
            continue
        if key == "policy_kwargs":
            assert model.policy_kwargs == eval_policy_kwargs(value)
        elif key == "value_learning_rate":
            assert model.value_learning_rate(1.0) == pytest.approx(0.02)
            assert model.value_learning_rate(0.5) == pytest.approx(0.01)
        elif key == "learning_rate":
            assert model.learning_rate(1.0) == value
        else:
            assert getattr(model, key) == value, key


def test_conf_file_replaces_the_package_yaml(tmp_path: Path) -> None:
    conf = tmp_path / "mine.yml"
    entry = {"n_timesteps": 1000, "policy": "MlpPolicy", "n_steps": 2, "train_freq": 8, "exploration_decay_rate": 0.5}
    entry["policy_kwargs"] = "dict(net_arch=[8, 8])"
    conf.write_text(yaml.safe_dump({"CartPole-v1": entry}))
    result = train(tmp_path, "nstep_sarsa", "CartPole-v1", "-conf", str(conf), "-params", "exploration_final_eps:0.2")
    assert f"Loading hyperparameters from: {conf}" in result.stdout
    model = load("nstep_sarsa", tmp_path / "logs" / "nstep_sarsa" / "CartPole-v1_1" / "CartPole-v1.zip")
    assert (model.n_steps, model.train_freq, model.exploration_decay_rate) == (2, 8, 0.5)
    assert model.policy_kwargs == {"net_arch": [8, 8]}
    assert model.num_timesteps >= 1000
    # ε decayed to the floor that -params set, the rest is the package's default (no lr decay)
    assert model.exploration_rate == 0.2
    assert model.lr_decay_every is None
    assert model.lr_decay_milestones is None


@pytest.mark.parametrize(("algo", "storage"), [("reinforce", "study.db"), ("nstep_sarsa", "study.log")])
def test_optimize(tmp_path: Path, algo: str, storage: str) -> None:
    """Two trials with each of the random and TPE samplers, the median pruner, in one study in a shared storage."""
    url = f"sqlite:///{tmp_path / storage}" if storage.endswith(".db") else str(tmp_path / storage)
    common = ["-n", "500", "-optimize", "--n-trials", "2", "--n-startup-trials", "2", "--pruner", "median"]
    common += ["--n-evaluations", "2", "--eval-episodes", "1", "--no-optim-plots", "--storage", url, "--study-name", "s"]
    for sampler in ("random", "tpe"):
        result = zoo(tmp_path, "train", "--algo", algo, "--env", "CartPole-v1", "--seed", "0", *common, "--sampler", sampler)
        # A trial that raised (a sampled argument the algorithm rejects) is printed and pruned
        assert "Sampled hyperparams" not in result.stdout, result.stdout[-4000:]
    reports = (tmp_path / "logs" / algo).glob("report_CartPole-v1_2-trials-500-*-median_*.csv")
    assert sorted(report.name.split("-")[4] for report in reports) == ["random", "tpe"]

    backend = optuna.storages.journal.JournalFileBackend(url) if storage.endswith(".log") else None  # type: ignore[attr-defined]
    study = optuna.load_study(study_name="s", storage=optuna.storages.JournalStorage(backend) if backend else url)
    states = [trial.state for trial in study.trials]
    assert len(states) == 4
    assert set(states) <= {optuna.trial.TrialState.COMPLETE, optuna.trial.TrialState.PRUNED}
    # The median pruner prunes nothing before its 2 startup trials
    assert states[:2] == [optuna.trial.TrialState.COMPLETE] * 2
    assert all(set(trial.params) == SEARCH_SPACES[algo][NETWORK] for trial in study.trials)


@pytest.mark.parametrize(
    ("algo", "env_id", "streaming"),
    [("nstep_sarsa", "CartPole-v1", True), ("reinforce", "CartPole-v1", True), ("nstep_sarsa", "MountainCar-v0", False)],
)
def test_optimize_tunes_what_the_entry_trains_with(tmp_path: Path, algo: str, env_id: str, streaming: bool) -> None:
    """
    A streaming entry's search drew a network's settings over it and dropped ObGD (its trials trained with Adam per
    step, without an error); every trial of MountainCar-v0's LinearPolicy entry drew hidden layers, refused.
    """
    url = f"sqlite:///{tmp_path / 'study.db'}"
    conf = ["-conf", str(hyperparams_path(f"{algo}_streaming"))] if streaming else []
    args = ["-n", "300", "-optimize", "--n-trials", "2", "--n-startup-trials", "2", "--n-evaluations", "1"]
    args += ["--eval-episodes", "1", "--no-optim-plots", "--storage", url, "--study-name", "s", *conf]
    result = zoo(tmp_path, "train", "--algo", algo, "--env", env_id, "--seed", "0", *args)
    assert "Sampled hyperparams" not in result.stdout, result.stdout[-4000:]
    study = optuna.load_study(study_name="s", storage=url)
    assert [trial.state for trial in study.trials] == [optuna.trial.TrialState.COMPLETE] * 2
    kind = STREAMING if streaming else LINEAR
    assert all(set(trial.params) == SEARCH_SPACES[algo][kind] for trial in study.trials)


def test_hyperparams_path_finds_every_yaml_the_package_ships(tmp_path: Path) -> None:
    # -conf hyperparams/nstep_sarsa_streaming.yml works from a checkout's root only: the path gives the YAML anywhere
    for name in ("reinforce", "nstep_sarsa", "reinforce_streaming", "nstep_sarsa_streaming"):
        path = hyperparams_path(name)
        assert path.name == f"{name}.yml"
        assert yaml.safe_load(path.read_text())
    with pytest.raises(ValueError, match="'dqn' must be one of 'reinforce', 'nstep_sarsa', 'reinforce_streaming'"):
        hyperparams_path("dqn")
    # The command that prints it, for -conf "$(python -m sb3_classic.zoo nstep_sarsa_streaming)"
    printed = run(tmp_path, "-W", "error", "-m", "sb3_classic.zoo", "nstep_sarsa_streaming").stdout
    assert printed == f"{hyperparams_path('nstep_sarsa_streaming')}\n"


def test_policy_kwargs_differences() -> None:
    entry: dict[str, Any] = {"net_arch": [32], "optimizer_class": ObGD, "optimizer_kwargs": {"kappa": 2.0}}
    saved: dict[str, Any] = {"net_arch": [32], "optimizer_kwargs": {"kappa": 2.0, "lr": 1.0}, "weight_init": "sparse"}
    assert policy_kwargs_differences(entry, saved) == [f"optimizer_class: {ObGD!r} in the YAML, None in the model"]
    saved |= {"optimizer_class": ObGD, "optimizer_kwargs": {"kappa": 3.0}}
    assert policy_kwargs_differences(entry, saved) == ["optimizer_kwargs['kappa']: 2.0 in the YAML, 3.0 in the model"]
    assert policy_kwargs_differences(entry, saved | {"optimizer_kwargs": {"kappa": 2.0}}) == []
    # As a saved model gives them back: a tuple as a list (SB3 saves JSON-able policy_kwargs as JSON), arrays (a
    # TileCoding's bounds) by their elements, where comparing them raised
    tiles = {"features_extractor_kwargs": {"low": np.array([-1.2, -0.07]), "high": np.array([0.6, 0.07])}}
    assert policy_kwargs_differences({"net_arch": (8,), **tiles}, {"net_arch": [8], **tiles}) == []
    moved = {"features_extractor_kwargs": {"low": np.array([-1.2, -0.07]), "high": np.array([0.6, 0.08])}}
    assert len(policy_kwargs_differences(tiles, moved)) == 1
    # An entry that leaves the optimizer to its default (Adam) for a model trained with ObGD
    assert policy_kwargs_differences({"net_arch": [32]}, {"net_arch": [32], "optimizer_class": ObGD}) == [
        f"optimizer_class: None in the YAML, {ObGD!r} in the model"
    ]


def test_continuing_a_model_with_another_networks_yaml_is_refused(tmp_path: Path) -> None:
    """
    The zoo drops the YAML's policy_kwargs on -i but passes its other settings: the streaming entry's learning_rate
    of 1.0 (ObGD's α) trained a model of the default entry's Adam to a loss of 6e18, without a word.
    """
    train(tmp_path, "nstep_sarsa", "CartPole-v1", "-n", "200")
    trained_agent = str(tmp_path / "logs" / "nstep_sarsa" / "CartPole-v1_1" / "CartPole-v1.zip")
    streaming = str(hyperparams_path("nstep_sarsa_streaming"))
    args = ["--algo", "nstep_sarsa", "--env", "CartPole-v1", "-n", "200", "-i", trained_agent, "-conf", streaming]
    result = zoo(tmp_path, "train", *args, check=False)
    assert result.returncode != 0
    message = " ".join(result.stderr.split())
    assert "the YAML entry's policy_kwargs differ from the model's (net_arch: [128, 128] in the YAML, [256, 256]" in message
    assert "continue with the settings the model was trained with (its -conf, -params or --trial-id)" in message
    assert not (tmp_path / "logs" / "nstep_sarsa" / "CartPole-v1_2" / "CartPole-v1.zip").exists()


@pytest.mark.parametrize("algo", ALGOS)
def test_train_with_a_stored_trial(tmp_path: Path, algo: str) -> None:
    """``--storage ... --study-name ... --trial-id N``: the converter turns the trial's parameters into arguments."""
    url = f"sqlite:///{tmp_path / 'study.db'}"
    study = optuna.create_study(storage=url, study_name="s", sampler=optuna.samplers.RandomSampler(seed=1))
    study.optimize(lambda trial: float(len(SAMPLERS[algo](trial, 0, 1, {}))), n_trials=2)
    params = study.trials[1].params

    result = train(tmp_path, algo, "CartPole-v1", "-n", "500", "--storage", url, "--study-name", "s", "--trial-id", "1")
    assert "Loading from Optuna study..." in result.stdout
    model = load(algo, tmp_path / "logs" / algo / "CartPole-v1_1" / "CartPole-v1.zip")
    assert model.gamma == pytest.approx(1 - params["one_minus_gamma"])
    assert model.learning_rate(1.0) == pytest.approx(params["learning_rate"])
    assert model.policy_kwargs["net_arch"] == [params["layer_size"]] * params["n_layers"]
    assert model.policy_kwargs["weight_init"] == params["weight_init"]
    assert (model.lr_decay_factor, model.lr_decay_every) == (params["lr_decay_factor"], params["lr_decay_every"])
    if algo == "reinforce":
        assert model.n_episodes == params["n_episodes"]
        assert model.value_learning_rate(1.0) == pytest.approx(params["value_learning_rate"])
    else:
        assert (model.n_steps, model.train_freq) == (params["n_steps"], params["train_freq"])
        assert model.exploration_schedule == params["exploration_schedule"]
        if params["exploration_schedule"] == "linear":
            assert model.exploration_fraction == params["exploration_fraction"]
        else:
            assert model.exploration_decay_rate == params["exploration_decay_rate"]


def test_a_misspelt_argument_in_params_names_the_argument_meant(tmp_path: Path) -> None:
    # Python's bare "unexpected keyword argument 'n_step'" named no fix
    arguments = ("--algo", "nstep_sarsa", "--env", "CartPole-v1", "-n", "64", "-params", "n_step:5")
    result = zoo(tmp_path, "train", *arguments, check=False)
    assert result.returncode != 0
    last_line = result.stderr.splitlines()[-1]
    assert "unexpected keyword argument 'n_step': did you mean 'n_steps'?" in last_line, result.stderr[-2000:]
