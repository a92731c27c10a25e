"""The documentation does not lie either: it builds with warnings as errors (a broken reference, a missing page or
image, a docstring autodoc cannot render), its Python examples run, its links to the repository's files and its
commands' modules exist, and its numbers are those of the committed results."""

import contextlib
import functools
import importlib.metadata
import importlib.util
import io
import json
import re
import shlex
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

ROOT = Path(__file__).parents[1]
DOCS = ROOT / "docs"
PAGES = sorted(path for path in DOCS.rglob("*.md") if "_build" not in path.parts)
RESULTS = ROOT / "benchmarks" / "results"


def page_text(name: str) -> str:
    """:return: the text of ``docs/<name>``"""
    return (DOCS / name).read_text()


def python_blocks() -> list[tuple[str, int, str]]:
    """:return: (page, line, code) of every ``python`` block of the pages"""
    blocks = []
    for page in PAGES:
        text = page.read_text()
        for match in re.finditer(r"```python\n(.*?)```", text, flags=re.DOTALL):
            line = text.count("\n", 0, match.start()) + 2
            blocks.append((page.relative_to(DOCS).as_posix(), line, match.group(1)))
    return blocks


def small_budget(code: str, steps: int = 1000, episodes: int = 5) -> str:
    """:return: the code with at most ``steps`` env steps per ``learn()`` and ``episodes`` per episode budget"""
    code = re.sub(r"\.learn\((total_timesteps=)?([\d_]+)", lambda m: f".learn({m[1] or ''}{min(int(m[2]), steps)}", code)
    return re.sub(r"max_episodes=(\d+)", lambda m: f"max_episodes={min(int(m[1]), episodes)}", code)


def bash_lines(text: str) -> list[str]:
    """:return: every command of the ``bash`` blocks of a page (a line ended by ``\\`` joined to the next), without its
    trailing ``# comment``; comment lines left out"""
    blocks = re.findall(r"```bash\n(.*?)```", text, flags=re.DOTALL)
    lines = [line.split("  #")[0].strip() for block in blocks for line in re.sub(r"\\\n\s*", "", block).splitlines()]
    return [line for line in lines if line and not line.startswith("#")]


def test_the_docs_build_with_warnings_as_errors(tmp_path: Path) -> None:
    # A fresh output folder: an incremental build does not repeat the warnings of pages it does not read again
    result = subprocess.run(
        [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html", str(DOCS), str(tmp_path / "html")],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stderr[-6000:]
    assert (tmp_path / "html" / "modules" / "nstep_sarsa.html").is_file()
    api = (tmp_path / "html" / "modules" / "reinforce.html").read_text()
    assert "value_learning_rate" in api, "the REINFORCE page has no API reference (autodoc)"
    # The committed figures are part of the site (an sdist leaves them out: docs/conf.py builds without them there)
    if (RESULTS / "Acrobot-v1-steps.png").exists():
        assert (tmp_path / "html" / "_images" / "Acrobot-v1-steps.png").is_file()


def test_every_page_is_in_the_toctree() -> None:
    index = page_text("index.md")
    listed = set(re.findall(r"^((?:guide|modules|misc)/\w+)$", index, flags=re.MULTILINE))
    pages = {page.relative_to(DOCS).with_suffix("").as_posix() for page in PAGES} - {"index"}
    assert pages == listed


EXAMPLES = [pytest.param(*block, id=f"{block[0]}:{block[1]}") for block in python_blocks()]


@pytest.mark.parametrize(("page", "line", "code"), EXAMPLES)
def test_python_example_runs(page: str, line: int, code: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # Each block as written, with a small budget: what is checked is that it runs (in a folder of its own: some save)
    monkeypatch.chdir(tmp_path)
    exec(compile(small_budget(code), f"docs/{page}:{line}", "exec"), {"__name__": "docs_example"})


def test_a_broken_example_fails(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # The runner above executes what it is given: a misspelt argument raises
    monkeypatch.chdir(tmp_path)
    code = 'from sb3_classic import NStepSARSA\nNStepSARSA("MlpPolicy", "CartPole-v1", n_step=3).learn(100)\n'
    with pytest.raises(TypeError):
        exec(compile(small_budget(code), "broken", "exec"), {})


def test_small_budget() -> None:
    code = "model.learn(200_000)\nmodel.learn(total_timesteps=50_000)\nmodel.learn(300)\nStop(max_episodes=500)"
    assert small_budget(code) == "model.learn(1000)\nmodel.learn(total_timesteps=1000)\nmodel.learn(300)\nStop(max_episodes=5)"


def test_the_links_to_the_repository_name_files_that_exist() -> None:
    links = [(page.name, target) for page in PAGES for target in re.findall(r"\{repo\}`([^`]+)`", page.read_text())]
    assert links, "no {repo} link found: this test checks nothing"
    missing = [(page, target) for page, target in links if not (ROOT / target).exists()]
    assert not missing, f"{{repo}} links to paths the repository does not have: {missing}"


def test_the_commands_name_modules_and_extras_that_exist() -> None:
    extras = set(importlib.metadata.metadata("sb3_classic").get_all("Provides-Extra") or [])
    assert "zoo" in extras
    modules, named_extras = set(), set()
    for page in PAGES:
        for line in bash_lines(page.read_text()):
            for command in line.split("&&"):
                words = shlex.split(command)
                if words[:2] == ["python", "-m"]:
                    modules.add(words[2])
                if words[:2] == ["pip", "install"]:
                    for word in words[2:]:
                        named_extras.update(re.findall(r"\.\[([\w,]+)\]", word))
    assert {"rl_zoo3.train", "benchmarks.run", "sb3_classic.studies"} <= modules
    missing = sorted(module for module in modules if importlib.util.find_spec(module) is None)
    assert not missing, f"python -m of modules that do not exist: {missing}"
    unknown = {extra for group in named_extras for extra in group.split(",")} - extras
    assert not unknown, f"pip install of extras the package does not define: {unknown}"


# --- Examples whose output the pages state ------------------------------------------------------------------------------


def example(page: str, after: str) -> str:
    """:return: the first ``python`` block of ``docs/<page>`` after the text ``after``"""
    (code,) = re.findall(re.escape(after) + r".*?```python\n(.*?)```", page_text(page), flags=re.DOTALL)[:1]
    return code


@functools.cache
def book_figure_example_output() -> float:
    """:return: what Fig 13.2's example prints, run as written (the whole run, ~10 s; once for the tests that read it)"""
    code = example("guide/textbook.md", "## A figure's point with the public API alone")
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        exec(compile(code, "docs/guide/textbook.md Fig 13.2 example", "exec"), {})
    return float(printed.getvalue().strip().splitlines()[-1])


@functools.cache
def trains_as_the_committed_results() -> bool:
    """
    :return: whether a seeded run here repeats its committed digest (``benchmarks/results/digest.json``): the CPU kind
        and library versions the pages' numbers were trained with, so that a seed's printed digits are its digits here
    """
    from benchmarks import digest

    committed = json.loads((RESULTS / "digest.json").read_text())
    return digest.configuration_digest("reinforce-1-env") == committed["reinforce-1-env"]


def test_book_figure_example_prints_the_books_number() -> None:
    # Fig 13.2's example: plain REINFORCE per step on the short corridor, episodes 401-500; the book gives -15.1 +- 0.2
    # over 100 runs, and the page says what the example's seed prints
    assert -17.0 < book_figure_example_output() < -13.5
    (stated,) = re.findall(r"This prints (−[\d.]+)", page_text("guide/textbook.md"))
    assert -17.0 < float(stated.replace("−", "-")) < -13.5


def test_book_figure_example_prints_the_pages_digits_where_training_repeats_the_committed_results() -> None:
    if not trains_as_the_committed_results():
        pytest.skip(
            "seeded training here does not repeat benchmarks/results/digest.json (another CPU kind or library versions "
            "round otherwise): the seed's run takes other draws, so the page's digits are not this machine's"
        )
    printed = book_figure_example_output()
    assert f"This prints {printed:.2f}".replace("-", "−") in page_text("guide/textbook.md"), printed


def test_tile_coding_example_runs_as_written() -> None:
    # Mountain Car with the book's settings, its whole budget (10,000 steps, ~5 s): "the first episodes take about a
    # thousand steps each", then shorter (the book's Fig 10.1: the optimistic weights explore, episodes shorten)
    code = example("modules/tile_coding.md", "## Example")
    namespace: dict[str, Any] = {}
    exec(compile(code, "docs/modules/tile_coding.md example", "exec"), namespace)
    lengths = [episode["l"] for episode in namespace["model"].ep_info_buffer]
    assert len(lengths) >= 3
    # (unseeded, as written: one of the first episodes can take 3,000 steps or more; their median is about a thousand)
    first = float(np.median(lengths[:3]))
    assert 300 < first < 3000
    assert lengths[-1] < first


def test_own_env_example_prints_what_the_page_says(capsys: pytest.CaptureFixture[str]) -> None:
    # The custom env of "Training on your own Gymnasium env", as written (3,000 steps per algorithm, ~10 s)
    code = example("guide/install.md", "## Training on your own Gymnasium env")
    exec(compile(code, "docs/guide/install.md own env example", "exec"), {})
    printed = capsys.readouterr().out.strip().splitlines()[-2:]
    assert printed == ["REINFORCE: -7.0 ± 0.0 (the best is −7)", "NStepSARSA: -7.0 ± 0.0 (the best is −7)"]
    assert "This prints −7.0 ± 0.0 for both" in page_text("guide/install.md")


# --- Numbers copied from the committed results --------------------------------------------------------------------------


def minus(text: str) -> str:
    """:return: the text with the pages' minus signs as the results files write them"""
    return text.replace("−", "-")


def learning_rows(results: Path = RESULTS / "learning.md") -> dict[tuple[str, str], str]:
    """:return: (env, algorithm) → that row of ``results`` (``benchmarks/results/learning.md`` by default)"""
    rows: dict[tuple[str, str], str] = {}
    env = ""
    for line in results.read_text().splitlines():
        if line.startswith("## ") and "threshold" in line:
            env = line.split()[1]
        elif line.startswith("| ") and env:
            rows[(env, line.split("|")[1].strip())] = line
    return rows


def headline_tables(text: str, first_column: str = "CartPole-v1 final") -> list[list[str]]:
    """
    :return: the rows of a page's results tables whose first header after the empty one is ``first_column`` (by
        default the table of both envs: CartPole-v1 final, …, Acrobot-v1 final, …), as cells
    """
    heading = re.escape(first_column)
    tables = re.findall(rf"^\| \| {heading} .*?\n\|[-|]+\n((?:\|.*\n)+)", text, flags=re.MULTILINE)
    return [[cell.strip() for cell in row.strip().strip("|").split("|")] for table in tables for row in table.splitlines()]


@pytest.mark.parametrize("path", ["README.md", "docs/guide/benchmarks.md"])
def test_the_learning_table_is_the_committed_results(path: str) -> None:
    rows = learning_rows()
    table = headline_tables((ROOT / path).read_text())
    assert len(table) == 5, f"{path}: the learning table of both envs was not found"
    for algorithm, *cells in table:
        name = algorithm.strip("*")
        for env, env_cells in (("CartPole-v1", cells[:4]), ("Acrobot-v1", cells[4:])):
            row = rows[(env, name)]
            for cell in env_cells:
                assert f"| {minus(cell)} |" in row, f"{path}: {name} {env} {cell!r} is not in learning.md's {row!r}"


@pytest.mark.parametrize("path", ["README.md", "docs/guide/benchmarks.md"])
def test_the_lunar_lander_table_is_the_committed_results(path: str) -> None:
    results = RESULTS / "lunar-lander" / "learning.md"
    rows = learning_rows(results)
    algorithms = []
    for algorithm, *cells in headline_tables((ROOT / path).read_text(), "LunarLander-v3 final"):
        name = algorithm.strip("*")
        algorithms.append(name)
        row = rows[("LunarLander-v3", name)]
        for cell in cells:
            assert f"| {minus(cell)} |" in row, f"{path}: {name} {cell!r} is not in {results.name}'s {row!r}"
    assert algorithms == ["REINFORCE", "NStepSARSA", "A2C", "PPO", "DQN"], f"{path}: {algorithms}"


@pytest.mark.parametrize("path", ["README.md", "docs/guide/benchmarks.md"])
def test_the_throughput_ratios_are_the_committed_results(path: str) -> None:
    committed = (RESULTS / "throughput.md").read_text()
    (table,) = re.findall(r"^\| \| CartPole-v1, 1 env .*?\n\|[-|]+\n((?:\|.*\n)+)", (ROOT / path).read_text(), re.MULTILINE)
    columns = [("CartPole-v1", 1), ("CartPole-v1", 8), ("Acrobot-v1", 1), ("Acrobot-v1", 8)]
    for row in table.splitlines():
        algorithm, *ratios = (cell.strip() for cell in row.strip().strip("|").split("|"))
        position = 5 if algorithm.startswith("REINFORCE") else 8  # the ratio's column in throughput.md
        for (env, n_envs), ratio in zip(columns, ratios, strict=True):
            # (the first table's row: the time breakdown under it has a row per algorithm)
            line = re.findall(rf"^\| {env} \| {n_envs} \|.*$", committed, flags=re.MULTILINE)[0]
            assert line.split("|")[position].strip().startswith(ratio + " "), f"{path}: {algorithm} {env} {n_envs}: {ratio}"


def test_the_book_table_is_the_committed_results() -> None:
    committed = (RESULTS / "textbook" / "textbook.md").read_text()
    text = page_text("guide/textbook.md")
    (table,) = re.findall(r"<!-- textbook-table -->\n(.*?)<!-- /textbook-table -->", text, flags=re.DOTALL)
    rows = [row for row in table.splitlines() if row.startswith("| ") and not row.startswith("| Figure")]
    assert len(rows) >= 6
    assert [row for row in rows if row not in committed] == []


def test_the_studies_verdicts_are_the_committed_results() -> None:
    # The seed report's table (its page, linked from the studies guide): each row's verdicts (as stated, and with one
    # step per episode where the study reads it) are its figure's committed verdicts, claim by claim in the study
    # file's order
    text = page_text("guide/seed_report.md")
    (table,) = re.findall(r"^\| Figure \| Claim \| As stated \| One step per episode \|\n\|[-|]+\n((?:\|.*\n)+)", text, re.M)
    rows_of: dict[int, list[list[str]]] = {}
    for row in table.splitlines():
        figure, _, *verdicts = (cell.strip() for cell in row.strip().strip("|").split("|"))
        rows_of.setdefault(int(figure), []).append(verdicts)
    records = {int(path.name[3:5]): path for path in (RESULTS / "studies").glob("fig*.json")}
    assert sorted(rows_of) == sorted(records), "one figure's rows per committed study"
    for figure, rows in rows_of.items():
        record = json.loads(records[figure].read_text())
        for reading, column in (("as stated", 0), ("one_step_per_episode", 1)):
            verdicts = [claim["verdict"] for claim in record["claims"] if claim["reading"] == reading]
            cells = [re.sub(r"[*(].*", "", row[column].replace("**", "")).strip() for row in rows]
            if not verdicts:
                assert set(cells) == {"–"}, f"Fig {figure}: {reading} is not a reading of its study"
                continue
            # (a cell starts with its verdict; what follows a comma or in parentheses is the detail)
            assert [cell.split(",")[0] for cell in cells] == verdicts, f"Fig {figure}, {reading}"
