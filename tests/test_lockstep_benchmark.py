"""The lockstep benchmark (``benchmarks/lockstep.py``): its command writes the comparison in the committed format."""

import csv
import time
from collections import Counter
from collections.abc import Callable
from contextlib import ExitStack
from pathlib import Path
from typing import Any
from unittest import mock

import pytest

from benchmarks import lockstep

COLUMNS = ["algo", "env_id", "setting", "k", "separate_cpu_s", "lockstep_cpu_s", "floor_cpu_s"]


def test_the_benchmark_writes_one_row_per_algorithm_env_and_setting(tmp_path: Path) -> None:
    arguments = ["--k", "2", "--steps", "60", "--batch-steps", "300", "--many-k", "3", "--many-steps", "40"]
    lockstep.main([*arguments, "--env", "CartPole-v1", "--repeats", "2", "--out", str(tmp_path)])
    with open(tmp_path / "lockstep.csv", newline="") as file:
        rows = list(csv.DictReader(file))
    assert list(rows[0]) == COLUMNS
    assert [(row["algo"], row["setting"].split(":")[0]) for row in rows] == [
        ("NStepSARSA", "per_step"),
        ("NStepSARSA", "batch"),
        ("NStepSARSA", "per_step"),
        ("REINFORCE", "per_step"),
        ("REINFORCE", "batch"),
    ]
    assert [row["k"] for row in rows] == ["2", "2", "3", "2", "2"]
    assert all(row["env_id"] == "CartPole-v1" for row in rows)
    assert all(float(row["separate_cpu_s"]) > 0 and float(row["lockstep_cpu_s"]) > 0 for row in rows)
    page = (tmp_path / "lockstep.md").read_text()
    assert "python -m benchmarks.lockstep --k 2 --steps 60" in page
    table = [line.split(" | ") for line in page.splitlines() if line.startswith(("| NStepSARSA |", "| REINFORCE |"))]
    assert [line[1] for line in table] == ["CartPole-v1"] * 5
    assert [line[4] for line in table] == ["60", "300", "40", "60", "300"]
    for line, row in zip(table, rows, strict=True):
        # one after the other, lockstep, ratio, floor, at most: the CSV's seconds and their ratios
        assert line[5:9] == [row["separate_cpu_s"], row["lockstep_cpu_s"], line[7], row["floor_cpu_s"]]
        assert line[7] == lockstep.ratio(row["separate_cpu_s"], row["lockstep_cpu_s"])
        assert line[9] == lockstep.ratio(row["separate_cpu_s"], row["floor_cpu_s"]) + " |"


@pytest.mark.parametrize("algo", ["NStepSARSA", "REINFORCE"])
def test_the_floor_clocks_each_stacked_call_and_env_step_once_and_leaves_them_as_they_were(algo: str) -> None:
    """Every clocked method is one the population calls, none inside another (no second count), and is restored."""
    clocked = lockstep.CLOCKED
    before = [getattr(owner, name) for owner, name in clocked]
    calls: Counter[str] = Counter()
    depth = [0]

    def counted(name: str, function: Callable[..., Any]) -> Callable[..., Any]:
        def call(*args: Any, **kwargs: Any) -> Any:
            assert depth[0] == 0, f"{name} called inside another clocked call"
            calls[name] += 1
            depth[0] += 1
            try:
                return function(*args, **kwargs)
            finally:
                depth[0] -= 1

        return call

    if algo == "NStepSARSA":
        models: list[Any] = lockstep.make_models("CartPole-v1", 2)
    else:
        env_id, _, kwargs = next(s for s in lockstep.reinforce_settings() if s[1].startswith("per_step"))
        models = lockstep.make_reinforce_models(env_id, 2, kwargs)
    with ExitStack() as stack:
        for owner, name in clocked:
            stack.enter_context(mock.patch.object(owner, name, counted(name, getattr(owner, name))))
        start = time.process_time()
        floor = lockstep.floor(models, 200)
        whole = time.process_time() - start
    assert 0 < floor < whole
    assert all(model.num_timesteps >= 200 for model in models)  # (REINFORCE ends its last episode)
    assert all(calls[name] > 0 for name in ["forward", "_gradient_step", "step_wait"]), calls
    # the clock is taken off again: what runs afterwards is the methods themselves
    assert [getattr(owner, name) for owner, name in clocked] == before


def test_the_committed_comparison_has_a_row_per_algorithm_env_and_setting_of_ten_seeds_and_one_of_thirty() -> None:
    with open(lockstep.RESULTS / "lockstep.csv", newline="") as file:
        rows = list(csv.DictReader(file))
    assert rows
    assert list(rows[0]) == COLUMNS
    many = [row for row in rows if row["k"] != "10"]
    assert [(row["algo"], row["env_id"], row["setting"].split(":")[0], row["k"]) for row in many] == [
        ("NStepSARSA", "CartPole-v1", "per_step", "30")
    ]
    rows = [row for row in rows if row["k"] == "10"]
    keys = {(row["algo"], row["env_id"], row["setting"].split(":")[0]) for row in rows}
    assert keys == {
        (algo, env_id, setting)
        for algo in ("NStepSARSA", "REINFORCE")
        for env_id in ("CartPole-v1", "Acrobot-v1")
        for setting in ("per_step", "batch")
    }
    assert len(rows) == len(keys)


def test_each_way_is_timed_on_fresh_members_at_every_repeat_and_the_medians_kept() -> None:
    built: list[list[Any]] = []

    def make() -> list[Any]:
        built.append(lockstep.make_models("CartPole-v1", 2))
        return built[-1]

    with mock.patch.object(lockstep, "floor", side_effect=[7.0, 2.0, 1.0]):
        separate, in_lockstep, floor = lockstep.timed(make, 20, repeats=3)
    assert floor == 2.0  # (not the first, last, mean, least or greatest)
    assert separate > 0
    assert in_lockstep > 0
    # each repeat: members for the separate runs, for the population, for the floor (not trained here: it is stubbed)
    assert len(built) == 9
    assert [models[0].num_timesteps for models in built] == [20, 20, 0] * 3


def committed_rows() -> list[dict[str, str]]:
    with open(lockstep.RESULTS / "lockstep.csv", newline="") as file:
        return list(csv.DictReader(file))


def guide_lines(start: tuple[str, ...]) -> list[list[str]]:
    """:return: the guide's table rows that start with one of ``start``, as cells"""
    text = (lockstep.RESULTS.parents[1] / "docs" / "guide" / "lockstep.md").read_text()
    return [[cell.strip() for cell in line.strip("|").split("|")] for line in text.splitlines() if line.startswith(start)]


def test_the_guide_s_speed_table_is_the_committed_comparison() -> None:
    rows = committed_rows()
    table = guide_lines(("| NStepSARSA |", "| REINFORCE |"))
    assert len(table) == len(rows)
    for cells, row in zip(table, rows, strict=True):
        separate, in_lockstep, floor = row["separate_cpu_s"], row["lockstep_cpu_s"], row["floor_cpu_s"]
        assert cells[:2] == [row["algo"], row["env_id"]]
        assert cells[2].startswith(row["setting"].split(":")[0].replace("_", " ") + ",")
        assert (f"{row['k']} seeds" in cells[2]) == (row["k"] != "10"), cells[2]
        ratios = [lockstep.ratio(separate, in_lockstep), lockstep.ratio(separate, floor)]
        assert cells[3:] == [separate, in_lockstep, *ratios], f"{cells} against {row}"


def test_the_guide_s_first_screen_gives_the_committed_ratios() -> None:
    # | NStepSARSA per step (…), CartPole-v1, Acrobot-v1 | 10 | 2.9×, 3.0× |: the CSV's ratios of those rows, in its order
    rows = committed_rows()
    table = guide_lines(("| NStepSARSA per step", "| NStepSARSA batch", "| REINFORCE per step", "| REINFORCE batch"))
    assert len(table) == 5
    covered = 0
    for setting, k, ratios in table:
        algo, family = setting.split()[0], setting.split()[1] + ("_step" if setting.split()[1] == "per" else "")
        matching = [row for row in rows if (row["algo"], row["setting"].split(":")[0], row["k"]) == (algo, family, k)]
        expected = [f"{float(row['separate_cpu_s']) / float(row['lockstep_cpu_s']):.1f}×" for row in matching]
        assert ratios.split(", ") == expected, f"{setting}, {k} seeds: {ratios} against {expected}"
        covered += len(matching)
    assert covered == len(rows)
