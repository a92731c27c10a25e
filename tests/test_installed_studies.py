"""
The study runner as a user of the installed package runs it: ``python -m sb3_classic.studies
my_study.yml`` in a folder of their own, with nothing of the repository: its cache and outputs land in that folder.
"""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd

import sb3_classic
from sb3_classic import zoo
from sb3_classic.harness.runner import RUN_FILE
from sb3_classic.studies.spec import load_study

STUDY = """
title: Mine
env: CartPole-v1
algo: nstep_sarsa
seeds: 1
budget: {episodes: 4}
hyperparams:
  policy: MlpPolicy
  learning_rate: !!float 1e-3
  train_freq: 1
  gradient_steps: 1
  policy_kwargs: {net_arch: [8]}
vary: {n_steps: [1, 2]}
claim: {text: "n = 2 beats n = 1", kind: better, variant: n_steps=2, others: [n_steps=1]}
threshold_window: 2
"""


def installed_package(folder: Path) -> Path:
    """
    This package laid out as its wheel installs it (the YAMLs inside it, in ``sb3_classic/hyperparams/``), in a folder
    that comes first on the path, with a ``benchmarks`` that fails to import: whatever else is installed (an editable
    install puts the repository on the path), a command run there uses this code and none of the repository's.

    :return: the folder, for ``PYTHONPATH``
    """
    site = folder / "site-packages"
    package = site / "sb3_classic"
    shutil.copytree(Path(sb3_classic.__file__).resolve().parent, package, ignore=shutil.ignore_patterns("__pycache__"))
    (package / "hyperparams").mkdir(exist_ok=True)
    for algo in zoo.ALGORITHMS:
        if not (package / "hyperparams" / f"{algo}.yml").exists():
            shutil.copy(zoo.hyperparams_path(algo), package / "hyperparams")
    (site / "benchmarks").mkdir()
    (site / "benchmarks" / "__init__.py").write_text('raise ImportError("the package imported benchmarks/")\n')
    return site


def test_an_installed_user_runs_a_study_in_their_folder(tmp_path: Path) -> None:
    work = tmp_path / "my-project"
    work.mkdir()
    (work / "my_study.yml").write_text(STUDY)
    env = {**os.environ, "PYTHONPATH": str(installed_package(tmp_path))}
    command = [sys.executable, "-m", "sb3_classic.studies", "my_study.yml", "--workers", "1"]
    done = subprocess.run(command, cwd=work, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "2 runs: 0 cached, 2 to run on 1 worker" in done.stdout

    # The cache in ./sb3_classic-cache/, under the keys this process computes (the same code, the same keys)
    cache = work / "sb3_classic-cache"
    for run in load_study(work / "my_study.yml").runs():
        assert (run.spec.run_dir(cache) / RUN_FILE).is_file(), run.spec.name
    # The outputs in ./studies-results/, showing the command the user ran
    results = work / "studies-results"
    assert sorted(path.name for path in results.iterdir()) == [
        "STUDIES.md",
        "my_study-seeds.csv",
        "my_study.csv",
        "my_study.json",
        "my_study.md",
        "my_study.png",
    ]
    assert sorted(path.name for path in work.iterdir()) == ["my_study.yml", "sb3_classic-cache", "studies-results"]
    # The command that re-runs it: the file, without --workers (which changes how, not what, it runs)
    assert "python -m sb3_classic.studies my_study.yml\n" in (results / "my_study.md").read_text()
    assert "`python -m sb3_classic.studies my_study.yml`" in (results / "STUDIES.md").read_text()
    assert json.loads((results / "my_study.json").read_text())["runs"] == 2
    assert pd.read_csv(results / "my_study.csv")["variant"].tolist() == ["n_steps=1", "n_steps=2"]

    # Again: nothing to run
    again = subprocess.run([*command, "--list"], cwd=work, env=env, capture_output=True, text=True, timeout=120)
    assert "2 runs, 2 cached" in again.stdout, again.stdout + again.stderr
