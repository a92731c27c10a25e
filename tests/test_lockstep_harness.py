"""The study runner's and the benchmark harness's lockstep: a setting's seeds planned, trained and cached as one population."""

import io
import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import pandas as pd
import pytest

from sb3_classic.common.population import MemberError
from sb3_classic.harness import common, lockstep, runner
from sb3_classic.harness.common import RunSpec
from sb3_classic.harness.lockstep import lockstep_jobs, plan_lockstep, refusal, training_plan
from sb3_classic.harness.runner import RunError, RunResult, execute_population
from sb3_classic.sarsa.lockstep import NStepSARSAPopulation

#: A per-step NStepSARSA setting a population covers, small enough to train in a second
PER_STEP = (
    "n_timesteps: 3000\npolicy: MlpPolicy\nn_envs: 1\nn_steps: 3\nupdate_mode: per_step\ntrain_freq: 1\n"
    "gradient_steps: 1\nlearning_rate: 0.001\npolicy_kwargs: dict(net_arch=[16])\n"
)
#: One it does not: q̂ = wᵀx with its own SGD update
LINEAR = PER_STEP.replace("MlpPolicy", "LinearPolicy").replace("dict(net_arch=[16])", "dict(net_arch=[])")


def spec(seed: int, hyperparams: str = PER_STEP, algo: str = "nstep_sarsa") -> RunSpec:
    return RunSpec(algo, "CartPole-v1", seed, 3000, 0, 2, hyperparams, max_episodes=6, label=f"run seed {seed}")


def test_the_seeds_of_a_covered_setting_are_planned_in_lockstep() -> None:
    plain = [spec(0), spec(1), spec(0, LINEAR), spec(1, LINEAR), spec(0, PER_STEP.replace("0.001", "0.002"))]
    planned = plan_lockstep(plain)
    # Two seeds of a covered setting; not the linear q̂ (refused by the population), nor a setting of one seed
    assert [run.lockstep for run in planned] == [True, True, False, False, False]
    assert "LinearPolicy" in (refusal("nstep_sarsa", "CartPole-v1", LINEAR) or "")
    # The key says which way: the two ways' results differ, so their cache entries do
    assert planned[0].key() != plain[0].key()
    assert planned[2].key() == plain[2].key()
    assert planned[0].setting_key() == planned[1].setting_key() != planned[1].key()
    assert [run.lockstep for run in plan_lockstep(plain, enabled=False)] == [False] * 5
    # Each run trained alone is told why, and what would train its setting's seeds together
    reasons = training_plan(plain)
    assert reasons[:2] == [None, None]
    assert reasons[2] == reasons[3] == refusal("nstep_sarsa", "CartPole-v1", LINEAR)
    assert reasons[2] is not None
    assert reasons[2].startswith("policy='LinearPolicy' has its own SGD update, not a stacked network's; use 'MlpPolicy'")
    assert reasons[4] == lockstep.ONE_SEED
    assert training_plan(plain, enabled=False) == [lockstep.SEPARATE] * 5
    assert training_plan(planned) == reasons  # (the plan's mark in the key aside)
    # Peers have no population: their runs are trained alone without a model being built to ask
    assert not any(run.lockstep for run in plan_lockstep([spec(0, algo="a2c"), spec(1, algo="a2c")]))
    # One job per population (by seed), one per run trained alone, in the order of their first run
    jobs = lockstep_jobs([planned[1], planned[2], planned[0], planned[3]])
    assert [[run.seed for run in job] for job in jobs] == [[0, 1], [0], [1]]
    assert [job[0].lockstep for job in jobs] == [True, False, False]


def test_a_member_of_a_population_is_the_run_of_its_seed_whatever_the_others() -> None:
    first, second = plan_lockstep([spec(0), spec(1)])
    together = execute_population([first, second])
    alone = execute_population([second])
    assert all(isinstance(result, RunResult) for result in [*together, *alone])
    results = [result for result in together if isinstance(result, RunResult)]
    episodes = [pd.read_csv(io.BytesIO(result.files["episodes.csv"])) for result in results]
    assert len(episodes[0]) == len(episodes[1]) == 6
    # Seed 1's episodes do not depend on seed 0 being trained beside it; they are not seed 0's
    assert isinstance(alone[0], RunResult)
    pd.testing.assert_frame_equal(episodes[1], pd.read_csv(io.BytesIO(alone[0].files["episodes.csv"])))
    assert not episodes[0].equals(episodes[1])
    summary = json.loads(results[1].files["run.json"])
    assert summary["training"] == "lockstep"
    assert summary["population"] == 2
    assert summary["key"] == second.key()
    assert summary["seed"] == 1
    assert summary["learn_time_s"] > 0
    assert "train.log" in results[1].files
    assert "evaluations.csv" in results[1].files


def test_a_member_stopped_by_its_env_fails_alone(monkeypatch: pytest.MonkeyPatch) -> None:
    class StoppedSecond(NStepSARSAPopulation):
        def learn(
            self,
            total_timesteps: int,
            callback: Any = None,
            log_interval: Any = "auto",
            tb_log_name: str | None = None,
            reset_num_timesteps: bool = True,
            use_masking: bool = True,
        ) -> Any:
            super().learn(total_timesteps, callback, log_interval, tb_log_name, reset_num_timesteps, use_masking)
            raise MemberError("member 1 (seed 1) stopped", {1: ValueError("the env returned NaN")})

    monkeypatch.setattr(runner, "population_class", lambda algo: StoppedSecond)
    results = execute_population(plan_lockstep([spec(0), spec(1)]))
    assert isinstance(results[0], RunResult)
    assert results[0].summary["seed"] == 0
    assert isinstance(results[1], RunError)
    assert "NaN" in str(results[1])


def test_a_population_is_of_one_setting() -> None:
    first, second = plan_lockstep([spec(0), spec(1)])
    with pytest.raises(ValueError, match="lockstep runs of one setting"):
        execute_population([first, replace(second, hyperparams_yaml=PER_STEP.replace("0.001", "0.002"))])
    with pytest.raises(ValueError, match="lockstep runs of one setting"):
        execute_population([spec(0), spec(1)])


def test_an_algorithm_without_a_population_module_plans_alone(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(common.POPULATIONS, "nstep_sarsa", ("sb3_classic.sarsa.absent", "Absent"))
    lockstep.refusal.cache_clear()
    try:
        assert not any(run.lockstep for run in plan_lockstep([spec(0), spec(1)]))
    finally:
        lockstep.refusal.cache_clear()


def test_the_study_command_trains_in_lockstep_unless_told(tmp_path: Path) -> None:
    from sb3_classic.studies.cli import Defaults, main

    study = tmp_path / "study.yml"
    study.write_text(
        "title: Tiny\nenv: CartPole-v1\nalgo: nstep_sarsa\nseeds: 2\nbudget: {episodes: 3}\nhyperparams:\n"
        "  policy: MlpPolicy\n  update_mode: per_step\n  train_freq: 1\n  gradient_steps: 1\n  n_steps: 2\n"
        "  policy_kwargs: {net_arch: [8]}\nvariants:\n  a: {}\n  b: {learning_rate: 0.01}\n"
        "claim: {text: b beats a, kind: better, variant: b, others: [a]}\n"
    )
    defaults = Defaults(cache_dir=tmp_path / "cache", results_dir=tmp_path / "results", catalogue=None)
    for options, training in (([], "lockstep"), (["--separate"], "alone")):
        assert main([str(study), "--workers", "1", *options], defaults) == 0
        found = {json.loads(path.read_text()).get("training") for path in (tmp_path / "cache").rglob("run.json")}
        assert training in found
    # Both ways are cached apart: 2 variants × 2 seeds each way
    assert len(list((tmp_path / "cache").rglob("run.json"))) == 8
