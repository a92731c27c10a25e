"""
CPU seconds of K seeds of one setting trained in lockstep (``NStepSARSAPopulation``, ``REINFORCEPopulation``) against
the same K seeds trained one after the other (``model.learn``), in one process with one PyTorch thread. Two families of
settings (``--settings``) per algorithm (``--algo``):

- ``per_step``: NStepSARSA in the book's per-step mode (2 × 128 MLP, n_steps 10 on CartPole-v1 and 5 on Acrobot-v1,
  learning_rate 5e-4, train_freq 1, gradient_steps 1, update_mode "per_step"); REINFORCE's per-step final models of the
  seed report on CartPole-v1 and Acrobot-v1 (``studies/seed_report/fig08-reinforce-cartpole-final.yml``,
  ``fig24-reinforce-acrobot-final.yml``);
- ``batch``: the tuned batch-mode entries of ``hyperparams/nstep_sarsa.yml`` (8 envs per seed, train_freq 16,
  gradient_steps 8, 2 × 256 MLP; Acrobot-v1's with its bootstrap network, weight average, λ-returns and Expected SARSA)
  and of ``hyperparams/reinforce.yml`` (one env, one Adam step per episode);
- ``many_seeds``: NStepSARSA's per-step setting on CartPole-v1 with more seeds (``--many-k``, 30) and fewer env steps
  per seed (``--many-steps``, 1,000).

    python -m benchmarks.lockstep                       # writes benchmarks/results/lockstep.{csv,md}
    python -m benchmarks.lockstep --k 10 --steps 3000 --settings per_step --repeats 1
    python -m benchmarks.lockstep --k 10 --batch-steps 20000 --settings batch --algo REINFORCE

Seconds are ``time.process_time`` of training only (the models are built before the clock starts), the median of
``--repeats`` timings of each way (3 by default).
Each row also gives lockstep's floor (``floor``): in a third run of the population, the seconds of its stacked calls and
the members' envs, what lockstep would take were each member's own rollout code free.
"""

import argparse
import csv
import os
import platform
import shlex
import statistics
import sys
import time
from collections.abc import Callable
from contextlib import ExitStack
from pathlib import Path
from typing import Any
from unittest import mock

import torch as th
import yaml
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv

from sb3_classic import REINFORCE, NStepSARSA
from sb3_classic.harness.common import load_hyperparams, positive_int
from sb3_classic.reinforce import REINFORCEPopulation
from sb3_classic.reinforce import lockstep as reinforce_lockstep
from sb3_classic.sarsa import NStepSARSAPopulation
from sb3_classic.sarsa import lockstep as sarsa_lockstep

RESULTS = Path(__file__).resolve().parent / "results"
N_STEPS = {"CartPole-v1": 10, "Acrobot-v1": 5}
SETTING = "per_step: 2x128 MLP, lr 5e-4, train_freq 1, gradient_steps 1"
#: The families of settings, in the order of the tables
SETTINGS = ("per_step", "batch", "many_seeds")
ALGOS = ("NStepSARSA", "REINFORCE")
#: The seed report's per-step final models of REINFORCE, by figure
FINAL_PER_STEP = {
    figure: Path(__file__).resolve().parent / "studies" / "seed_report" / f"{figure}-reinforce-{name}-final.yml"
    for figure, name in (("fig08", "cartpole"), ("fig24", "acrobot"))
}


def make_models(env_id: str, k: int) -> list[NStepSARSA]:
    """:return: K members of the per-step setting, seeds 0..K-1, each with its own env seeded as its model"""
    return [
        NStepSARSA(
            "MlpPolicy",
            make_vec_env(env_id, n_envs=1, seed=seed),
            learning_rate=5e-4,
            n_steps=N_STEPS[env_id],
            train_freq=1,
            gradient_steps=1,
            update_mode="per_step",
            policy_kwargs=dict(net_arch=[128, 128]),
            seed=seed,
        )
        for seed in range(k)
    ]


def timed(make: Callable[[], list[Any]], steps: int, repeats: int) -> tuple[float, float, float]:
    """
    :param make: builds the K members (called three times per repeat: once for each way of training them, and once
        more for the floor)
    :param steps: env steps per seed
    :param repeats: how many times to time each of the three (the machine's noise: the medians are kept)
    :return: the medians of the CPU seconds of the K seeds one after the other, in lockstep, and of lockstep's floor
        (``floor``)
    """
    times: list[tuple[float, float, float]] = []
    for _ in range(repeats):
        models: list[BaseAlgorithm] = make()
        start = time.process_time()
        for model in models:
            model.learn(steps)
        separate = time.process_time() - start
        models = make()
        start = time.process_time()
        population_of(models).learn(steps)
        times.append((separate, time.process_time() - start, floor(make(), steps)))
    separate, lockstep, floor_s = (statistics.median(column) for column in zip(*times, strict=True))
    return separate, lockstep, floor_s


def population_of(models: list[Any]) -> REINFORCEPopulation | NStepSARSAPopulation:
    """:return: ``models`` as one population of their algorithm (``REINFORCEPopulation`` or ``NStepSARSAPopulation``)"""
    return REINFORCEPopulation(models) if isinstance(models[0], REINFORCE) else NStepSARSAPopulation(models)


#: The stacked calls of the populations: their forward passes for the members' actions (REINFORCE's with the softmax
#: of its logits) and their gradient steps (the members' chunks laid side by side, the stacked networks' forward and
#: backward passes and Adam steps; not the members' own code that each result is sent on to)
STACKED_CALLS: tuple[tuple[Any, str], ...] = (
    (sarsa_lockstep._StackedQ, "forward"),
    (sarsa_lockstep._StackedQ, "_gradient_step"),
    (reinforce_lockstep._StackedPolicy, "forward"),
    (reinforce_lockstep._StackedPolicy, "_gradient_step"),
)
#: What ``floor`` clocks: the stacked calls and the members' envs
CLOCKED: tuple[tuple[Any, str], ...] = (*STACKED_CALLS, (DummyVecEnv, "step_wait"))


def floor(models: list[Any], steps: int) -> float:
    """
    The part of a lockstep run that no change to the members' own rollout code could remove: the populations' stacked
    calls (``STACKED_CALLS``: the forward passes that choose the members' actions and the stacked gradient steps, as
    they are) and the members' envs (SB3's ``DummyVecEnv.step_wait``: Monitor, Gymnasium's wrappers, the env, its reset
    at an episode's end). The rest of a member's env step (its ε-greedy draw or action sample, its buffer, its update's
    windows and targets with their bootstrap values, the moves of its copies of q̂, its logger and callbacks) is its own
    code, run as in its separate run. The separate runs' seconds over this floor bound the ratio that lockstep could
    reach with that code free.

    :param models: the K members, untrained
    :param steps: env steps per seed
    :return: CPU seconds of the stacked calls and the envs, in one lockstep run of ``models`` (the clock's own calls,
        about a microsecond each, included)
    """
    seconds = [0.0]

    def clocked(function: Callable[..., Any]) -> Callable[..., Any]:
        def call(*args: Any, **kwargs: Any) -> Any:
            start = time.process_time()
            try:
                return function(*args, **kwargs)
            finally:
                seconds[0] += time.process_time() - start

        return call

    with ExitStack() as stack:
        for owner, name in CLOCKED:
            stack.enter_context(mock.patch.object(owner, name, clocked(getattr(owner, name))))
        population_of(models).learn(steps)
    return seconds[0]


def per_step_rows(env_ids: list[str], k: int, steps: int, repeats: int) -> list[dict[str, Any]]:
    """:return: the rows of the per-step setting, one per env"""
    rows = []
    for env_id in env_ids:
        seconds = timed(lambda env_id=env_id: make_models(env_id, k), steps, repeats)  # type: ignore[misc]
        rows.append(row("NStepSARSA", env_id, f"{SETTING}, n_steps {N_STEPS[env_id]}", k, steps, seconds))
    return rows


def linear_schedule(initial_value: float) -> Callable[[float], float]:
    """:return: the zoo's ``lin_<initial_value>``: the learning rate falls linearly to 0 over the training"""

    def schedule(progress_remaining: float) -> float:
        return progress_remaining * initial_value

    return schedule


def yaml_setting(env_id: str) -> tuple[int, dict[str, Any]]:
    """
    :param env_id: an env of ``hyperparams/nstep_sarsa.yml``
    :return: its entry's ``n_envs`` and the model's arguments, read as the zoo reads them (``lin_`` a linear schedule,
        ``policy_kwargs`` evaluated), one learning-rate schedule object for all the members (a setting they share)
    """
    hyperparams = load_hyperparams("nstep_sarsa", env_id)
    n_envs = int(hyperparams.pop("n_envs", 1))
    for key in ("n_timesteps", "policy"):
        hyperparams.pop(key, None)
    learning_rate = hyperparams.get("learning_rate")
    if isinstance(learning_rate, str) and learning_rate.startswith("lin_"):
        hyperparams["learning_rate"] = linear_schedule(float(learning_rate[len("lin_") :]))
    if isinstance(hyperparams.get("policy_kwargs"), str):
        hyperparams["policy_kwargs"] = eval(hyperparams["policy_kwargs"], {"__builtins__": {}, "dict": dict})
    return n_envs, hyperparams


def make_yaml_models(env_id: str, k: int) -> list[NStepSARSA]:
    """:return: K members of the YAML's entry for ``env_id``, seeds 0..K-1, each with its own envs seeded as its model"""
    n_envs, hyperparams = yaml_setting(env_id)
    return [
        NStepSARSA("MlpPolicy", make_vec_env(env_id, n_envs=n_envs, seed=seed), seed=seed, **hyperparams) for seed in range(k)
    ]


def batch_rows(env_ids: list[str], k: int, steps: int, repeats: int) -> list[dict[str, Any]]:
    """:return: the rows of the YAML's batch-mode entries, one per env"""
    rows = []
    for env_id in env_ids:
        n_envs, hyperparams = yaml_setting(env_id)
        setting = (
            f"batch: hyperparams/nstep_sarsa.yml's {env_id} entry (n_envs {n_envs}, train_freq {hyperparams['train_freq']}, "
            f"gradient_steps {hyperparams['gradient_steps']}, 2x256 MLP)"
        )
        seconds = timed(lambda env_id=env_id: make_yaml_models(env_id, k), steps, repeats)  # type: ignore[misc]
        rows.append(row("NStepSARSA", env_id, setting, k, steps, seconds))
    return rows


def _policy_kwargs(value: str | dict[str, Any] | None) -> dict[str, Any]:
    """
    :param value: ``policy_kwargs`` as a zoo YAML writes it (a string the zoo evaluates, with ``nn`` for torch.nn) or
        as a study YAML does (a mapping, classes named ``nn.X``)
    :return: the keyword arguments
    """
    if value is None:
        return {}
    if isinstance(value, str):
        return dict(eval(value, {"nn": th.nn, "dict": dict}))  # the zoo's own parsing of the string
    return {
        key: getattr(th.nn, item[3:]) if isinstance(item, str) and item.startswith("nn.") else item
        for key, item in value.items()
    }


def reinforce_settings() -> list[tuple[str, str, dict[str, Any]]]:
    """:return: (env id, setting name, REINFORCE's keyword arguments) of each REINFORCE row"""
    settings = []
    for env_id in N_STEPS:
        entry = load_hyperparams("reinforce", env_id)
        kwargs = {key: value for key, value in entry.items() if key not in ("n_timesteps", "policy", "n_envs")}
        kwargs["policy_kwargs"] = _policy_kwargs(kwargs.get("policy_kwargs"))
        settings.append((env_id, "batch: hyperparams/reinforce.yml", kwargs))
    for figure, path in FINAL_PER_STEP.items():
        study = yaml.safe_load(path.read_text())
        kwargs = {key: value for key, value in study["hyperparams"].items() if key not in ("policy", "n_envs")}
        kwargs["policy_kwargs"] = _policy_kwargs(kwargs.get("policy_kwargs"))
        settings.append((study["env"], f"per_step: the seed report's final model ({figure})", kwargs))
    return settings


def make_reinforce_models(env_id: str, k: int, kwargs: dict[str, Any]) -> list[REINFORCE]:
    """:return: K REINFORCE members of one setting, seeds 0..K-1, each with its own env seeded as its model"""
    return [REINFORCE("MlpPolicy", make_vec_env(env_id, n_envs=1, seed=seed), seed=seed, **kwargs) for seed in range(k)]


def reinforce_rows(family: str, env_ids: list[str], k: int, steps: int, repeats: int) -> list[dict[str, Any]]:
    """:return: the REINFORCE rows of one family of settings (``per_step`` or ``batch``) on the given envs"""
    rows = []
    for env_id, setting, kwargs in reinforce_settings():
        if env_id not in env_ids or not setting.startswith(family):
            continue
        seconds = timed(lambda env_id=env_id, kwargs=kwargs: make_reinforce_models(env_id, k, kwargs), steps, repeats)  # type: ignore[misc]
        rows.append(row("REINFORCE", env_id, setting, k, steps, seconds))
    return rows


def row(algo: str, env_id: str, setting: str, k: int, steps: int, seconds: tuple[float, float, float]) -> dict[str, Any]:
    """
    :param seconds: ``timed``'s: one after the other, in lockstep, lockstep's floor
    :return: a row of the CSV (``steps`` is kept for the page, not written to the CSV), printed as it is made
    """
    separate, lockstep, floor_s = seconds
    print(f"{algo} {env_id}, {setting.split(':')[0]}: separate {separate:.2f} s, lockstep {lockstep:.2f} s, "
          f"{separate / lockstep:.2f}x (floor {floor_s:.2f} s, at most {separate / floor_s:.2f}x)", flush=True)  # fmt: skip
    return dict(algo=algo, env_id=env_id, setting=setting, k=k, separate_cpu_s=f"{separate:.2f}",
                lockstep_cpu_s=f"{lockstep:.2f}", steps=steps, floor_cpu_s=f"{floor_s:.2f}")  # fmt: skip


def ratio(seconds: str, other: str) -> str:
    """:return: ``seconds`` over ``other`` (the CSV's text), as the page writes it; a dash where ``other`` rounds to 0"""
    return f"{float(seconds) / float(other):.2f}×" if float(other) else "—"


def cpu_model() -> str:
    """:return: the CPU's model name (Linux's ``/proc/cpuinfo``), or the machine type where it cannot be read"""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return f"{line.split(':', 1)[1].strip()} ({platform.machine()})"
    except OSError:
        pass
    return platform.processor() or platform.machine()


def settings_list(text: str) -> list[str]:
    """:return: the families of settings named in ``text`` (comma-separated), each one of ``SETTINGS``"""
    names = [name.strip() for name in text.split(",") if name.strip()]
    unknown = [name for name in names if name not in SETTINGS]
    if unknown or not names:
        raise argparse.ArgumentTypeError(f"{text!r}: name some of {', '.join(SETTINGS)}, comma-separated")
    return names


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--k", type=positive_int, default=10, help="seeds (members)")
    parser.add_argument("--steps", type=positive_int, default=3000, help="env steps per seed of the per-step settings")
    parser.add_argument(
        "--batch-steps", type=positive_int, default=20000, help="env steps per seed (all its envs) of the batch settings"
    )
    parser.add_argument("--many-k", type=positive_int, default=30, help="seeds of the many_seeds row")
    parser.add_argument("--many-steps", type=positive_int, default=1000, help="env steps per seed of the many_seeds row")
    parser.add_argument(
        "--repeats", type=positive_int, default=3, help="times each way is timed; the medians are reported (default 3)"
    )
    parser.add_argument("--env", nargs="+", default=list(N_STEPS), choices=list(N_STEPS))
    parser.add_argument(
        "--settings", type=settings_list, default=list(SETTINGS), help=f"comma-separated, of {', '.join(SETTINGS)}"
    )
    parser.add_argument("--algo", nargs="+", default=list(ALGOS), choices=list(ALGOS), help="the algorithms' rows")
    parser.add_argument("--out", type=Path, default=RESULTS, help="the folder of lockstep.csv and lockstep.md")
    args = parser.parse_args(argv)
    th.set_num_threads(1)
    rows = []
    if "NStepSARSA" in args.algo and "per_step" in args.settings:
        rows += per_step_rows(args.env, args.k, args.steps, args.repeats)
    if "NStepSARSA" in args.algo and "batch" in args.settings:
        rows += batch_rows(args.env, args.k, args.batch_steps, args.repeats)
    if "NStepSARSA" in args.algo and "many_seeds" in args.settings:
        rows += per_step_rows(["CartPole-v1"], args.many_k, args.many_steps, args.repeats)
    if "REINFORCE" in args.algo and "per_step" in args.settings:
        rows += reinforce_rows("per_step", args.env, args.k, args.steps, args.repeats)
    if "REINFORCE" in args.algo and "batch" in args.settings:
        rows += reinforce_rows("batch", args.env, args.k, args.batch_steps, args.repeats)
    args.out.mkdir(parents=True, exist_ok=True)
    columns = ["algo", "env_id", "setting", "k", "separate_cpu_s", "lockstep_cpu_s", "floor_cpu_s"]
    with open(args.out / "lockstep.csv", "w", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=columns, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    command = "python -m benchmarks.lockstep " + shlex.join(argv if argv is not None else sys.argv[1:])
    table = "\n".join(
        f"| {row['algo']} | {row['env_id']} | {row['setting'].split(':')[0]} | {row['k']} | {row['steps']} | "
        f"{row['separate_cpu_s']} | "
        f"{row['lockstep_cpu_s']} | {ratio(row['separate_cpu_s'], row['lockstep_cpu_s'])} | "
        f"{row['floor_cpu_s']} | {ratio(row['separate_cpu_s'], row['floor_cpu_s'])} |"
        for row in rows
    )
    settings = "\n".join(f"- {row['algo']}, {row['env_id']}, {row['setting']}" for row in rows)
    timings = f"the median of {args.repeats} timings of each way" if args.repeats > 1 else "one timing of each way"
    (args.out / "lockstep.md").write_text(
        f"""# K seeds in lockstep against one after the other

CPU seconds (`time.process_time`) of training only, one process, one PyTorch thread
(OMP_NUM_THREADS={os.environ.get("OMP_NUM_THREADS", "unset")}), {timings}. The settings:

{settings}

    {command.strip()}

Machine: {cpu_model()}, {os.cpu_count()} logical CPUs, Python {platform.python_version()}, torch {th.__version__}. The
ratios depend on the CPU (its matrix products against its Python overhead): compare code on one machine.

| algorithm | env | setting | K | env steps per seed | one after the other (s) | lockstep (s) | ratio | floor (s) | at most |
|---|---|---|---|---|---|---|---|---|---|
{table}

*Floor*: in a third run of the same population, the CPU seconds of the stacked calls (the forward passes that choose
the members' actions and the stacked gradient steps) and of the members' envs (SB3's `DummyVecEnv.step_wait`: Monitor,
Gymnasium's wrappers, the env and its resets). The rest of a lockstep run is each member's own code per env step, run
as in its separate run, which is what makes a member its separate run: its ε-greedy draw or action sample, its buffer,
its update's windows and targets with their bootstrap values, the moves of its copies of q̂, its logger and callbacks.
*At most*: one after the other over the floor, the ratio lockstep would reach were that code of the members' free. A
ratio above it would take a cheaper stacked step or the members' envs stepped as arrays across members (a vectorised
env in place of each member's `VecEnv`).

Where the floor goes. In the per-step settings, one stacked gradient step per env step, and, for SARSA, about four
stacked forward passes per gradient step: at an episode's start a member takes its first n − 1 env steps before the
others' next gradient step, each with a forward pass. In the batch settings, SARSA's stacked gradient steps through
2 × 256 layers on batches of about 128 transitions are bound by arithmetic: stacked, a forward and backward pass costs
what the ten networks' own passes cost, so lockstep saves the per-call overhead of the rollouts' forward passes and of
Adam, not the gradients' arithmetic; on Acrobot-v1 the envs add their physics' four Runge-Kutta stages per step.
REINFORCE's batch updates, one per episode and member, seldom fall on the same env step, so most of its stacked
gradient steps train one member; what it shares is the rollouts' forward passes. Its per-step mode trains an episode's
T steps one stacked gradient step at a time while the other members go on with theirs, and shares those steps too.
"""
    )


if __name__ == "__main__":
    main()
