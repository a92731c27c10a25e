"""Tables and plots of the learning runs, from the cache: pandas for the numbers, matplotlib for the figures."""

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from sb3_classic.harness.common import LABELS, THRESHOLDS, RunSpec
from sb3_classic.harness.runner import EPISODES_FILE, EVALUATIONS_FILE, RUN_FILE, load_run, load_run_table

RUN_COLUMNS = ["algo", "env_id", "seed"]
#: What the tables use of each run's ``run.json``
SUMMARY_COLUMNS = ["n_envs", "num_timesteps", "n_episodes", "learn_time_s", "steps_per_s"]
COLORS = {"reinforce": "tab:blue", "nstep_sarsa": "tab:orange", "a2c": "tab:green", "ppo": "tab:red", "dqn": "tab:purple"}


@dataclass
class Results:
    """
    The cached data of a set of runs, one row per run, training episode and evaluation episode.

    :param runs: the runs' summaries (``run.json``)
    :param episodes: the training episodes (``episodes.csv``)
    :param evaluations: the evaluation episodes (``evaluations.csv``)
    :param missing: the runs asked for that are not in the cache
    """

    runs: pd.DataFrame
    episodes: pd.DataFrame
    evaluations: pd.DataFrame
    missing: list[RunSpec]


def load_results(specs: Sequence[RunSpec], cache_dir: Path) -> Results:
    """
    :param specs: the runs to report on
    :param cache_dir: the cache root
    :return: their cached data (those not cached are listed in ``missing``)
    """
    runs, episodes, evaluations, missing = [], [], [], []
    for spec in specs:
        run_dir = spec.run_dir(cache_dir)
        if not (run_dir / RUN_FILE).exists():
            missing.append(spec)
            continue
        labels = {"algo": spec.algo, "env_id": spec.env_id, "seed": spec.seed}
        summary = load_run(run_dir)
        runs.append({**labels, **{key: summary[key] for key in SUMMARY_COLUMNS}})
        episodes.append(load_run_table(run_dir, EPISODES_FILE).assign(**labels))
        evaluations.append(load_run_table(run_dir, EVALUATIONS_FILE).assign(**labels))
    return Results(
        runs=pd.DataFrame(runs, columns=[*RUN_COLUMNS, *SUMMARY_COLUMNS]),
        episodes=_stack(episodes),
        evaluations=_stack(evaluations),
        missing=missing,
    )


def _stack(tables: list[pd.DataFrame]) -> pd.DataFrame:
    """
    :param tables: one table of each run (its episodes or its evaluations), labelled with the run
    :return: their rows in one table. A run with no rows (a run whose envs ended no episode in its budget) adds none:
        its table, read from a header-only CSV, has object-typed columns, which would make every column of the
        concatenation object-typed (pandas counts empty tables in the result's dtypes), and the plots fail on them.
        If every table is empty, the first one (for its columns).
    """
    if not tables:
        return pd.DataFrame(columns=RUN_COLUMNS)
    return pd.concat([table for table in tables if len(table)] or tables[:1], ignore_index=True)


def evaluation_means(evaluations: pd.DataFrame) -> pd.DataFrame:
    """:return: one row per evaluation of each run: its ``timesteps`` and mean ``return`` over its episodes"""
    return (
        evaluations.groupby([*RUN_COLUMNS, "eval_index"], as_index=False)
        .agg(timesteps=("timesteps", "first"), mean_return=("return", "mean"))
        .sort_values([*RUN_COLUMNS, "eval_index"], ignore_index=True)
    )


def first_crossing(timesteps: np.ndarray, mean_returns: np.ndarray, threshold: float) -> int | None:
    """
    :param timesteps: the env steps of a run's evaluations, in order
    :param mean_returns: their mean returns
    :param threshold: the return to reach
    :return: the env steps of the first evaluation whose mean return reaches ``threshold``, None if none does
    """
    reached = np.flatnonzero(np.asarray(mean_returns) >= threshold)
    return int(np.asarray(timesteps)[reached[0]]) if len(reached) else None


def episodes_by(end_steps: np.ndarray, step: int) -> int:
    """
    :param end_steps: the env steps at which a run's training episodes ended
    :param step: an env step of the run
    :return: how many training episodes had ended by then
    """
    return int((np.asarray(end_steps) <= step).sum())


def stayed_counts(mean_returns: np.ndarray, threshold: float) -> tuple[int, int] | None:
    """
    :param mean_returns: a run's evaluation mean returns, in order
    :param threshold: the return to reach
    :return: of the evaluations after the first one that reaches ``threshold``, how many are still ≥ ``threshold``
        and how many there are; None if the run never reaches it
    """
    reached = np.flatnonzero(np.asarray(mean_returns) >= threshold)
    if not len(reached):
        return None
    later = np.asarray(mean_returns)[reached[0] + 1 :]
    return int((later >= threshold).sum()), len(later)


def stability(mean_returns_by_run: dict[Any, np.ndarray], threshold: float) -> dict[str, Any]:
    """
    How well the runs of one algorithm stay at the threshold once they reach it.

    :param mean_returns_by_run: per run (seed), its evaluation mean returns in order
    :param threshold: the return to reach
    :return: ``runs``; ``reached`` (runs with an evaluation ≥ threshold); ``final_at`` (runs whose final evaluation is
        ≥ threshold); ``stayed_pooled`` (of all the evaluations after each run's first reaching one, pooled over runs,
        the fraction ≥ threshold; NaN if there are none); ``stayed_median`` and ``stayed_min`` (the same fraction per
        run, median and minimum over the runs that have later evaluations)
    """
    kept, later, fractions = 0, 0, []
    for mean_returns in mean_returns_by_run.values():
        counts = stayed_counts(mean_returns, threshold)
        if counts is None or counts[1] == 0:
            continue
        kept, later = kept + counts[0], later + counts[1]
        fractions.append(counts[0] / counts[1])
    finals = [np.asarray(mean_returns)[-1] for mean_returns in mean_returns_by_run.values() if len(mean_returns)]
    return {
        "runs": len(mean_returns_by_run),
        "reached": sum(stayed_counts(r, threshold) is not None for r in mean_returns_by_run.values()),
        "final_at": int(sum(final >= threshold for final in finals)),
        "stayed_pooled": kept / later if later else float("nan"),
        "stayed_median": float(np.median(fractions)) if fractions else float("nan"),
        "stayed_min": float(np.min(fractions)) if fractions else float("nan"),
    }


def _stayed(stab: dict[str, Any]) -> str:
    if np.isnan(stab["stayed_pooled"]):
        return "–"
    return f"{stab['stayed_pooled']:.0%} (worst seed {stab['stayed_min']:.0%})"


def threshold_crossings(results: Results) -> pd.DataFrame:
    """
    :return: per run, ``steps_to_threshold`` (the env steps of its first evaluation whose mean return reaches the
        env's threshold) and ``episodes_to_threshold`` (the training episodes ended by then); NaN if it never did
    """
    means = evaluation_means(results.evaluations)
    rows = []
    for (algo, env_id, seed), run in means.groupby(RUN_COLUMNS, sort=True):
        step = first_crossing(run["timesteps"].to_numpy(), run["mean_return"].to_numpy(), THRESHOLDS[str(env_id)])
        episodes = results.episodes
        end_steps = episodes.loc[
            (episodes["algo"] == algo) & (episodes["env_id"] == env_id) & (episodes["seed"] == seed), "end_step"
        ].to_numpy()
        rows.append(
            {
                "algo": algo,
                "env_id": env_id,
                "seed": seed,
                "final_return": run["mean_return"].iloc[-1],
                "steps_to_threshold": np.nan if step is None else step,
                "episodes_to_threshold": np.nan if step is None else episodes_by(end_steps, step),
            }
        )
    return pd.DataFrame(rows, columns=[*RUN_COLUMNS, "final_return", "steps_to_threshold", "episodes_to_threshold"])


def _mean_std(values: pd.Series, digits: int = 1) -> str:
    if len(values) == 0:
        return "–"
    std = values.std() if len(values) > 1 else 0.0
    return f"{values.mean():,.{digits}f} ± {std:,.{digits}f}"


def _median_range(values: pd.Series) -> str:
    values = values.dropna()
    if len(values) == 0:
        return "–"
    return f"{values.median():,.0f} ({values.min():,.0f}–{values.max():,.0f})"


def summary_table(results: Results, crossings: pd.DataFrame, env_id: str, algos: Sequence[str]) -> pd.DataFrame:
    """
    The table of one env, one row per algorithm.

    :param results: the cached data
    :param crossings: ``threshold_crossings(results)``
    :param env_id: the env
    :param algos: the algorithms, in the table's order
    :return: the table, as strings
    """
    threshold = THRESHOLDS[env_id]
    means = evaluation_means(results.evaluations)
    rows = []
    for algo in algos:
        runs = results.runs[(results.runs["algo"] == algo) & (results.runs["env_id"] == env_id)]
        crossed = crossings[(crossings["algo"] == algo) & (crossings["env_id"] == env_id)]
        if runs.empty:
            continue
        algo_means = means[(means["algo"] == algo) & (means["env_id"] == env_id)]
        stab = stability(
            {seed: run["mean_return"].to_numpy() for seed, run in algo_means.groupby("seed", sort=True)}, threshold
        )
        rows.append(
            {
                "Algorithm": LABELS[algo],
                "Seeds": len(runs),
                "n_envs": ", ".join(map(str, sorted(runs["n_envs"].unique()))),
                "Final eval return": _mean_std(crossed["final_return"]),
                f"Seeds reaching {threshold:g}": f"{crossed['steps_to_threshold'].notna().sum()}/{len(runs)}",
                f"Final ≥ {threshold:g}": f"{stab['final_at']}/{len(runs)}",
                "Stayed": _stayed(stab),
                "Env steps to threshold": _median_range(crossed["steps_to_threshold"]),
                "Episodes to threshold": _median_range(crossed["episodes_to_threshold"]),
                "Training episodes": _median_range(runs["n_episodes"]),
                "Learn time (s)": _mean_std(runs["learn_time_s"], digits=0),
                "Env steps/s": _mean_std(runs["steps_per_s"], digits=0),
            }
        )
    return pd.DataFrame(rows)


def markdown_table(frame: pd.DataFrame) -> str:
    """:return: ``frame`` as a GitHub markdown table (what ``DataFrame.to_markdown`` does, without tabulate)"""
    lines = ["| " + " | ".join(map(str, frame.columns)) + " |", "|" + "---|" * len(frame.columns)]
    lines += ["| " + " | ".join(map(str, row)) + " |" for row in frame.itertuples(index=False)]
    return "\n".join(lines)


def _band(axes: Axes, x: np.ndarray, mean: np.ndarray, std: np.ndarray, algo: str, label: str) -> None:
    axes.plot(x, mean, color=COLORS[algo], label=label, linewidth=1.0)
    axes.fill_between(x, mean - std, mean + std, color=COLORS[algo], alpha=0.2, linewidth=0)


def episode_curves(results: Results, env_id: str, algos: Sequence[str]) -> dict[str, pd.DataFrame]:
    """
    The training return of each episode, mean and std over seeds, for the episodes every seed of every algorithm
    completed (so that the algorithms are compared on the same episodes, as in the seed report).

    :param results: the cached data
    :param env_id: the env
    :param algos: the algorithms
    :return: per algorithm with runs on ``env_id``: ``mean``, ``std`` and ``count`` (seeds) indexed by ``episode``
    """
    curves = {}
    for algo in algos:
        episodes = results.episodes[(results.episodes["algo"] == algo) & (results.episodes["env_id"] == env_id)]
        if episodes.empty:
            continue
        curve = episodes.groupby("episode")["return"].agg(["mean", "std", "count"])
        curves[algo] = curve[curve["count"] == episodes["seed"].nunique()].fillna({"std": 0.0})
    common = min((len(curve) for curve in curves.values()), default=0)
    return {algo: curve.iloc[:common] for algo, curve in curves.items()}


def plot_episode_curves(results: Results, env_id: str, algos: Sequence[str], path: Path) -> None:
    """
    The seed report's figure: the training return of each episode, mean ± std over seeds (``episode_curves``).

    :param results: the cached data
    :param env_id: the env
    :param algos: the algorithms to draw
    :param path: the PNG to write
    """
    figure = Figure(figsize=(8, 4.5), layout="constrained")
    axes = figure.add_subplot()
    curves = episode_curves(results, env_id, algos)
    for algo, curve in curves.items():
        n_seeds = int(curve["count"].max()) if len(curve) else 0
        mean, std = curve["mean"].to_numpy(), curve["std"].to_numpy()
        _band(axes, curve.index.to_numpy(), mean, std, algo, f"{LABELS[algo]} ({n_seeds} seeds)")
    axes.axhline(THRESHOLDS[env_id], color="gray", linestyle="--", linewidth=0.8, label=f"threshold {THRESHOLDS[env_id]:g}")
    n_episodes = min((len(curve) for curve in curves.values()), default=0)
    axes.set(
        xlabel="episode",
        ylabel="training return (mean ± std over seeds)",
        title=f"{env_id}: return per training episode (the first {n_episodes}, completed by every run)",
    )
    axes.legend(loc="best")
    axes.grid(alpha=0.3)
    figure.savefig(path, dpi=120)


def plot_evaluation_curves(results: Results, env_id: str, algos: Sequence[str], path: Path) -> None:
    """
    The deterministic evaluation return against env steps, mean ± std over seeds, all algorithms on one axis.

    :param results: the cached data
    :param env_id: the env
    :param algos: the algorithms to draw
    :param path: the PNG to write
    """
    figure = Figure(figsize=(8, 4.5), layout="constrained")
    axes = figure.add_subplot()
    means = evaluation_means(results.evaluations)
    for algo in algos:
        runs = means[(means["algo"] == algo) & (means["env_id"] == env_id)]
        if runs.empty:
            continue
        n_seeds = runs["seed"].nunique()
        curve = runs.groupby("eval_index").agg(
            timesteps=("timesteps", "mean"), mean=("mean_return", "mean"), std=("mean_return", "std"), count=("seed", "count")
        )
        curve = curve[curve["count"] == n_seeds].fillna({"std": 0.0})
        _band(
            axes,
            curve["timesteps"].to_numpy(),
            curve["mean"].to_numpy(),
            curve["std"].to_numpy(),
            algo,
            f"{LABELS[algo]} ({n_seeds} seeds)",
        )
    axes.axhline(THRESHOLDS[env_id], color="gray", linestyle="--", linewidth=0.8, label=f"threshold {THRESHOLDS[env_id]:g}")
    axes.set(
        xlabel="env steps",
        ylabel="evaluation return (mean ± std over seeds)",
        title=f"{env_id}: deterministic evaluation return",
    )
    axes.legend(loc="best")
    axes.grid(alpha=0.3)
    figure.savefig(path, dpi=120)


def write_learning_report(
    results: Results, env_ids: Sequence[str], algos: Sequence[str], header: str, results_dir: Path, footer: str = ""
) -> Path:
    """
    Write ``learning.md`` (the command and settings, then a table and two plots per env), the plots
    (``<env>-episodes.png``: our algorithms per training episode; ``<env>-steps.png``: all algorithms against env
    steps) and ``learning-runs.csv`` (one row per run).

    :param results: the cached data
    :param env_ids: the envs
    :param algos: the algorithms
    :param header: the markdown above the tables (the command that made them, and its settings)
    :param footer: the markdown below them
    :param results_dir: where to write
    :return: the markdown file
    """
    results_dir.mkdir(parents=True, exist_ok=True)
    crossings = threshold_crossings(results)
    sections = [header]
    if results.missing:
        sections.append(f"**Incomplete: {len(results.missing)} runs missing** ({', '.join(s.name for s in results.missing)}).")
    for env_id in env_ids:
        table = summary_table(results, crossings, env_id, algos)
        episodes_png, steps_png = f"{env_id}-episodes.png", f"{env_id}-steps.png"
        plot_episode_curves(
            results, env_id, [algo for algo in algos if algo in ("reinforce", "nstep_sarsa")], results_dir / episodes_png
        )
        plot_evaluation_curves(results, env_id, algos, results_dir / steps_png)
        sections.append(
            f"## {env_id} (threshold {THRESHOLDS[env_id]:g})\n\n{markdown_table(table)}\n\n"
            f"![{env_id}: training return per episode]({episodes_png})\n"
            f"![{env_id}: evaluation return against env steps]({steps_png})"
        )
    per_run = results.runs.merge(crossings, on=RUN_COLUMNS, how="left")
    per_run.to_csv(results_dir / "learning-runs.csv", index=False, float_format="%.6g")
    path = results_dir / "learning.md"
    path.write_text("\n\n".join([*sections, footer]).rstrip() + "\n")
    return path
