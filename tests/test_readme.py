"""The README does not lie: CI (.ci/run) runs its commands, and its Python quick start runs. (The pages of docs/, where
the rest of the documentation is, have their own checks: tests/test_docs.py.)"""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1]
README = (ROOT / "README.md").read_text()


def readme_commands() -> set[str]:
    """:return: every line of the README's ``bash`` blocks, without its trailing ``# comment``"""
    blocks = re.findall(r"```bash\n(.*?)```", README, flags=re.DOTALL)
    return {line.split("  #")[0].strip() for block in blocks for line in block.splitlines() if line.strip()}


@pytest.mark.skipif(not (ROOT / ".ci" / "run").exists(), reason="CI's script is the repository's, not in the sdist")
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
    assert n_budgets >= 2, "the quick start's learn() calls were not found"
    namespace: dict[str, object] = {}
    exec(compile(code, "README.md quick start", "exec"), namespace)
    assert (tmp_path / "sarsa_cartpole.zip").is_file()
    assert namespace["action"] is not None
