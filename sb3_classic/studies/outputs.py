"""
The outputs of a study, from its runs in the cache: per study a figure in the seed report's form (``<name>.png``),
its table (``<name>.md``, ``<name>.csv``) and its verdicts (``<name>.json``); and ``STUDIES.md``, one row per claim.
"""

import dataclasses
import hashlib
import json
import math
import shlex
import textwrap
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import yaml
from matplotlib.ticker import MaxNLocator

import sb3_classic
from sb3_classic.harness.common import RunSpec, code_versions
from sb3_classic.harness.lockstep import training_plan
from sb3_classic.harness.runner import EPISODES_FILE, RUN_FILE, load_run, load_run_table
from sb3_classic.studies import sequential, stats, untrained
from sb3_classic.studies.spec import STATED, StudyRun, StudySpec

STUDIES_FILE = "STUDIES.md"
#: The measured error rates of the verdicts' rule, beside the repository's results (``benchmarks.studies.error_rates``)
ERROR_CONTROL = "error-control.md"
NOT_RUN = "not yet run"
#: The module of the command the outputs show (``python -m sb3_classic.studies ...``)
PROGRAM = "sb3_classic.studies"
#: The panels (one per reading) in a row of a study's figure
MAX_PANEL_COLUMNS = 4
#: Characters of the figure's title per inch of its width (at its font size, 10 points), where a line wraps
TITLE_CHARACTERS_PER_INCH = 12
#: STUDIES.md names each other reading's verdict of a claim up to this many readings, and sums them up beyond
MAX_LISTED_READINGS = 3
#: Beside a verdict in STUDIES.md where the compared variants stayed at a random policy's return (``stats.untrained_note``)
UNTRAINED_MARK = "not learned: no compared variant above a random policy's return"


@dataclass
class StudyResults:
    """
    A study's runs found in the cache, and what follows from them.

    :param study: the study
    :param returns: per (reading, variant), the training returns, seeds × episodes (the figure's: with a budget in
        env steps, the episodes every seed completed; the metrics are over each seed's own)
    :param seeds: per (reading, variant), the seeds found
    :param episode_counts: per (reading, variant), the episodes each of its seeds completed (all the same with a budget
        in episodes)
    :param metrics: per (reading, variant), ``stats.seed_metrics``
    :param verdicts: per reading, the result of each claim (absent where a variant has no run)
    :param missing: the runs not in the cache
    :param run_seconds: per run found (its cache key), its ``learn()`` and final evaluation time in seconds (one CPU
        core each; a run trained in lockstep, its share of its population's); studies and readings that share a run
        share its key
    :param lockstep_runs: the keys of the runs found that were trained in lockstep (``run.json``'s ``training``)
    :param random_levels: per (reading, variant) found, a uniformly random policy's mean return on its env and its
        interval over episodes (``untrained``; absent for an env without a time limit)
    :param runs: per (reading, variant), each seed found's cache key when it ran, its settings' key
        (``settings_key``), CPU seconds and training, for ``<name>-seeds.csv``
    :param recorded: the runs found only in the study's committed ``<name>-seeds.csv`` (``recorded_seeds``): their
        metrics, not their episodes (the figure and table draw the seeds in the cache)
    :param looks: a sequential design's verdict of each claim as stated, by its text (``sequential``)
    """

    study: StudySpec
    returns: dict[tuple[str, str], np.ndarray] = field(default_factory=dict)
    seeds: dict[tuple[str, str], list[int]] = field(default_factory=dict)
    episode_counts: dict[tuple[str, str], list[int]] = field(default_factory=dict)
    metrics: dict[tuple[str, str], dict[str, np.ndarray]] = field(default_factory=dict)
    verdicts: dict[str, list[stats.ClaimResult]] = field(default_factory=dict)
    missing: list[StudyRun] = field(default_factory=list)
    run_seconds: dict[str, float] = field(default_factory=dict)
    lockstep_runs: set[str] = field(default_factory=set)
    random_levels: dict[tuple[str, str], stats.Interval] = field(default_factory=dict)
    n_runs: int = 0
    runs: dict[tuple[str, str], list[dict[str, Any]]] = field(default_factory=dict)
    recorded: int = 0
    looks: dict[str, sequential.SequentialVerdict] = field(default_factory=dict)

    @property
    def runs_without_episodes(self) -> int:
        """Runs found that completed no episode within their budget (a budget in env steps shorter than an episode)."""
        return sum(int(np.count_nonzero(np.isnan(metrics["mean_return"]))) for metrics in self.metrics.values())

    @property
    def learn_seconds(self) -> float:
        """The compute of the study's distinct runs, in CPU seconds."""
        return math.fsum(self.run_seconds.values())


def settings_key(spec: RunSpec, study: StudySpec) -> str:
    """
    :param spec: a run of ``study``
    :param study: the study (its threshold and window, which its recorded metrics depend on)
    :return: the key of a run's settings and seed without its code's digest (``RunSpec.key`` has it): a seed recorded
        in a study's committed ``<name>-seeds.csv`` counts as run while its settings, seed, metrics' threshold and
        sb3_classic's release are the same (the package keeps seeded training identical between releases' edits,
        ``benchmarks.digest``; a change of results comes with a new release)
    """
    content = {
        "hyperparams": spec.hyperparams,
        "run": {name: getattr(spec, name) for name in ("algo", "env_id", "seed", "n_timesteps", "max_episodes", "lockstep")},
        "release": sb3_classic.__version__,
        # (NaN, no threshold, as a string: JSON has no NaN)
        "threshold": [repr(study.threshold), study.threshold_window],
    }
    return hashlib.sha256(json.dumps(content, sort_keys=True).encode()).hexdigest()[:16]


def recorded_seeds(study: StudySpec, results_dir: Path | None) -> dict[str, dict[str, Any]]:
    """
    :param study: the study
    :param results_dir: where its outputs were written (None: no records)
    :return: the rows of its ``<name>-seeds.csv`` there, by ``settings_key``: the seeds run before, on this machine
        or another, whose runs the cache may no longer hold
    """
    path = None if results_dir is None else results_dir / f"{study.name}-seeds.csv"
    if path is None or not path.exists():
        return {}
    frame = pd.read_csv(path)
    if "settings" not in frame.columns:
        return {}
    return {str(row["settings"]): row for row in frame.to_dict("records")}


def load_study_results(study: StudySpec, cache_dir: Path, results_dir: Path | None = None) -> StudyResults:
    """
    :param study: the study
    :param cache_dir: the harness's cache
    :param results_dir: where the study's outputs are (its committed ``<name>-seeds.csv``: seeds not in the cache
        count from it, ``recorded_seeds``)
    :return: its runs found in ``cache_dir`` (or recorded), their metrics and the claims' verdicts; with a sequential
        design, the runs of its next look missing
    :raise DamagedRunError: naming a cached run whose files cannot be read
    """
    results = StudyResults(study)
    frames: dict[tuple[str, str], list[pd.DataFrame]] = {}
    recorded = recorded_seeds(study, results_dir)
    values: dict[tuple[str, str], list[dict[str, float]]] = {}
    for run in study.runs(sequential.seeds_planned(study)):
        run_dir, key = run.spec.run_dir(cache_dir), (run.reading, run.variant)
        settings, record = settings_key(run.spec, study), None
        if (run_dir / RUN_FILE).exists():
            summary = load_run(run_dir)
            seconds = float(summary["learn_time_s"]) + float(summary.get("eval_time_s", 0.0))
            lockstep, run_key = summary.get("training") == "lockstep", run.spec.key()
            frames.setdefault(key, []).append(load_run_table(run_dir, EPISODES_FILE, study.budget.episodes or 0))
        elif settings in recorded:
            record = recorded[settings]
            seconds, lockstep, run_key = float(record["cpu_seconds"]), bool(record["lockstep"]), str(record["run"])
            results.recorded += 1
        else:
            continue
        results.run_seconds[run_key] = seconds
        if lockstep:
            results.lockstep_runs.add(run_key)
        results.n_runs += 1
        results.seeds.setdefault(key, []).append(run.seed)
        results.runs.setdefault(key, []).append(
            {"run": run_key, "settings": settings, "cpu_seconds": seconds, "lockstep": lockstep}
        )
        values.setdefault(key, []).append(record or {})
    for key, found in values.items():
        # Each seed's metrics: from its episodes where the cache has them, else as recorded
        episodes = iter(frames.get(key, []))
        rows = [None if record else next(episodes) for record in found]
        cached = [frame for frame in rows if frame is not None]
        returns = stats.seed_returns(cached, study.budget.episodes) if cached else []
        computed = stats.seed_metrics(returns, study.threshold, study.threshold_window) if cached else {}
        index = iter(range(len(cached)))
        columns: dict[str, list[Any]] = {name: [] for name in (*stats.METRIC_LABELS, "reached")}
        for record in found:
            at = None if record else next(index)
            for name, column in columns.items():
                # (a study without a threshold records no episodes to threshold: NaN, and not reached)
                missing = False if name == "reached" else np.nan
                column.append(record.get(name, missing) if record else computed[name][at])
        results.metrics[key] = {
            name: np.asarray(column, dtype=bool if name == "reached" else float) for name, column in columns.items()
        }
        if cached:
            results.returns[key] = stats.returns_matrix(returns)
        results.episode_counts[key] = [len(row) for row in returns] or [study.budget.episodes or 0]
        results.random_levels.update(_random_level(study, key, cache_dir))
    for reading in study.readings:
        variants = {variant: results.metrics.get((reading, variant)) for variant in study.variants}
        levels = {variant: level for (read, variant), level in results.random_levels.items() if read == reading}
        judged = []
        for claim in study.claims:
            needed = (claim.variant, *claim.others)
            if all(variants[variant] is not None for variant in needed):
                metrics: dict[str, Any] = {variant: variants[variant] for variant in needed}
                margin = sequential.claim_margin(study, claim)
                if study.design is not None and reading == STATED:
                    # A look's n seeds are the study's first n: a variant's found after a gap wait for it
                    prefix = {name: _consecutive(study, results.seeds[(reading, name)]) for name in needed}
                    metrics = {name: _first_seeds({name: metrics[name]}, prefix[name])[name] for name in needed}
                    looked = sequential.judge_sequentially(claim, metrics, study.design, margin, study.return_range())
                    if looked is None:
                        continue
                    results.looks[claim.text] = looked
                    result = looked.result
                else:
                    first = study.design.looks[0] if study.design is not None else None
                    result = stats.judge(claim, _first_seeds(metrics, first), margin=margin)
                note = stats.untrained_note(claim, metrics, levels)
                judged.append(dataclasses.replace(result, untrained=note))
        results.verdicts[reading] = judged
    wanted = sequential.seeds_wanted(study, results.looks)
    results.missing = [run for run in study.runs(wanted) if run.seed not in results.seeds.get((run.reading, run.variant), [])]
    return results


def _consecutive(study: StudySpec, seeds: Sequence[int]) -> int:
    """:return: how many of the study's first seeds, in order, are among ``seeds`` (found in the cache or recorded)"""
    found = set(seeds)
    return next((index for index, seed in enumerate(study.seeds) if seed not in found), len(study.seeds))


def _first_seeds(metrics: dict[str, Any], n: int | None) -> dict[str, Any]:
    """:return: each variant's metrics of its first ``n`` seeds (None: all)"""
    return {name: {key: values[:n] for key, values in found.items()} for name, found in metrics.items()}


def _random_level(study: StudySpec, key: tuple[str, str], cache_dir: Path) -> dict[tuple[str, str], stats.Interval]:
    """:return: for the (reading, variant) ``key``, a uniformly random policy's return on its env, if measurable"""
    reading, variant = key
    env_kwargs = study.zoo_entry(variant, reading).get("env_kwargs")
    returns = untrained.cached_random_returns(cache_dir, study.env_id, env_kwargs)
    return {} if returns is None else {key: stats.interval(returns)}


def _trained_how(results: StudyResults) -> str:
    """:return: how the study's runs found were trained, for its page (nothing if every one alone)"""
    lockstep = len(results.lockstep_runs)
    if not lockstep:
        return ""
    if lockstep == len(results.run_seconds):
        return ", trained in lockstep: each variant's seeds one population"
    return f", {lockstep} of them trained in lockstep"


def training_summary(study: StudySpec) -> str:
    """
    :return: how the seeds of each variant (and reading) train, as planned (``harness.lockstep.training_plan``):
        together, one population of the algorithm, or one by one, with why and what would train them together; one
        phrase for the study where every variant trains alike
    """
    runs = study.runs(sequential.seeds_planned(study))
    reasons: dict[tuple[str, str], str | None] = {}
    seeds: dict[tuple[str, str], int] = {}
    for run, reason in zip(runs, training_plan([run.spec for run in runs], study.lockstep), strict=True):
        reasons.setdefault((run.reading, run.variant), reason)
        seeds[(run.reading, run.variant)] = seeds.get((run.reading, run.variant), 0) + 1
    groups: dict[str, list[str]] = {}
    for (reading, variant), reason in reasons.items():
        if reason is None and study.design is not None:
            # (a look's new seeds of a variant: its looks are run one after the other)
            how = "seeds trained together, each look's new ones as one population (lockstep)"
        elif reason is None:
            how = f"{seeds[(reading, variant)]} seeds trained together, as one population (lockstep)"
        else:
            how = f"seeds trained one by one: {reason}"
        groups.setdefault(how, []).append(f"`{variant}`" + ("" if reading == STATED else f" [{reading}]"))
    if len(groups) == 1:
        return f"each variant's {next(iter(groups))}"
    return "; ".join(f"{', '.join(names)}: {how}" for how, names in groups.items())


def study_command(study: StudySpec, extra: Sequence[str] = (), program: str = PROGRAM, root: Path | None = None) -> str:
    """
    :param study: the study
    :param extra: the command's options
    :param program: the module the command runs (``python -m <program>``)
    :param root: the folder the command runs in (default: the working directory)
    :return: the command that runs ``study``: its path relative to ``root`` where it is inside, else as given
    """
    assert study.path is not None
    path, root = study.path.resolve(), (root or Path.cwd()).resolve()
    shown = path.relative_to(root).as_posix() if path.is_relative_to(root) else str(study.path)
    return shlex.join(["python", "-m", program, shown, *extra])


def has_threshold(study: StudySpec) -> bool:
    """:return: whether the study has a threshold (one without: NaN, where no claim reads it, ``spec.load_study``)"""
    return math.isfinite(study.threshold)


def shown_metrics(study: StudySpec) -> list[str]:
    """:return: the metrics of ``stats.METRIC_LABELS`` the study's outputs give: episodes to threshold where it has one"""
    return [metric for metric in stats.METRIC_LABELS if has_threshold(study) or metric != "episodes_to_threshold"]


def seeds_frame(results: StudyResults) -> pd.DataFrame:
    """
    :return: one row per run found: reading, variant, seed, each metric of the seed and whether it reached the
        threshold (the values the intervals and verdicts are computed from; a study without a threshold has neither
        episodes to threshold nor ``reached``)
    """
    metric_names = shown_metrics(results.study)
    reached = ["reached"] if has_threshold(results.study) else []
    rows = []
    for (reading, variant), metrics in results.metrics.items():
        for index, seed in enumerate(results.seeds[(reading, variant)]):
            row: dict[str, Any] = {"reading": reading, "variant": variant, "seed": seed}
            row |= {metric: float(metrics[metric][index]) for metric in metric_names}
            row |= {name: bool(metrics[name][index]) for name in reached}
            rows.append(row | results.runs[(reading, variant)][index])
    columns = ["reading", "variant", "seed", *metric_names, *reached, "run", "settings", "cpu_seconds", "lockstep"]
    return pd.DataFrame(rows, columns=columns)


def summary_frame(results: StudyResults) -> pd.DataFrame:
    """
    :return: one row per (reading, variant): seeds, the fewest and most episodes a seed completed (``episodes``,
        ``episodes_max``: equal with a budget in episodes), and each metric's mean over seeds with its bootstrap interval
        (95%; from fewer than ``stats.MIN_SEEDS`` seeds, not one that holds), and the seeds that reached the threshold
        (a study without a threshold: neither these nor episodes to threshold)
    """
    rows = []
    for (reading, variant), metrics in results.metrics.items():
        row: dict[str, Any] = {"reading": reading, "variant": variant, "seeds": len(results.seeds[(reading, variant)])}
        counts = results.episode_counts[(reading, variant)]
        row["episodes"], row["episodes_max"] = min(counts), max(counts)
        for metric in shown_metrics(results.study):
            value = stats.interval(metrics[metric])
            row[metric], row[f"{metric}_low"], row[f"{metric}_high"] = value.estimate, value.low, value.high
        if has_threshold(results.study):
            row["seeds_reaching"] = int(metrics["reached"].sum())
        rows.append(row)
    return pd.DataFrame(rows)


def markdown_table(results: StudyResults) -> str:
    """:return: the study's table in markdown (estimates with their 95% intervals)"""
    frame = summary_frame(results)
    readings = len(results.study.readings) > 1
    metric_names, reaching = shown_metrics(results.study), has_threshold(results.study)
    header = ["Reading"] if readings else []
    header += ["Variant", "Seeds", "Episodes", *(stats.METRIC_LABELS[metric] for metric in metric_names)]
    header += ["Seeds reaching"] if reaching else []
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for row in frame.itertuples(index=False):
        values = row._asdict()
        cells = [values["reading"]] if readings else []
        fewest, most = values["episodes"], values["episodes_max"]
        cells += [f"`{values['variant']}`", str(values["seeds"]), str(fewest) if fewest == most else f"{fewest}–{most}"]
        for metric in metric_names:
            interval = stats.Interval(values[metric], values[f"{metric}_low"], values[f"{metric}_high"])
            cells.append(interval.format())
        if reaching:
            cells.append(f"{values['seeds_reaching']}/{values['seeds']}")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def plot_study(results: StudyResults, path: Path) -> Path:
    """
    The seed report's figure: training return per episode, the mean over seeds with its bootstrap band (``_band``), one
    line per variant (a moving average of ``study.smooth`` episodes, of each seed before the mean); one panel per
    reading, ``MAX_PANEL_COLUMNS`` to a row.

    :return: ``path``
    """
    study = results.study
    readings = list(study.readings)
    columns = min(len(readings), MAX_PANEL_COLUMNS)
    rows = -(-len(readings) // columns)
    figure, axes = plt.subplots(
        rows, columns, figsize=(6.4 * columns, 4.4 * rows), squeeze=False, sharey=True, layout="constrained"
    )
    for axis in axes.flat[len(readings) :]:
        axis.set_visible(False)
    for axis, reading in zip(axes.flat, readings, strict=False):
        for variant in study.variants:
            returns = results.returns.get((reading, variant))
            if returns is None:
                continue
            mean, low, high = stats.episode_band(stats.moving_average(returns, study.smooth))
            episodes = np.arange(1, len(mean) + 1)
            found = len(results.seeds[(reading, variant)])
            others = f" of {found}: the others recorded only" if found > returns.shape[0] else ""
            drawn = f"{returns.shape[0]} seeds{others}"
            (line,) = axis.plot(episodes, mean, label=f"{variant} ({drawn})", linewidth=1.2)
            axis.fill_between(episodes, low, high, color=line.get_color(), alpha=0.2, linewidth=0)
        if has_threshold(study):
            axis.axhline(study.threshold, color="grey", linestyle=":", linewidth=1)
        axis.set_xlabel("Episode")
        axis.xaxis.set_major_locator(MaxNLocator(integer=True))
        axis.set_title(reading if len(readings) > 1 else study.env_id, fontsize=10)
        if axis.lines[:-1]:
            axis.legend(fontsize=8, loc="best")
        else:
            axis.text(0.5, 0.5, "no run in the cache yet", transform=axis.transAxes, ha="center", color="grey")
        axis.grid(alpha=0.3)
    smooth = f", moving average of {study.smooth} episodes" if study.smooth > 1 else ""
    for row in axes:
        row[0].set_ylabel("Training return")
    title = [study.title, f"mean over seeds with its {_band(_fewest_seeds(results))}{smooth}"]
    width = int(TITLE_CHARACTERS_PER_INCH * figure.get_figwidth())
    lines = [line for text in title for line in text.splitlines()]
    figure.suptitle("\n".join(textwrap.fill(line, width) for line in lines), fontsize=10)
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return path


def write_study(results: StudyResults, results_dir: Path, command: str, reduced: bool = False) -> Path:
    """
    Write ``<name>.png``, ``<name>.csv`` (per variant), ``<name>-seeds.csv`` (per run), ``<name>.md`` and
    ``<name>.json`` of a study into ``results_dir``.

    :param results: the study's results
    :param results_dir: where
    :param command: the command that produced them
    :param reduced: whether seeds or budget were reduced from the study file's (not the study's result)
    :return: the markdown file
    """
    study = results.study
    results_dir.mkdir(parents=True, exist_ok=True)
    figure = results_dir / f"{study.name}.png"
    if not figure.exists() or not results.recorded:
        # (runs counted from the seeds' record have no episodes to draw: the figure drawn with them is kept)
        plot_study(results, figure)
    summary_frame(results).to_csv(results_dir / f"{study.name}.csv", index=False)
    seeds = seeds_frame(results)
    # The rows of other settings recorded before (another release, --separate, another threshold) are kept: a record is
    # never lost to a command that did not read it
    kept = [row for key, row in recorded_seeds(study, results_dir).items() if key not in set(seeds["settings"])]
    pd.concat([seeds, pd.DataFrame(kept, columns=seeds.columns)] if kept else [seeds]).to_csv(
        results_dir / f"{study.name}-seeds.csv", index=False
    )
    claims = []
    for reading, judged in results.verdicts.items():
        for result in judged:
            looked = results.looks.get(result.claim.text) if reading == STATED else None
            claims.append(
                {
                    "text": result.claim.text,
                    "reading": reading,
                    "verdict": result.verdict,
                    "measured": result.measured + (f" ({_looks_taken(looked)})" if looked is not None else ""),
                    "favour": stats.favour(result),
                    **({"untrained": result.untrained} if result.untrained else {}),
                    **({"seeds": looked.seeds, "looks": looked.looks_taken} if looked is not None else {}),
                    **({"seeds_needed": looked.needed} if looked is not None and looked.needed else {}),
                }
            )
    record = {
        "study": study.name,
        "title": study.title,
        "source": study.source,
        "env_id": study.env_id,
        "algo": study.algo,
        "seeds": len(study.seeds),
        **({"design": study.design.describe()} if study.design is not None else {}),
        "budget": study.budget.describe(),
        "command": command,
        "reduced": reduced,
        "complete": not results.missing,
        "runs": results.n_runs,
        "missing_runs": len(results.missing),
        "cpu_hours": results.learn_seconds / 3600,
        "run_seconds": results.run_seconds,
        "lockstep_runs": sorted(results.lockstep_runs),
        # The runs of the study as stated (its other readings are alternatives), for STUDIES.md's compute
        "stated_runs": sorted(
            {row["run"] for (reading, _), rows in results.runs.items() if reading == STATED for row in rows}
        ),
        "claims": claims,
        "claim_texts": [claim.text for claim in study.claims],
    }
    (results_dir / f"{study.name}.json").write_text(json.dumps(record, indent=2) + "\n")
    censored_at = "the episode budget" if study.budget.episodes is not None else "the episodes they completed"
    lines = [f"# {study.title}", ""]
    if study.source:
        lines += [f"Source: {study.source}.", ""]
    if reduced:
        banner = "**Reduced run** (other seeds or another budget than the study file's: `--seeds`, `--episodes`, `--steps`)"
        lines += [f"{banner}: not the study's result.", ""]
    lines += [
        "Produced by:",
        "",
        "```",
        command,
        "```",
        "",
        f"- {study.algo} on {study.env_id}, {_seeds_line(study)}, {study.budget.describe()} per run "
        f"({results.n_runs} runs found, {len(results.missing)} missing; {results.learn_seconds / 3600:.2f} CPU hours for "
        f"the {len(results.run_seconds)} distinct ones{_trained_how(results)}).",
        f"- Training: {training_summary(study)}.",
        _threshold_note(study, censored_at),
        f"- Intervals{' of the table' if study.design is not None else ''}: {_intervals(_fewest_seeds(results))}; "
        "verdicts by the rule of [STUDIES.md](STUDIES.md).",
        *_design_notes(results, results_dir),
        *_random_level_notes(results),
        *_short_budget_notes(study),
        *_step_budget_notes(results),
        *_empty_run_notes(results),
        f"- Versions: {', '.join(f'{name} {version}' for name, version in code_versions(study.algo).items())}.",
        "",
        "## Claims",
        "",
    ]
    if results.missing and study.design is not None:
        lines += [
            f"**Looks to come**: the next look's {len(results.missing)} runs are not yet run (run the command again to "
            "run them); the undecided claims' verdicts are of the looks taken.",
            "",
        ]
    elif results.missing:
        lines += [
            f"**Partial**: {len(results.missing)} of {results.n_runs + len(results.missing)} runs are missing (run the "
            "command again to run them); the verdicts are of the runs found.",
            "",
        ]
    partial = f" (partial: {len(results.missing)} runs missing)" if results.missing and study.design is None else ""
    for reading, judged in results.verdicts.items():
        suffix = "" if reading == STATED else f" (reading `{reading}`)"
        by_text = {result.claim.text: result for result in judged}
        for claim in study.claims:
            found = by_text.get(claim.text)
            if found is None:
                lines.append(f"- **{NOT_RUN}**{suffix}: {claim.text} (the runs of a variant it compares are missing).")
            else:
                looked = results.looks.get(claim.text) if reading == STATED else None
                taken = f" ({_looks_taken(looked)})" if looked is not None else ""
                line = f"- **{found.verdict}**{partial}{suffix}: {claim.text}. Measured: {found.measured}{taken}."
                lines.append(line + (f" **Not learned**: {found.untrained}." if found.untrained else ""))
    if len(results.verdicts) > 1:
        lines += ["", *_best_readings([claim.text for claim in study.claims], claims)]
    lines += [
        "",
        "## Table",
        "",
        markdown_table(results) if results.metrics else NOT_RUN,
        "",
        f"![{study.title}]({figure.name})",
    ]
    lines += [
        "",
        "## Settings",
        "",
        "The zoo YAML entry of each variant (as stated; readings apply their overrides on top):",
        "",
    ]
    entries = {variant: _without_budget(study.zoo_entry(variant)) for variant in study.variants}
    lines += ["```yaml", settings_yaml(entries), "```"]
    if len(study.readings) > 1:
        readings = {name: overrides for name, overrides in study.readings.items() if name != STATED}
        lines += ["", "Readings:", "", "```yaml", settings_yaml(readings), "```"]
    if study.notes:
        lines += ["", "## Notes", "", study.notes]
    path = results_dir / f"{study.name}.md"
    path.write_text("\n".join(lines) + "\n")
    return path


RULE = f"""Verdicts are decided by 95% bootstrap confidence intervals over seeds (`scipy.stats.bootstrap`, BCa, 10,000
resamples; each variant's seeds resampled independently):

- **better** (A beats B on a metric): the interval of A − B, oriented so that positive means A is better (lower is
  better for episodes to threshold and for the spread over seeds). *supported* if it lies above 0, *reversed* if below
  0, *too close to call* if it contains 0. Against several variants: supported if every comparison is, reversed if
  every one is reversed, *not supported* if some are reversed, too close to call otherwise. On the spread over seeds,
  supported or reversed also needs a permutation test of equal spreads (`scipy.stats.permutation_test`) to reject, at
  5% (5%/K at each of a sequential design's K looks).
- **similar** (A and B alike): *supported* if the interval of A − B lies within ± the claim's margin, *not supported* if
  it excludes 0, too close to call otherwise.
- **reaches** / **below** a level, on the metric's own scale: the interval of A's metric lies at or above the level
  (*supported* / *not supported*), below it (the opposite), or across it (too close to call).
- **Equivalence**: a *better* comparison whose interval lies within ± the study's margin (declared in its file; default
  5% of the env's range of returns, 25 on CartPole-v1 and Acrobot-v1) is *not supported: alike within ±m*.
- **A sequential design** (`seeds: {{start, step, max}}`): at each look the claim is judged on each variant's first
  n seeds with studentized bootstrap intervals joined with Student's t-intervals at the look's level, set by Pocock's
  (or O'Brien–Fleming's) group-sequential boundaries so that the error rate stays 5% over all looks (seeds that all
  share one return: the interval the env's range of returns allows); the first decided look is the verdict, and a
  claim undecided at the last look says the seeds per variant that would decide it (error-control.md).
- A claim with fewer than 5 seeds in one of its variants is too close to call, whatever its intervals.
- Beside the verdict, *not learned* where no compared variant's mean return over its last 100 episodes has an
  interval above that of a uniformly random policy's return on its env ({untrained.EPISODES} episodes, or those that
  end within {untrained.MAX_STEPS:,} env steps; measured and cached with the runs): whatever the verdict, it compares
  runs that did not measurably learn.
- Episodes to threshold is censored: a seed that never reaches the threshold counts as the budget, a lower bound of
  its value. Comparisons between variants are of the means within the budget (restricted means); a verdict that
  censoring could overturn is too close to call: a mean shown below a level, two variants shown alike, a comparison
  where no seed of either reached the threshold, the spread over seeds.

Metrics per seed, from the training return of each episode (the Monitor's): the mean over all episodes of the budget,
the mean over the last 100, and the episodes until the mean of the study's `threshold_window` consecutive episodes
(default 100) first reaches its threshold (default: the env's reward threshold, 475 on CartPole-v1, −100 on
Acrobot-v1; a seed that never does counts as the budget)."""


def write_studies_index(
    studies: Sequence[StudySpec],
    results_dir: Path,
    title: str = "Studies",
    program: str = PROGRAM,
    root: Path | None = None,
    extra: Sequence[str] = (),
    reduced: bool = False,
) -> Path:
    """
    ``STUDIES.md``: one row per claim of ``studies`` and of every other study with results in ``results_dir``,
    with its verdict (or "not yet run"), what was measured and the command that re-runs it; and the compute taken.

    :param program: the module of the commands shown (``study_command``)
    :param root: the folder they run in (``study_command``)
    :param extra: the options of the commands shown (``study_command``: a reduced run's budget)
    :param reduced: whether this command's runs are reduced (the title's, where the folder has no results yet)
    :return: its path
    """
    records: dict[str, dict[str, Any]] = {}
    for path in sorted(results_dir.glob("*.json")):
        record = json.loads(path.read_text())
        if isinstance(record, dict) and "claims" in record and "study" in record:
            records[record["study"]] = record
    # One table in the order of the studies' names (a seed report's figures in order), whichever command wrote it last
    rows_of: dict[str, list[tuple[str, str, str, str, str]]] = {}
    for study in studies:
        record = records.get(study.name)
        command = study_command(study, extra, program=program, root=root)
        rows_of[study.name] = _claim_rows(study.name, study.source, [c.text for c in study.claims], record, command)
    for name, record in records.items():
        if name not in rows_of:
            rows_of[name] = _claim_rows(name, record.get("source", ""), record["claim_texts"], record, record["command"])
    rows = [row for name in sorted(rows_of) for row in rows_of[name]]
    listed = {study.name for study in studies}
    # Each distinct run once: studies (and readings) that share settings share their runs. A folder may hold the
    # results of full and of reduced runs (--results-dir given to both): the title and the compute say which
    run_seconds: dict[str, float] = {}
    reduced_runs: set[str] = set()
    lockstep_runs: set[str] = set()
    stated_runs: set[str] = set()
    for record in records.values():
        run_seconds.update(record.get("run_seconds", {}))
        lockstep_runs.update(record.get("lockstep_runs", []))
        stated_runs.update(record.get("stated_runs", []))
        if record.get("reduced"):
            reduced_runs.update(record.get("run_seconds", {}))
    runs, hours = len(run_seconds), math.fsum(run_seconds.values()) / 3600
    kinds = {bool(record.get("reduced")) for record in records.values()} or {reduced}
    if title == "Studies" and kinds == {True}:
        title += " (reduced runs)"
    elif title == "Studies" and kinds == {True, False}:
        title += " (full and reduced runs: the reduced ones are marked)"
    of_reduced = f" ({len(reduced_runs)} of them of reduced runs)" if reduced_runs and len(kinds) > 1 else ""
    counts: dict[str, int] = {}
    for row in rows:
        verdict = row[3].split(" (")[0]
        counts[verdict] = counts.get(verdict, 0) + 1
    tally = ", ".join(f"{count} {verdict}" for verdict, count in sorted(counts.items()))
    planned = [run.spec.key() for study in studies for run in study.runs(sequential.seeds_planned(study))]
    designs = sum(study.design is not None for study in studies)
    stated = stated_runs & set(run_seconds)
    lines = [
        f"# {title}",
        "",
        f"{len(rows)} {plural(len(rows), 'claim', 'claims')}: {tally}.",
        "",
        _family_note(len(rows), studies, results_dir),
        "",
        f"Planned, for the {len(studies)} study {plural(len(studies), 'file', 'files')} named: {len(planned)} runs"
        + (f" at most ({designs} of a sequential design run the looks their claims need)" if designs else "")
        + ", "
        f"{len(set(planned))} distinct (runs of the same settings, in several studies or readings, share their cache "
        "entry)"
        + (
            f"; the table also lists the {len(records) - len(listed & set(records))} other studies with results "
            "in this folder."
            if set(records) - listed
            else "."
        ),
        f"Compute: {runs} distinct {plural(runs, 'run', 'runs')}{of_reduced}, {hours:.1f} CPU hours (`learn()` and the final "
        "evaluation, one core per run; a run trained in lockstep counts its share of its population's), "
        + (
            f"{len(lockstep_runs & set(run_seconds))} of them trained in lockstep "
            f"({math.fsum(run_seconds[key] for key in lockstep_runs & set(run_seconds)) / 3600:.1f} CPU hours), "
            if lockstep_runs & set(run_seconds)
            else ""
        )
        + "summed over the studies' results in this folder, each run once (they may come from several invocations: the "
        "cache resumes)"
        + (
            f"; the studies as stated, without their other readings: {len(stated)} runs, "
            f"{math.fsum(run_seconds[key] for key in stated) / 3600:.1f} CPU hours."
            if stated
            else "."
        ),
        "",
        "| Source | Claim | Measured | Verdict | Command |",
        "|---|---|---|---|---|",
    ]
    lines += ["| " + " | ".join(cell.replace("|", "\\|") for cell in row) + " |" for row in rows]
    lines += ["", "## How verdicts are decided", "", RULE, ""]
    path = results_dir / STUDIES_FILE
    results_dir.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines))
    return path


class _SettingsDumper(yaml.SafeDumper):
    """PyYAML's safe dumper without anchors and aliases: settings two variants share are written out in each."""

    def ignore_aliases(self, data: Any) -> bool:
        return True


def settings_yaml(settings: dict[str, Any]) -> str:
    """
    :param settings: zoo entries or readings, by name
    :return: them as YAML, in their order, each written out in full (no ``&id001`` anchor and ``*id001`` alias where
        two share a value): what a reader pastes into a zoo file
    """
    return yaml.dump(settings, Dumper=_SettingsDumper, sort_keys=False).rstrip()


def _family_note(n_claims: int, studies: Sequence[StudySpec], results_dir: Path) -> str:
    """:return: STUDIES.md's line on the error rate per claim and what it means for all of them together"""
    alpha = 1 - stats.CONFIDENCE
    designs = sum(study.design is not None for study in studies)
    sequential_ones = (
        f"the {designs} {plural(designs, 'study', 'studies')} of a sequential design take wider intervals at each look "
        f"to keep it at {alpha:.0%} however early a claim stops; "
        if designs
        else ""
    )
    return (
        f"Error rate: each claim is designed to say *supported* or *reversed* where there is no difference at most "
        f"{alpha:.0%} of the time ({sequential_ones}a fixed design takes 95% intervals). Over {n_claims} "
        f"{plural(n_claims, 'claim', 'claims')}, that is {alpha * n_claims:.1f} wrong verdicts expected if none had a "
        "difference, fewer as some do: no correction is made across claims, each is its own question. The rates "
        "measured on synthetic per-seed data, and where they exceed the design's (a level where most seeds sit at a "
        "bound of the returns; 10 seeds' BCa intervals): "
        f"{_error_control(results_dir)}."
    )


def _seeds_line(study: StudySpec) -> str:
    """:return: the seeds per variant of the study's page: ``10 seeds per variant`` or its design's looks"""
    if study.design is None:
        return f"{len(study.seeds)} seeds per variant"
    other = "; its other readings the first look's" if len(study.readings) > 1 else ""
    return f"{study.design.describe()}{other}"


def _looks_taken(looked: sequential.SequentialVerdict) -> str:
    """:return: e.g. ``20 seeds per variant, look 2 of 4; ...`` and, undecided at the last look, the seeds needed"""
    text = f"{looked.seeds} seeds per variant, look {looked.looks_taken}"
    if looked.next_seeds:
        text += f"; the next look at {looked.next_seeds}"
    return text + (f"; {looked.needed}" if looked.needed else "")


def _error_control(results_dir: Path) -> str:
    """:return: a link to the measured error rates where they lie beside the outputs (the repository's results), else
    where to find them"""
    if (results_dir / ERROR_CONTROL).exists():
        return f"[{ERROR_CONTROL}]({ERROR_CONTROL})"
    return f"`benchmarks/results/studies/{ERROR_CONTROL}` in sb3_classic's repository"


def _design_notes(results: StudyResults, results_dir: Path) -> list[str]:
    """:return: what the study's sequential design and equivalence margin are, and its seeds recorded, not cached"""
    study, notes = results.study, []
    if study.design is not None:
        notes.append(
            f"- Sequential design: {study.design.describe()}; studentized bootstrap intervals joined with Student's "
            "t-intervals; a claim decided at a look keeps its verdict and draws no more seeds; designed for "
            f"{study.design.alpha:.0%} wrong verdicts per claim where there is no difference, however early it stops "
            f"(the rates measured: {_error_control(results_dir)})."
        )
    margins = sorted({margin for claim in study.claims if (margin := sequential.claim_margin(study, claim)) is not None})
    if margins:
        notes.append(
            f"- Equivalence margin of the `better` claims: ±{', ±'.join(f'{margin:g}' for margin in margins)} (declared "
            "in the study file, or 5% of the env's range of returns): a difference shown within it is *not supported: "
            "alike*."
        )
    if results.recorded:
        notes.append(
            f"- {results.recorded} of the runs are counted from this folder's `{study.name}-seeds.csv` (run before; "
            "the cache no longer holds them): their metrics count in the verdicts and the table; without their "
            "episodes, the figure is the one drawn from the seeds whose episodes were at hand (its legend names how "
            "many)."
        )
    return notes


def _fewest_seeds(results: StudyResults) -> int:
    """:return: the fewest seeds found of a (reading, variant) (a partial run's), or the study's seeds if none is found"""
    return min((len(seeds) for seeds in results.seeds.values()), default=len(results.study.seeds))


def _too_few_seeds(n_seeds: int) -> str | None:
    """:return: "2 seeds" where fewer than ``stats.MIN_SEEDS`` give no interval that holds at 95%, else None"""
    return None if n_seeds >= stats.MIN_SEEDS else f"{n_seeds} seed{'s' * (n_seeds != 1)}"


def _band(n_seeds: int) -> str:
    """:return: what the figure's band over ``n_seeds`` seeds is (``_too_few_seeds``)"""
    few = _too_few_seeds(n_seeds)
    return "95% bootstrap band" if few is None else f"bootstrap band ({few}: too few for a 95% one)"


def _intervals(n_seeds: int) -> str:
    """:return: what the report's intervals over ``n_seeds`` seeds are (``_too_few_seeds``)"""
    method = "bootstrap over seeds (`scipy.stats.bootstrap`, BCa)"
    few = _too_few_seeds(n_seeds)
    if few is None:
        return f"95% {method}"
    return f"{method}, at 95% but from {few}, too few for it to hold: every verdict is too close to call"


def _random_level_notes(results: StudyResults) -> list[str]:
    """:return: the level of a policy that learned nothing, which the claims are checked against"""
    levels = sorted({level.format() for level in results.random_levels.values()})
    if not levels:
        return []
    return [
        f"- A uniformly random policy's return on the env: {' or '.join(levels)} (the mean of {untrained.EPISODES} "
        f"episodes, or of those that end within {untrained.MAX_STEPS:,} env steps, and its 95% interval; with each "
        "variant's `env_kwargs`). A claim none of whose variants rose above it is marked **Not learned**."
    ]


def _empty_run_notes(results: StudyResults) -> list[str]:
    """:return: what runs that completed no episode make of the metrics"""
    empty = results.runs_without_episodes
    if not empty:
        return []
    return [
        f"- **{empty} {plural(empty, 'run', 'runs')} completed no episode** in {results.study.budget.describe()}: "
        "its metrics are NaN (no return to average), and so is every mean over seeds with it: the claims on them are "
        "too close to call. Give a budget of at least a few episodes."
    ]


def _short_budget_notes(study: StudySpec) -> list[str]:
    """:return: what a budget too short for a metric makes of it (a reduced run's, typically)"""
    episodes = study.budget.episodes
    return [] if episodes is None else _short_run_notes(study, episodes, "per run")


def _short_run_notes(study: StudySpec, fewest: int, whose: str) -> list[str]:
    """
    :param study: the study
    :param fewest: the fewest episodes a run has (an episode budget's, or the fewest a seed completed in env steps)
    :param whose: whose episodes those are, for the notes ("per run", "for the seed with the fewest")
    :return: what so few episodes make of the last-100 mean and of episodes to threshold
    """
    notes = []
    if 0 < fewest <= stats.LAST_EPISODES:
        notes.append(
            f"- **{fewest} episodes** {whose}: the mean over the last {stats.LAST_EPISODES} episodes of a seed with at "
            "most that many is the mean over all of them."
        )
    if 0 < fewest < study.threshold_window and has_threshold(study):
        notes.append(
            f"- **{fewest} episodes**, fewer than the threshold's window of {study.threshold_window}, {whose}: a seed "
            "with fewer episodes than the window cannot reach the threshold, and its episodes to threshold is its "
            "episode count (censored)."
        )
    return notes


def _threshold_note(study: StudySpec, censored_at: str) -> str:
    """:return: the study page's line on its threshold (``censored_at``: what a seed that never reaches it counts as)"""
    if not has_threshold(study):
        return (
            "- No threshold: no claim reads one, and episodes to threshold is not measured (give `threshold:`, the "
            "return that counts as solved, to have it)."
        )
    return (
        f"- Threshold: {study.threshold:g}, reached when the mean of {study.threshold_window} consecutive training "
        "episodes reaches it (episodes to threshold: the last episode of the first such window; seeds that never "
        f"reach it count as {censored_at}, a lower bound)."
    )


def _step_budget_notes(results: StudyResults) -> list[str]:
    """:return: what a budget in env steps makes of the table's episodes, the metrics and the figure"""
    study = results.study
    if study.budget.episodes is not None:
        return []
    note = (
        "- **A budget in env steps**: seeds complete different numbers of episodes. The table's Episodes are the "
        "fewest and the most a seed of the variant completed; each seed's metrics are over all of its own episodes; "
        "the figure's curves are over the first episodes, as many as every seed of the variant completed. A run stops "
        "at the end of the update that reaches the budget (SARSA's rollouts take `train_freq` steps of every env, "
        "REINFORCE's update waits for its episodes to end), so it may take a few more steps, and the episodes it "
        "completes are all counted."
    )
    fewest = min((count for seeds in results.episode_counts.values() for count in seeds), default=0)
    return [note, *_short_run_notes(study, fewest, "for the seed with the fewest")]


def _best_readings(claim_texts: Sequence[str], records: Sequence[dict[str, Any]]) -> list[str]:
    """
    :param claim_texts: the study's claims
    :param records: each claim's record under each reading (``write_study``'s json)
    :return: for each claim, the reading that favours it most (``stats.favour``) and those under which it holds, a line
        each
    """
    lines = []
    for text in claim_texts:
        judged = [record for record in records if record["text"] == text]
        best = _most_favourable(judged)
        if best is None:
            continue
        held = [record["reading"] for record in judged if record["verdict"] == stats.SUPPORTED]
        where = ", ".join(f"`{name}`" for name in held) if held else "none"
        lines.append(
            f'Best reading for "{text}": `{best["reading"]}` ({best["verdict"]}; {best["measured"]}). '
            f"Supported under {len(held)} of {len(judged)} readings: {where}."
        )
    return lines


def _most_favourable(records: Sequence[dict[str, Any]]) -> dict[str, Any] | None:
    """:return: of a claim's records under several readings, the one of the largest ``favour``; None if none has one"""
    scored = [record for record in records if not math.isnan(record.get("favour", math.nan))]
    return max(scored, key=lambda record: record["favour"]) if scored else None


def plural(count: int, one: str, many: str) -> str:
    """:return: ``one`` for a count of 1, else ``many``"""
    return one if count == 1 else many


def _claim_rows(
    name: str, source: str, texts: Sequence[str], record: dict[str, Any] | None, command: str
) -> list[tuple[str, str, str, str, str]]:
    rows = []
    for text in texts:
        judged = [claim for claim in (record or {}).get("claims", []) if claim["text"] == text]
        stated = [claim for claim in judged if claim["reading"] == STATED]
        if record is None or not stated:
            rows.append((source or name, text, "–", NOT_RUN, f"`{command}`"))
            continue
        verdict = stated[0]["verdict"]
        measured = stated[0]["measured"]
        others = [claim for claim in judged if claim["reading"] != STATED]
        if len(others) > MAX_LISTED_READINGS:
            measured = measured.rstrip(".") + ". " + _readings_summary(stated[0], others)
        elif others:
            listed = "; ".join(f"{claim['reading']}: {claim['verdict']}" for claim in others)
            measured = measured.rstrip(".") + f". Other readings: {listed}."
        if not record.get("complete", True):
            verdict += f" (partial: {record['missing_runs']} runs missing)"
        if stated[0].get("untrained"):
            verdict += f" ({UNTRAINED_MARK})"
        if record.get("reduced"):
            verdict += " (reduced run)"
        rows.append((f"[{source or name}]({name}.md)", text, measured, verdict, f"`{command}`"))
    return rows


def _readings_summary(stated: dict[str, Any], others: list[dict[str, Any]]) -> str:
    """
    :param stated: a claim's record under the reading as stated (``write_study``'s json)
    :param others: its records under the other readings
    :return: the other readings by verdict, and the one that favours the claim most (``stats.favour``) with its
        measurement, for STUDIES.md's row of the claim
    """
    by_verdict: dict[str, list[str]] = {}
    for claim in others:
        by_verdict.setdefault(claim["verdict"], []).append(claim["reading"])
    parts = [f"{verdict} under {', '.join(names)}" for verdict, names in by_verdict.items()]
    text = f"Other readings ({len(others)}): " + "; ".join(parts) + "."
    best = _most_favourable([stated, *others])
    if best is not None:
        text += f" Best reading: {best['reading']}, {best['measured'].rstrip('.')} ({best['verdict']})."
    return text


def _without_budget(entry: dict[str, Any]) -> dict[str, Any]:
    # n_timesteps is the zoo's required key, set to the run's step cap: the budget is stated above
    return {key: value for key, value in entry.items() if key != "n_timesteps"}
