"""The package as pip builds and installs it: the sdist and wheel, their licence and long description, and the
README's install commands run from where the README says to run them."""

import re
import shlex
import subprocess
import sys
import tarfile
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1]
README = (ROOT / "README.md").read_text()
# A Markdown link or image whose target is not a web address or an anchor: PyPI's page cannot follow it
RELATIVE_LINK = re.compile(r"\]\((?!https?://|#)[^)]*\)")


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """:return: the sdist and the wheel, built from the checkout by its build backend"""
    out = tmp_path_factory.mktemp("dist")
    subprocess.run([sys.executable, "-m", "hatchling", "build", "-d", str(out)], cwd=ROOT, check=True, capture_output=True)
    (sdist,) = out.glob("*.tar.gz")
    (wheel,) = out.glob("*.whl")
    return sdist, wheel


def test_the_sdist_holds_what_building_and_testing_need(built: tuple[Path, Path]) -> None:
    sdist, _ = built
    with tarfile.open(sdist) as archive:
        names = {name.split("/", 1)[1] for name in archive.getnames() if "/" in name}
    assert {"LICENSE", "pyproject.toml", "README.md", "_sb3_classic_zoo.pth", "sb3_classic/__init__.py"} <= names
    assert {"hyperparams/nstep_sarsa.yml", "hyperparams/reinforce.yml", "tests/test_contract.py"} <= names
    assert not [name for name in names if name.endswith(".png") or name.startswith(".ci/")]
    assert sdist.stat().st_size < 1_000_000


def test_the_wheel_carries_the_licence_and_a_long_description_pypi_can_show(built: tuple[Path, Path]) -> None:
    _, wheel = built
    with zipfile.ZipFile(wheel) as archive:
        names = set(archive.namelist())
        (metadata,) = [name for name in names if name.endswith(".dist-info/METADATA")]
        text = archive.read(metadata).decode()
    assert any(name.endswith(".dist-info/licenses/LICENSE") for name in names)
    assert {"sb3_classic/hyperparams/nstep_sarsa.yml", "_sb3_classic_zoo.pth"} <= names
    assert "License-Expression: MIT" in text
    assert "Description-Content-Type: text/markdown" in text
    long_description = text.split("\n\n", 1)[1]
    assert RELATIVE_LINK.search(README), "the README has no relative link: this test checks nothing"
    assert not RELATIVE_LINK.findall(long_description)
    assert "https://raw.githubusercontent.com/sb3-classic/sb3_classic/main/" in long_description


def readme_local_installs() -> set[str]:
    """:return: every target of the README's ``pip install`` commands that is a path (``".[zoo]"``), not torch"""
    targets: set[str] = set()
    for block in re.findall(r"```bash\n(.*?)```", README, flags=re.DOTALL):
        for command in re.split(r"&&|\n", block):
            words = shlex.split(command.split("  #")[0])
            if words[:2] == ["pip", "install"]:
                targets.update(word for word in words[2:] if word.startswith("."))
    return targets


def test_the_readmes_install_commands_run_from_the_checkouts_root() -> None:
    # pip resolves each target as the README's command gives it, from the folder the README says to run it in
    targets = readme_local_installs()
    assert ".[zoo]" in targets
    for target in targets:
        result = subprocess.run(
            [sys.executable, "-m", "pip", "install", "--dry-run", "--no-deps", "--no-build-isolation", "--no-index", target],
            cwd=ROOT,
            capture_output=True,
            text=True,
        )
        assert result.returncode == 0, f"pip install {target!r}: {result.stderr[-2000:]}"
