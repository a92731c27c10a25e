"""The benchmark harness's own logic: threshold crossings, episode counts, cache keys, budgets, throughput, hot paths."""

import contextlib
import dataclasses
import json
import os
import queue
import subprocess
import sys
import time
from collections.abc import Callable
from concurrent.futures import Future
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pandas as pd
import pytest
import yaml
from rich.console import Console

from benchmarks import hot_paths, masking, per_step_speed, textbook
from benchmarks.common import ENV_IDS, OPTIONAL_ENV_IDS, REPO_ROOT, THRESHOLDS, parse_overrides
from benchmarks.report import (
    RUN_COLUMNS,
    Results,
    episode_curves,
    episodes_by,
    first_crossing,
    load_results,
    stability,
    stayed_counts,
    summary_table,
    threshold_crossings,
    write_learning_report,
)
from benchmarks.run import FULL, QUICK, learning_header, main, make_specs, parse_budgets
from benchmarks.throughput import (
    build_model,
    measure,
    throughput_ratios,
    throughput_table,
    time_breakdown_table,
)
from benchmarks.throughput import main as throughput_main
from sb3_classic import NStepSARSA
from sb3_classic.harness import pool, runner
from sb3_classic.harness.common import ALL_ALGOS, RunSpec, code_versions, hyperparams_path, register_algorithms
from sb3_classic.harness.runner import EPISODES_FILE, EVALUATIONS_FILE, RUN_FILE, episodes_from_monitors, run_one
from sb3_classic.sarsa.policies import LinearQPolicy

SPEC = RunSpec(
    algo="reinforce",
    env_id="CartPole-v1",
    seed=0,
    n_timesteps=1000,
    eval_freq=500,
    n_eval_episodes=2,
    hyperparams_yaml="learning_rate: 0.003\npolicy: MlpPolicy\n",
)


def test_first_crossing() -> None:
    steps = np.array([1000, 2000, 3000, 4000])
    assert first_crossing(steps, np.array([100.0, 480.0, 300.0, 500.0]), 475.0) == 2000
    # Reaching the threshold counts; for Acrobot it is negative
    assert first_crossing(steps, np.array([-500.0, -120.0, -100.0, -80.0]), -100.0) == 3000
    assert first_crossing(steps, np.array([10.0, 20.0, 30.0, 474.9]), 475.0) is None
    assert first_crossing(np.array([]), np.array([]), 475.0) is None


def test_episodes_by() -> None:
    end_steps = np.array([20, 45, 45, 100])
    assert episodes_by(end_steps, 19) == 0
    assert episodes_by(end_steps, 45) == 3
    assert episodes_by(end_steps, 10_000) == 4


def write_monitor(path: Path, lengths: list[int]) -> None:
    rows = "".join(f"{float(length)},{length},{index * 0.1:.1f}\n" for index, length in enumerate(lengths))
    path.write_text('#{"t_start": 0.0, "env_id": "CartPole-v1"}\nr,l,t\n' + rows)


def test_episodes_from_monitors_orders_the_envs_by_end_step(tmp_path: Path) -> None:
    # Two envs in lockstep: env 0 ends episodes at its steps 3 and 5, env 1 at its step 2 (run steps ×2)
    write_monitor(tmp_path / "0.monitor.csv", [3, 2])
    write_monitor(tmp_path / "1.monitor.csv", [2])
    episodes = episodes_from_monitors(tmp_path, n_envs=2)
    assert episodes["episode"].tolist() == [1, 2, 3]
    assert episodes["env_rank"].tolist() == [1, 0, 0]
    assert episodes["end_step"].tolist() == [4, 6, 10]
    assert episodes["return"].tolist() == [2.0, 3.0, 2.0]


def synthetic_results() -> Results:
    """Three CartPole-v1 seeds of REINFORCE: reaching 475 at 2000 and 3000 steps, and never."""
    timesteps = [1000, 2000, 3000]
    mean_returns = {0: [100.0, 480.0, 490.0], 1: [50.0, 200.0, 475.0], 2: [20.0, 30.0, 40.0]}
    evaluations = pd.DataFrame(
        [
            {"algo": "reinforce", "env_id": "CartPole-v1", "seed": seed, "eval_index": index, "timesteps": step, "return": r}
            for seed, returns in mean_returns.items()
            for index, (step, mean) in enumerate(zip(timesteps, returns, strict=True))
            # Two episodes per evaluation around the mean
            for r in (mean - 1.0, mean + 1.0)
        ]
    )
    # One training episode ends every 250 steps for seed 0, every 500 steps for the others
    episodes = pd.DataFrame(
        [
            {"algo": "reinforce", "env_id": "CartPole-v1", "seed": seed, "episode": index + 1, "end_step": end, "return": 1.0}
            for seed, every in ((0, 250), (1, 500), (2, 500))
            for index, end in enumerate(range(every, 3001, every))
        ]
    )
    runs = pd.DataFrame(
        [
            {
                "algo": "reinforce",
                "env_id": "CartPole-v1",
                "seed": seed,
                "n_envs": 1,
                "num_timesteps": 3000,
                "n_episodes": 3000 // every,
                "learn_time_s": 10.0,
                "steps_per_s": 300.0,
            }
            for seed, every in ((0, 250), (1, 500), (2, 500))
        ]
    )
    return Results(runs=runs, episodes=episodes, evaluations=evaluations, missing=[])


def test_threshold_crossings() -> None:
    crossings = threshold_crossings(synthetic_results()).set_index("seed")
    assert crossings.loc[0, "steps_to_threshold"] == 2000
    assert crossings.loc[0, "episodes_to_threshold"] == 8
    assert crossings.loc[1, "steps_to_threshold"] == 3000
    assert crossings.loc[1, "episodes_to_threshold"] == 6
    assert np.isnan(crossings.loc[2, "steps_to_threshold"])
    assert np.isnan(crossings.loc[2, "episodes_to_threshold"])
    assert crossings["final_return"].tolist() == [490.0, 475.0, 40.0]


def test_summary_table() -> None:
    results = synthetic_results()
    table = summary_table(results, threshold_crossings(results), "CartPole-v1", ["reinforce", "a2c"])
    # A2C has no runs: no row
    assert table["Algorithm"].tolist() == ["REINFORCE"]
    row = table.iloc[0]
    assert row["Seeds"] == 3
    assert row["Seeds reaching 475"] == "2/3"
    assert row["Env steps to threshold"] == "2,500 (2,000–3,000)"
    assert row["Episodes to threshold"] == "7 (6–8)"
    assert row["Final eval return"] == f"335.0 ± {np.std([490.0, 475.0, 40.0], ddof=1):.1f}"
    # Seeds 0 and 1 end at 475 or above; after their first evaluation at 475 seed 0 has one more (490), seed 1 none
    assert row["Final ≥ 475"] == "2/3"
    assert row["Stayed"] == "100% (worst seed 100%)"


def test_stayed_counts() -> None:
    # Acrobot: the threshold is negative, reaching it counts, the first reaching evaluation is not counted again
    assert stayed_counts(np.array([-500.0, -100.0, -90.0, -500.0, -95.0]), -100.0) == (2, 3)
    assert stayed_counts(np.array([-500.0, -300.0]), -100.0) is None
    assert stayed_counts(np.array([-500.0, -99.0]), -100.0) == (0, 0)


def test_stability_pools_later_evaluations_and_reports_the_worst_seed() -> None:
    runs = {
        # reaches at index 1, then 3 of 4 later evaluations stay
        0: np.array([-500.0, -90.0, -95.0, -500.0, -80.0, -85.0]),
        # reaches at index 0, then 1 of 2 stays, and ends below
        1: np.array([-100.0, -80.0, -120.0]),
        # never reaches
        2: np.array([-500.0, -500.0, -500.0]),
        # reaches only at its last evaluation: no later evaluations, nothing to pool
        3: np.array([-500.0, -300.0, -99.0]),
    }
    stab = stability(runs, -100.0)
    assert stab["runs"] == 4
    assert stab["reached"] == 3
    assert stab["final_at"] == 2
    assert stab["stayed_pooled"] == pytest.approx(4 / 6)
    assert stab["stayed_median"] == pytest.approx((0.75 + 0.5) / 2)
    assert stab["stayed_min"] == 0.5
    assert np.isnan(stability({0: np.array([-500.0, -99.0])}, -100.0)["stayed_pooled"])


def test_summary_table_stability_columns() -> None:
    results = synthetic_results()
    # Seed 0 falls back below 475 at the end: 480, then 400
    seed0_last = (results.evaluations["seed"] == 0) & (results.evaluations["eval_index"] == 2)
    results.evaluations.loc[seed0_last, "return"] -= 90.0
    row = summary_table(results, threshold_crossings(results), "CartPole-v1", ["reinforce"]).iloc[0]
    assert row["Seeds reaching 475"] == "2/3"
    assert row["Final ≥ 475"] == "1/3"
    # Only seed 0 has evaluations after its first at 475 (one, at 400)
    assert row["Stayed"] == "0% (worst seed 0%)"


def cache_run(
    cache_dir: Path, spec: RunSpec, summary: dict[str, Any], episodes: pd.DataFrame, evaluations: pd.DataFrame
) -> None:
    """Write a finished run's files into the cache, as the runner does (the tables without the run's labels)."""
    run_dir = spec.run_dir(cache_dir)
    run_dir.mkdir(parents=True)
    (run_dir / RUN_FILE).write_text(json.dumps(summary))
    episodes.drop(columns=RUN_COLUMNS).to_csv(run_dir / EPISODES_FILE, index=False)
    evaluations.drop(columns=RUN_COLUMNS).to_csv(run_dir / EVALUATIONS_FILE, index=False)


def test_a_run_that_ended_no_episode_is_reported_as_one_with_none(tmp_path: Path) -> None:
    # NStepSARSA's 8 Acrobot-v1 envs end no episode in a budget of 2,000 steps: the run's episodes.csv is a header only,
    # read back with object-typed columns, which made the columns of all the runs' episodes object-typed and the
    # episode plot fail (TypeError in fill_between)
    synthetic = synthetic_results()
    specs = [dataclasses.replace(SPEC, seed=seed) for seed in (0, 1, 2)]
    for spec in specs:
        summary = json.loads(synthetic.runs[synthetic.runs["seed"] == spec.seed].iloc[0].to_json())
        episodes, evaluations = (table[table["seed"] == spec.seed] for table in (synthetic.episodes, synthetic.evaluations))
        cache_run(tmp_path / "cache", spec, summary, episodes, evaluations)
    # An NStepSARSA run that evaluates as REINFORCE's seed 2 (never at the threshold) and ended no episode
    no_episode = dataclasses.replace(SPEC, algo="nstep_sarsa", seed=2)
    summary = {**json.loads(synthetic.runs.iloc[2].to_json()), "algo": "nstep_sarsa", "n_episodes": 0}
    evaluations = synthetic.evaluations[synthetic.evaluations["seed"] == 2]
    cache_run(tmp_path / "cache", no_episode, summary, synthetic.episodes.iloc[:0], evaluations)

    results = load_results([*specs, no_episode], tmp_path / "cache")
    assert results.episodes.dtypes[["episode", "return", "end_step"]].tolist() == ["int64", "float64", "int64"]
    assert (results.episodes["algo"] == "reinforce").all()
    path = write_learning_report(results, ["CartPole-v1"], ["reinforce", "nstep_sarsa"], "# Learning", tmp_path / "results")
    rows = {row[0]: row for row in (line.split(" | ") for line in path.read_text().splitlines() if line.startswith("| "))}
    # REINFORCE's row as from its runs alone (test_summary_table); NStepSARSA's as a run that never reached 475
    assert rows["| REINFORCE"][4:9] == ["2/3", "2/3", "100% (worst seed 100%)", "2,500 (2,000–3,000)", "7 (6–8)"]
    assert rows["| NStepSARSA"][1:10] == ["1", "1", "40.0 ± 0.0", "0/1", "0/1", "–", "–", "–", "0 (0–0)"]
    for name in ("CartPole-v1-episodes.png", "CartPole-v1-steps.png"):
        assert (tmp_path / "results" / name).stat().st_size > 0
    per_run = pd.read_csv(tmp_path / "results" / "learning-runs.csv").set_index("algo")
    assert per_run.loc["nstep_sarsa", "n_episodes"] == 0
    assert np.isnan(per_run.loc["nstep_sarsa", "episodes_to_threshold"])


def test_run_key_covers_what_changes_the_result(tmp_path: Path) -> None:
    variants = [
        dataclasses.replace(SPEC, algo="nstep_sarsa"),
        dataclasses.replace(SPEC, env_id="Acrobot-v1"),
        dataclasses.replace(SPEC, seed=1),
        dataclasses.replace(SPEC, n_timesteps=2000),
        dataclasses.replace(SPEC, eval_freq=250),
        dataclasses.replace(SPEC, n_eval_episodes=3),
        dataclasses.replace(SPEC, hyperparams_yaml="learning_rate: 0.001\npolicy: MlpPolicy\n"),
    ]
    run_dirs = {spec.run_dir(tmp_path) for spec in [SPEC, *variants]}
    assert len(run_dirs) == len(variants) + 1
    # The same hyperparameters written another way are the same run
    reordered = dataclasses.replace(SPEC, hyperparams_yaml="policy: 'MlpPolicy'\nlearning_rate: !!float 3e-3\n")
    assert reordered.run_dir(tmp_path) == SPEC.run_dir(tmp_path)
    assert SPEC.run_dir(tmp_path).relative_to(tmp_path).parts[:3] == ("CartPole-v1", "reinforce", "seed_0")


def test_code_versions() -> None:
    # Our algorithms' runs depend on the package's sources, the peers' do not
    assert "sb3_classic" in code_versions("reinforce")
    assert "sb3_classic" not in code_versions("a2c")
    assert code_versions("a2c").items() <= code_versions("reinforce").items()


def test_a_run_is_not_trained_with_other_code_than_the_commands(monkeypatch: pytest.MonkeyPatch) -> None:
    # The package's sources edited while a study ran: every run trained, and store_run then refused each result
    # ("trained on <host> with other versions than this process's"), hours lost
    trained: list[RunSpec] = []
    monkeypatch.setattr(runner, "execute_run", lambda spec, queue: trained.append(spec))
    started = {**code_versions("reinforce"), "sb3_classic": "0.1.0+000000000000"}
    with pytest.raises(
        ValueError, match=r"was not trained: the installed code changed since this command started \(sb3_classic"
    ):
        runner.run_in_worker(SPEC, started)
    assert trained == []
    runner.run_in_worker(SPEC, code_versions("reinforce"))
    assert trained == [SPEC]


def test_parse_budgets() -> None:
    envs = ["CartPole-v1", "Acrobot-v1"]
    defaults = {"CartPole-v1": 5, "Acrobot-v1": 6}
    assert parse_budgets([], envs, defaults) == defaults
    assert parse_budgets(["3e5"], envs, defaults) == {"CartPole-v1": 300_000, "Acrobot-v1": 300_000}
    assert parse_budgets(["1e5", "Acrobot-v1=2000"], envs, defaults) == {"CartPole-v1": 100_000, "Acrobot-v1": 2000}
    with pytest.raises(ValueError, match="MountainCar-v0"):
        parse_budgets(["MountainCar-v0=1000"], envs, defaults)
    with pytest.raises(ValueError, match="positive number"):
        parse_budgets(["CartPole-v1=lots"], envs, defaults)


def test_lunar_lander_is_benchmarked_when_named() -> None:
    # The default envs stay those of the committed benchmark; LunarLander-v3 runs with its own budget, Gymnasium's
    # "solved" threshold, and each algorithm's own entry there (not the default entry of our YAMLs)
    assert ENV_IDS == ("CartPole-v1", "Acrobot-v1")
    assert "LunarLander-v3" in OPTIONAL_ENV_IDS
    assert THRESHOLDS["LunarLander-v3"] == gym.spec("LunarLander-v3").reward_threshold == 200
    specs = make_specs(FULL, ["LunarLander-v3"], ALL_ALGOS, lockstep=False)
    assert {spec.n_timesteps for spec in specs} == {FULL.budgets["LunarLander-v3"]} == {500_000}
    for algo in ALL_ALGOS:
        entry = yaml.safe_load(hyperparams_path(algo).read_text())["LunarLander-v3"]
        assert all(spec.hyperparams == entry for spec in specs if spec.algo == algo), algo


def test_make_specs_share_budgets_and_seeds() -> None:
    specs = make_specs(FULL, ["CartPole-v1", "Acrobot-v1"], ["reinforce", "nstep_sarsa", "a2c", "ppo", "dqn"])
    seeds = {
        algo: sorted(spec.seed for spec in specs if spec.algo == algo and spec.env_id == "CartPole-v1")
        for algo in ["a2c", "reinforce"]
    }
    assert seeds == {"a2c": list(range(FULL.peer_seeds)), "reinforce": list(range(FULL.seeds))}
    assert len(specs) == 2 * (2 * FULL.seeds + 3 * FULL.peer_seeds)
    for env_id in ("CartPole-v1", "Acrobot-v1"):
        assert {spec.n_timesteps for spec in specs if spec.env_id == env_id} == {FULL.budgets[env_id]}
    assert len({spec.name for spec in specs}) == len(specs)
    assert QUICK.budgets["CartPole-v1"] < FULL.budgets["CartPole-v1"]


def test_throughput_ratios_pair_each_repeat() -> None:
    rows = [
        {"env_id": "CartPole-v1", "n_envs": n_envs, "repeat": repeat, "algo": algo, "steps_per_s": sps}
        for n_envs, repeat, algo, sps in [
            (1, 0, "a2c", 1000.0),
            (1, 0, "reinforce", 3000.0),
            (1, 0, "nstep_sarsa", 1000.0),
            (1, 1, "a2c", 500.0),  # a slow moment of the machine: the ratio of the repeat holds
            (1, 1, "reinforce", 2000.0),
            (1, 1, "nstep_sarsa", 600.0),
        ]
    ]
    ratios = throughput_ratios(pd.DataFrame(rows)).set_index("algo")
    assert ratios.loc["reinforce", "ratio_min"] == 3.0
    assert ratios.loc["reinforce", "ratio_max"] == 4.0
    assert ratios.loc["reinforce", "ratio"] == 3.5
    assert ratios.loc["nstep_sarsa", "ratio"] == pytest.approx(1.1)
    table = throughput_table(pd.DataFrame(rows))
    assert table.loc[0, "REINFORCE / A2C"] == "3.50× (3.00–4.00)"
    assert table.loc[0, "REINFORCE ≥ 2×"] == "yes"
    assert table.loc[0, "NStepSARSA ≥ 2×"] == "no"


def test_time_breakdown_is_per_10k_steps_and_the_rest_is_what_env_and_train_leave() -> None:
    rows = [
        {"env_id": "Acrobot-v1", "n_envs": 8, "repeat": repeat, "algo": "nstep_sarsa", "steps": steps, **times}
        for repeat, steps, times in [
            (0, 20_000, {"seconds": 2.0, "env_s": 1.0, "train_s": 0.6}),
            (1, 20_000, {"seconds": 2.2, "env_s": 1.2, "train_s": 0.8}),
            (2, 20_000, {"seconds": 9.0, "env_s": 1.1, "train_s": 0.7}),  # a stall of the machine: the median holds
        ]
    ]
    table = time_breakdown_table(pd.DataFrame(rows))
    assert len(table) == 1
    row = table.iloc[0]
    assert row["Algorithm"] == "NStepSARSA"
    assert row["learn() s"] == "1.100"  # the median 2.2 s per 20k steps
    assert row["env.step s"] == "0.550 (50%)"
    assert row["train() s"] == "0.350 (32%)"
    assert row["rest of the loop s"] == "0.200 (18%)"  # median of 0.2, 0.1 and 3.6 s per 10k


@pytest.mark.parametrize("algo", ["a2c", "nstep_sarsa"])
def test_measure_times_the_envs_and_train_inside_learn(algo: str, tmp_path: Path) -> None:
    register_algorithms()
    result = measure(algo, "CartPole-v1", 2, 400, 0, tmp_path)
    assert result["steps"] >= 400
    assert 0 < result["env_s"] < result["seconds"]
    assert 0 < result["train_s"] < result["seconds"]
    assert result["env_s"] + result["train_s"] < result["seconds"]


def test_throughput_set_changes_one_algorithms_entry_but_not_the_throughputs_own_keys(tmp_path: Path) -> None:
    register_algorithms()
    overrides = {"nstep_sarsa": {"gradient_steps": 4, "n_envs": 3}}
    sarsa = build_model("nstep_sarsa", "CartPole-v1", 2, 0, tmp_path, overrides)
    assert sarsa.gradient_steps == 4  # type: ignore[attr-defined]
    assert sarsa.n_envs == 2  # the measured number of envs wins
    assert sarsa.policy.q_net.q_net[0].out_features == 64  # type: ignore[union-attr,index]
    assert build_model("nstep_sarsa", "CartPole-v1", 2, 0, tmp_path).gradient_steps == 8  # type: ignore[attr-defined]
    assert build_model("a2c", "CartPole-v1", 2, 0, tmp_path, overrides).n_envs == 2


def test_throughput_set_needs_a_results_dir(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        throughput_main(["--set", "nstep_sarsa.gradient_steps=4"])
    assert "--set needs --results-dir" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("command", "argv", "message"),
    [
        # 0 is refused, not taken as "the default" (`args.steps or default`), which would run the full benchmark
        (throughput_main, ["--steps", "0"], "--steps: '0' is not an integer >= 1"),
        (throughput_main, ["--steps", "-100"], "--steps: '-100' is not an integer >= 1"),
        (throughput_main, ["--n-envs", "0"], "--n-envs: '0' is not an integer >= 1"),
        (main, ["--seeds", "-3"], "--seeds: '-3' is not an integer >= 0"),
        (main, ["--algos", "a2c", "--peer-seeds", "0"], "no run of ['a2c'] to make"),
        (main, ["--eval-freq", "0"], "--eval-freq: '0'"),
        (main, ["--workers", "0"], "--workers: '0'"),
        (main, ["--budget", "CartPol-v1=100"], "'CartPol-v1' is not one of the envs benchmarked"),
        # --envs accepts LunarLander-v3, and then the budgets are those of the envs named
        (main, ["--envs", "LunarLander-v3", "--budget", "Acrobot-v1=100"], "not one of the envs benchmarked (LunarLander-v3)"),
        (textbook.main, ["--runs", "7.3=4"], "'7.3' is not one of the figures"),
        (textbook.main, ["--workers", "0"], "--workers: '0'"),
        (per_step_speed.main, ["--repeats", "zero"], "--repeats: 'zero' is not an integer >= 1"),
    ],
)
def test_benchmark_counts_are_refused_as_usage_errors(
    command: Any, argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exit_:
        command(argv)
    assert exit_.value.code == 2
    assert message in capsys.readouterr().err


def test_hot_paths_variants_are_what_they_say() -> None:
    implementations = {}
    for name, kwargs in hot_paths.ADAM_VARIANTS.items():
        model = NStepSARSA("MlpPolicy", "CartPole-v1", policy_kwargs=dict(optimizer_kwargs=kwargs), device="cpu")
        defaults = model.policy.optimizer.defaults
        implementations[name] = "fused" if defaults["fused"] else "foreach" if defaults["foreach"] else "loop"
    assert list(implementations.values()) == ["loop", "foreach", "fused"]
    assert "default" in next(name for name, implementation in implementations.items() if implementation == "fused")


def test_hot_paths_command_line(tmp_path: Path) -> None:
    hot_paths.main(["--quick", "--envs", "CartPole-v1", "--results-dir", str(tmp_path)])
    lines = (tmp_path / "hot_paths.md").read_text().splitlines()
    rows = [line.split(" | ") for line in lines if line.startswith("| ") and "CartPole-v1" in line]
    # 3 Adam implementations, then SB3's and REINFORCE's sampling for 1 and for 8 envs
    assert len(rows) == len(hot_paths.ADAM_VARIANTS) + 4
    assert [row[-1] for row in rows if row[2].startswith(("Adam, loop", "SB3"))] == ["1.00× |"] * 3
    # Then the linear update of Mountain Car's tile coding: through autograd, directly on the dense features, over the tiles
    linear = [line.split(" | ") for line in lines if "MountainCar-v0" in line]
    variants = [
        "autograd + torch.optim.SGD",
        "applied directly to the dense features",
        "over the active tiles (sb3_classic's)",
    ]
    assert [row[2] for row in linear] == variants
    assert all(float(row[3]) > 0 for row in rows + linear)
    # Each variant's model takes its own path
    models = [update.func.__self__ for update in hot_paths.linear_sgd_updates().values()]  # type: ignore[attr-defined]
    assert [isinstance(model.policy, LinearQPolicy) for model in models] == [False, True, True]
    assert [getattr(model.policy, "tile_coding", None) is not None for model in models] == [False, False, True]


def test_run_one_trains_once_and_caches(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    spec = RunSpec.create("reinforce", "CartPole-v1", seed=0, n_timesteps=300, eval_freq=100, n_eval_episodes=2)
    summary = run_one(spec, tmp_path)
    run_dir = spec.run_dir(tmp_path)
    assert json.loads((run_dir / RUN_FILE).read_text()) == summary
    assert summary["num_timesteps"] >= 300
    assert summary["steps_per_s"] > 0
    evaluations = pd.read_csv(run_dir / runner.EVALUATIONS_FILE)
    # Every 100 steps, and the last one at the end of training
    assert evaluations["timesteps"].unique().tolist()[:3] == [100, 200, 300]
    assert evaluations["timesteps"].iloc[-1] == summary["num_timesteps"]
    assert (evaluations.groupby("eval_index").size() == 2).all()
    episodes = pd.read_csv(run_dir / runner.EPISODES_FILE)
    assert len(episodes) == summary["n_episodes"] > 0
    assert episodes["end_step"].is_monotonic_increasing
    assert not list(tmp_path.rglob("*.partial"))

    # A cached run is read back, not run again
    def fail(*args: object) -> None:
        raise AssertionError("a cached run was trained again")

    monkeypatch.setattr(runner, "_train", fail)
    assert run_one(spec, tmp_path) == summary


def test_command_line(tmp_path: Path) -> None:
    """The real command, on one small run: the cache, the report and its command line."""
    command = [
        sys.executable,
        "-m",
        "benchmarks.run",
        *("--envs", "CartPole-v1", "--algos", "nstep_sarsa", "--seeds", "1", "--peer-seeds", "0"),
        *("--budget", "300", "--eval-freq", "100", "--eval-episodes", "2", "--workers", "1"),
        *("--cache-dir", str(tmp_path / "cache"), "--results-dir", str(tmp_path / "results"), "--skip-throughput"),
    ]
    completed = subprocess.run(command, cwd=REPO_ROOT, capture_output=True, text=True, timeout=300)
    assert completed.returncode == 0, completed.stdout + completed.stderr
    markdown = (tmp_path / "results" / "learning.md").read_text()
    assert "python -m benchmarks.run --envs CartPole-v1 --algos nstep_sarsa" in markdown
    assert "| NStepSARSA | 1 |" in markdown
    for name in ("CartPole-v1-episodes.png", "CartPole-v1-steps.png", "learning-runs.csv"):
        assert (tmp_path / "results" / name).stat().st_size > 0
    assert len(list((tmp_path / "cache").rglob(RUN_FILE))) == 1


def test_episode_curves_share_the_episodes_every_run_completed() -> None:
    results = synthetic_results()
    # A second algorithm whose only seed completed 4 episodes
    other = results.episodes[results.episodes["seed"] == 1].head(4).assign(algo="nstep_sarsa")
    results.episodes = pd.concat([results.episodes, other], ignore_index=True)
    curves = episode_curves(results, "CartPole-v1", ["reinforce", "nstep_sarsa", "a2c"])
    assert list(curves) == ["reinforce", "nstep_sarsa"]
    # REINFORCE's seeds 1 and 2 completed 6 episodes, but NStepSARSA's only 4
    assert [len(curve) for curve in curves.values()] == [4, 4]
    assert (curves["reinforce"]["count"] == 3).all()


def test_benchmark_set_changes_only_the_named_algorithms_entries() -> None:
    overrides = parse_overrides(
        ["nstep_sarsa.max_grad_norm=10.0", "nstep_sarsa.learning_rate=lin_1e-3", "nstep_sarsa.tau=5e-3"],
        ["nstep_sarsa", "a2c"],
    )
    # 5e-3 is a string to YAML 1.1, which the zoo would take for a schedule's name
    assert overrides == {"nstep_sarsa": {"max_grad_norm": 10.0, "learning_rate": "lin_1e-3", "tau": 5e-3}}
    settings = dataclasses.replace(QUICK, seeds=1, peer_seeds=1)
    plain = make_specs(settings, ["CartPole-v1"], ["nstep_sarsa", "a2c"])
    changed = make_specs(settings, ["CartPole-v1"], ["nstep_sarsa", "a2c"], overrides)
    assert changed[0].hyperparams == {**plain[0].hyperparams, **overrides["nstep_sarsa"]}
    assert changed[0].key() != plain[0].key()
    assert changed[1] == plain[1]  # A2C's entry untouched


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ("max_grad_norm=10", "write ALGO.KEY=VALUE"),
        ("nstep_sarsa.max_grad_norm", "write ALGO.KEY=VALUE"),
        ("ppo.ent_coef=0.1", "'ppo' is not one"),
        # A typo would otherwise fail every run, each with a TypeError from the constructor
        ("nstep_sarsa.n_step=3", "did you mean 'n_steps'?"),
        ("nstep_sarsa.n_timesteps=3", "--budget"),
    ],
)
def test_benchmark_set_errors_name_the_value(value: str, message: str) -> None:
    with pytest.raises(ValueError, match=message) as error:
        parse_overrides([value], ["nstep_sarsa", "a2c"])
    assert value in str(error.value)


def test_benchmark_set_needs_a_results_dir(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["--set", "nstep_sarsa.max_grad_norm=10.0", "--skip-throughput"])
    assert "--set needs --results-dir" in capsys.readouterr().err


def test_benchmark_set_values_the_algorithm_rejects_stop_before_any_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # Each run started, and each failed with the same error ("2 runs failed")
    command = ["--set", "reinforce.update_mode=perstep", "--algos", "reinforce", "--envs", "CartPole-v1", "--seeds", "2"]
    command += ["--skip-throughput", "--budget", "2000", "--cache-dir", str(tmp_path / "cache")]
    command += ["--results-dir", str(tmp_path)]
    status = main(command)
    assert status == 2
    output = " ".join(capsys.readouterr().out.split())
    assert "Nothing was run: the algorithm rejects these --set values" in output
    assert "reinforce on CartPole-v1: ValueError: update_mode='perstep'" in output
    assert not (tmp_path / "cache").exists()


def test_a_report_from_the_cache_does_not_claim_this_commands_workers() -> None:
    # A rerun that trained nothing wrote its own --workers (and machine) as the runs'
    def header(ran: int | None) -> str:
        return learning_header("python -m benchmarks.run", FULL, ["CartPole-v1"], ["reinforce"], 7, ran=ran)

    assert "7 runs in parallel" in header(None)
    assert "7 runs in parallel" not in header(0)
    assert "Every run was in the cache (`--cache-dir`): this command trained none of them" in header(0)
    assert "This command trained 3 of the runs; the rest were in the cache." in header(3)


def test_an_interruption_stops_the_running_runs_at_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # A Ctrl-C stops the pool: the runs not started are cancelled, and the running ones are stopped at once (not left
    # to finish, minutes in a study), without the temporary folders they trained in
    monkeypatch.setenv("TMPDIR", str(tmp_path))  # the spawned workers' temporary folders
    yaml_entry = "learning_rate: 0.003\nn_timesteps: 10000000\npolicy: MlpPolicy\n"
    long_run = dataclasses.replace(SPEC, n_timesteps=10**7, eval_freq=0, hyperparams_yaml=yaml_entry, label="long")
    with pool.local_runs(1) as runs:
        future = runs.submit(long_run)
        deadline = time.monotonic() + 120
        while not list(tmp_path.glob("sb3-classic-run-*")):
            assert time.monotonic() < deadline, "the run did not start"
            time.sleep(0.2)
        workers = list(runs.pool._processes.values())
        start = time.monotonic()
        runs.cancel()
        try:
            for worker in workers:
                while worker.exitcode is None and _process_exists(worker.pid):
                    assert time.monotonic() - start < 30, "the running run was left to finish"
                    time.sleep(0.1)
        finally:
            for worker in workers:
                worker.kill()  # (if the assertion failed: else the pool's exit would wait for the run's end)
    assert not future.done() or future.cancelled() or isinstance(future.exception(), BrokenProcessPool)
    assert not list(tmp_path.glob("sb3-classic-run-*"))


def _process_exists(pid: int | None) -> bool:
    # (the pool's own thread may have reaped it: its Process object then never learns its exit code)
    try:
        os.kill(pid or 0, 0)
    except ProcessLookupError:
        return False
    return True


def test_run_names_are_shown_as_they_are(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    # A study's reading is in its runs' names in brackets, which rich would take for markup and drop
    specs = [dataclasses.replace(SPEC, seed=seed, label=f"study a [reading] seed {seed}") for seed in (0, 1)]

    class Runs:
        progress: "queue.Queue[tuple[str, int]]" = queue.Queue()

        def submit(self, spec: RunSpec) -> "Future[None]":
            future: Future[None] = Future()
            future.set_result(None) if spec.seed == 0 else future.set_exception(RuntimeError("boom"))
            return future

        def cancel(self) -> None:
            pass

    monkeypatch.setattr(pool, "open_runs", lambda *args: contextlib.nullcontext(Runs()))

    def store(spec: RunSpec, result: Callable[[], Any], cache_dir: Path) -> str | None:
        try:
            result()
        except RuntimeError as error:
            return str(error)
        return None

    monkeypatch.setattr(pool, "_store", store)
    failed = pool.run_pending(specs, 1, tmp_path, Console(width=200))
    output = capsys.readouterr().out
    assert failed == specs[1:]
    assert "done: study a [reading] seed 0" in output
    assert "failed: study a [reading] seed 1: boom" in output


def test_masking_benchmark_writes_each_run_as_it_finishes_and_resumes(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    arguments = ["--seeds", "2", "--budget", "200", "--eval-freq", "100", "--eval-episodes", "1"]
    arguments += ["--results-dir", str(tmp_path)]
    assert masking.main(arguments) == 0
    records = [json.loads(path.read_text()) for path in sorted((tmp_path / "masking").glob("*.json"))]
    assert sorted((record["algo"], record["variant"], record["seed"]) for record in records) == sorted(
        (algo, variant, seed) for algo, variant in masking.RUNS for seed in (0, 1)
    )
    for record in records:
        # Before training, every 100 env steps, and at the end (MaskablePPO's first rollout is 2048 steps)
        assert record["timesteps"][:3] == [0, 100, 200]
        assert len(record["mean_return"]) == len(record["timesteps"])
        assert all(0.0 <= value <= 100.0 for value in record["mean_return"])
    assert not list((tmp_path / "masking").glob("*.partial"))
    markdown = (tmp_path / "masking.md").read_text()
    assert "python -m benchmarks.masking --seeds 2 --budget 200" in markdown
    rows = [line for line in markdown.splitlines() if line.startswith("| ") and not line.startswith("| Algorithm")]
    labels = ["REINFORCE, masked", "REINFORCE, unmasked", "NStepSARSA, masked", "NStepSARSA, unmasked", "MaskablePPO"]
    assert [row.split(" | ")[0].removeprefix("| ") for row in rows] == labels
    assert markdown.count(": met.") + markdown.count(": **not met**.") == 3
    assert (tmp_path / "masking.png").stat().st_size > 0

    # A rerun trains nothing and writes the same page
    def fail(*args: object) -> None:
        raise AssertionError("a cached run was trained again")

    monkeypatch.setattr(masking, "train_run", fail)
    assert masking.main(arguments) == 0
    assert (tmp_path / "masking.md").read_text() == markdown

    # Other settings train again: one seed at another evaluation frequency
    trained: list[tuple[str, str, int]] = []

    def record_training(algo: str, variant: str, seed: int, settings: masking.Settings) -> dict[str, Any]:
        trained.append((algo, variant, seed))
        return {"timesteps": [0, 200], "mean_return": [0.0, 1.0], "seconds": 0.0}

    monkeypatch.setattr(masking, "train_run", record_training)
    masking.main(
        ["--seeds", "1", "--budget", "200", "--eval-freq", "200", "--eval-episodes", "1", "--results-dir", str(tmp_path)]
    )
    assert trained == [(algo, variant, 0) for algo, variant in masking.RUNS]


def masking_summary(algo: str, variant: str, curve: list[float]) -> masking.Summary:
    return masking.Summary(algo, variant, np.arange(len(curve)) * 1000, np.array([curve, curve]), 1.0)


@pytest.mark.parametrize(
    ("sarsa_masked", "ppo", "verdicts"),
    [
        # Masked SARSA at 90 after 2000 steps, unmasked never; at PPO's final 95 after 3000 steps, PPO after 3000
        ([0, 50, 90, 95], [0, 20, 80, 95], ["met", "met", "met"]),
        # Masked SARSA at 90 after 3000 steps as unmasked; PPO reaches 95 sooner than either masked run
        ([0, 50, 60, 90], [0, 95, 95, 95], ["met", "**not met**", "**not met**"]),
    ],
)
def test_masking_targets(sarsa_masked: list[float], ppo: list[float], verdicts: list[str]) -> None:
    summaries = {
        ("reinforce", "masked"): masking_summary("reinforce", "masked", [0, 90, 92, 92]),
        ("reinforce", "unmasked"): masking_summary("reinforce", "unmasked", [0, 10, 20, 91]),
        ("nstep_sarsa", "masked"): masking_summary("nstep_sarsa", "masked", sarsa_masked),
        ("nstep_sarsa", "unmasked"): masking_summary("nstep_sarsa", "unmasked", [0, 10, 20, 90]),
        ("maskable_ppo", "masked"): masking_summary("maskable_ppo", "masked", ppo),
    }
    lines = masking.targets(summaries, masking.Settings(budget=3000))
    assert [line.rsplit(": ", 1)[1].removesuffix(".") for line in lines] == verdicts


def test_the_streaming_benchmark_records_resumes_and_reports(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from benchmarks import streaming

    args = ["--algo", "nstep_sarsa", "--seeds", "0", "--episodes", "3", "--out", str(tmp_path), "--page"]
    streaming.main([*args, str(tmp_path / "streaming.md")])
    runs = pd.read_csv(tmp_path / "runs.csv")
    assert set(runs["optimizer"]) == {"obgd", "adam"}, runs
    assert len(runs) == 2, runs
    episodes = pd.read_csv(tmp_path / "nstep_sarsa-CartPole-v1.csv")
    assert set(episodes["episode"]) == {1, 2, 3}
    assert len(episodes) == 6
    # A finished run is not run again; the page reads what is recorded
    streaming.main([*args, str(tmp_path / "streaming.md")])
    assert "0 runs to do (2 recorded" in capsys.readouterr().out
    assert len(pd.read_csv(tmp_path / "runs.csv")) == 2
    page = (tmp_path / "streaming.md").read_text()
    assert "| NStepSARSA (SARSA(λ)) | streaming recipe (ObGD) | 1 |" in page
    assert (tmp_path / "streaming-CartPole-v1.png").exists()
    # A run recorded under other settings (its YAML entry changed since) does not count: it is run anew
    runs["settings"] = ["0" * 12, runs["settings"][1]]
    runs.to_csv(tmp_path / "runs.csv", index=False)
    streaming.main([*args, str(tmp_path / "streaming.md")])
    assert "1 runs to do (1 recorded" in capsys.readouterr().out
    assert len(streaming.current_runs(tmp_path)) == 2


def test_the_streaming_benchmarks_cost_is_paired_per_seed_and_resumes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from benchmarks import streaming

    page = tmp_path / "streaming.md"
    args = ["--algo", "nstep_sarsa", "--seeds", "0", "1", "--cost", "300", "--out", str(tmp_path), "--page", str(page)]
    streaming.main(args)
    cost = pd.read_csv(tmp_path / "cost.csv")
    # Both optimizers per seed, the order alternating (ObGD first for seed 0, Adam first for seed 1)
    assert list(zip(cost["seed"], cost["optimizer"], strict=True)) == [(0, "obgd"), (0, "adam"), (1, "adam"), (1, "obgd")]
    assert (cost["steps"] == 300).all(), cost
    capsys.readouterr()
    streaming.main(args)
    assert "cost:" not in capsys.readouterr().out
    assert len(pd.read_csv(tmp_path / "cost.csv")) == 4
    micros = 1e6 * cost["cpu_seconds"] / cost["steps"]
    ratios = (micros[cost["optimizer"] == "obgd"].to_numpy() / micros[cost["optimizer"] == "adam"].to_numpy()).tolist()
    text = page.read_text()
    assert "## Cost per env step, paired" in text
    assert "| NStepSARSA (SARSA(λ)) | CartPole-v1 | 300 | 2 |" in text, text
    assert ", ".join(f"{ratio:.2f}" for ratio in ratios) in text, (ratios, text)
    # A pair measured under other settings (its YAML entry changed since) is left out and measured anew
    cost.loc[cost["seed"] == 1, "settings"] = "0" * 12
    cost.to_csv(tmp_path / "cost.csv", index=False)
    streaming.main(args)
    assert capsys.readouterr().out.count("cost:") == 2
    current = streaming.current_runs(tmp_path, "cost.csv")
    pairs = sorted(zip(current["seed"], current["optimizer"], strict=True))
    assert pairs == [(0, "adam"), (0, "obgd"), (1, "adam"), (1, "obgd")], current
    assert (current["settings"] != "0" * 12).all(), current
