"""The lockstep benchmark (``benchmarks/lockstep.py``): its command writes the comparison in the committed format."""

import csv
import time
from pathlib import Path

from stable_baselines3.common.vec_env import DummyVecEnv

from benchmarks import lockstep

COLUMNS = ["algo", "env_id", "setting", "k", "separate_cpu_s", "lockstep_cpu_s"]


def test_the_benchmark_writes_one_row_per_algorithm_env_and_setting(tmp_path: Path) -> None:
    lockstep.main(["--k", "2", "--steps", "60", "--batch-steps", "300", "--env", "CartPole-v1", "--out", str(tmp_path)])
    with open(tmp_path / "lockstep.csv", newline="") as file:
        rows = list(csv.DictReader(file))
    assert list(rows[0]) == COLUMNS
    assert [(row["algo"], row["setting"].split(":")[0]) for row in rows] == [
        ("NStepSARSA", "per_step"),
        ("NStepSARSA", "batch"),
        ("REINFORCE", "per_step"),
        ("REINFORCE", "batch"),
    ]
    assert all(row["env_id"] == "CartPole-v1" and row["k"] == "2" for row in rows)
    assert all(float(row["separate_cpu_s"]) > 0 and float(row["lockstep_cpu_s"]) > 0 for row in rows)
    page = (tmp_path / "lockstep.md").read_text()
    assert "python -m benchmarks.lockstep --k 2 --steps 60" in page
    table = [line.split(" | ") for line in page.splitlines() if line.startswith(("| NStepSARSA |", "| REINFORCE |"))]
    assert [line[1] for line in table] == ["CartPole-v1"] * 4
    for line, row in zip(table, rows, strict=True):
        # one after the other, lockstep, ratio, floor, at most: the CSV's seconds, and the floor's ratio
        assert line[5:7] == [row["separate_cpu_s"], row["lockstep_cpu_s"]]
        assert float(line[8]) > 0
        assert line[9] == f"{float(row['separate_cpu_s']) / float(line[8]):.2f}× |"


def test_the_floor_is_part_of_a_lockstep_run_and_leaves_the_clocked_methods_as_they_were() -> None:
    clocked = (*lockstep.STACKED_CALLS, (DummyVecEnv, "step_wait"))
    before = [owner.__dict__[name] for owner, name in clocked]
    models = lockstep.make_models("CartPole-v1", 2)
    start = time.process_time()
    floor = lockstep.floor(models, 200)
    whole = time.process_time() - start
    assert 0 < floor < whole
    assert all(model.num_timesteps == 200 for model in models)
    # the clock is taken off again: what runs afterwards is the methods themselves
    assert [owner.__dict__[name] for owner, name in clocked] == before


def test_the_committed_comparison_has_a_row_per_algorithm_env_and_setting_of_ten_seeds() -> None:
    with open(lockstep.RESULTS / "lockstep.csv", newline="") as file:
        rows = list(csv.DictReader(file))
    assert rows
    assert list(rows[0]) == COLUMNS
    keys = {(row["algo"], row["env_id"], row["setting"].split(":")[0]) for row in rows}
    assert keys == {
        (algo, env_id, setting)
        for algo in ("NStepSARSA", "REINFORCE")
        for env_id in ("CartPole-v1", "Acrobot-v1")
        for setting in ("per_step", "batch")
    }
    assert all(row["k"] == "10" for row in rows)
