"""The README does not lie: CI (.ci/run) runs its commands, and its Python quick start runs."""

import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

ROOT = Path(__file__).parents[1]
README = (ROOT / "README.md").read_text()


def readme_commands() -> set[str]:
    """:return: every line of the README's ``bash`` blocks, without its trailing ``# comment``"""
    blocks = re.findall(r"```bash\n(.*?)```", README, flags=re.DOTALL)
    return {line.split("  #")[0].strip() for block in blocks for line in block.splitlines() if line.strip()}


def test_ci_runs_the_readme_commands() -> None:
    ci_commands = [
        line.strip()
        for line in (ROOT / ".ci" / "run").read_text().splitlines()
        if line.strip() and not line.startswith(("#", "set ", "cd "))
    ]
    assert ci_commands, ".ci/run runs nothing"
    missing = [command for command in ci_commands if command not in readme_commands()]
    assert not missing, f"commands of .ci/run that README.md does not give: {missing}"
    # The install and the test command are the README's "tests" command
    assert any("pip install torch==2.13.0" in command and "pytest" in command for command in ci_commands)


def test_quick_start_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (quick_start,) = re.findall(r"## Quick start\n+```python\n(.*?)```", README, flags=re.DOTALL)
    monkeypatch.chdir(tmp_path)
    # The same code with a small budget: what is checked is that it runs as written
    code, n_budgets = re.subn(r"\.learn\([\d_]+", ".learn(600", quick_start)
    assert n_budgets >= 3, "the quick start's learn() calls were not found"
    namespace: dict[str, object] = {}
    exec(compile(code, "README.md quick start", "exec"), namespace)
    assert (tmp_path / "sarsa_cartpole.zip").is_file()
    assert namespace["action"] is not None


def test_book_figure_example_prints_the_books_number(capsys: pytest.CaptureFixture[str]) -> None:
    # The README's Fig 13.2 example as written (the whole run, ~10 s): plain REINFORCE per step on the short corridor,
    # episodes 401-500; the book gives -15.1 +- 0.2 over 100 runs, and the README says what this seed prints
    (example,) = re.findall(r"A figure's point with the public API alone.*?```python\n(.*?)```", README, flags=re.DOTALL)
    exec(compile(example, "README.md Fig 13.2 example", "exec"), {})
    printed = float(capsys.readouterr().out.strip().splitlines()[-1])
    assert -17.0 < printed < -13.5
    assert f"This prints {printed:.2f}".replace("-", "−") in README


def test_tile_coding_example_runs_as_written() -> None:
    # The README's Mountain Car example, its whole budget (10,000 steps, ~5 s): "the first episodes take about a
    # thousand steps each", then shorter (the book's Fig 10.1: the optimistic weights explore, episodes shorten)
    tile_example = r"```python\n(import torch as th\n\nfrom sb3_classic import NStepSARSA, TileCoding.*?)```"
    (example,) = re.findall(tile_example, README, flags=re.DOTALL)
    namespace: dict[str, Any] = {}
    exec(compile(example, "README.md tile coding example", "exec"), namespace)
    lengths = [episode["l"] for episode in namespace["model"].ep_info_buffer]
    assert len(lengths) >= 3
    # (unseeded, as written: one of the first episodes can take 3,000 steps or more; their median is about a thousand)
    first = float(np.median(lengths[:3]))
    assert 300 < first < 3000
    assert lengths[-1] < first
