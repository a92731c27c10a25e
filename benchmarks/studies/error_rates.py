"""
``python -m benchmarks.studies.error_rates``: the rate of wrong verdicts of the studies' sequential design, measured
on simulated studies of synthetic per-seed data where the truth is known (no RL training), beside the naive rule (a
95% interval at every look); and what each design would decide of the seed report's claims and at what cost, with
each variant's recorded seeds as the truth. Writes ``benchmarks/results/studies/error-control.md``.

    python -m benchmarks.studies.error_rates                 # 2,000 studies per case (about 10 minutes on one core)
    python -m benchmarks.studies.error_rates --studies 200   # a quick look (not the committed page)

The per-seed distributions (``DISTRIBUTIONS``) are bounded and skewed like the seed report's returns: a variant whose
seeds mostly stay at CartPole-v1's floor with a few that learn, Acrobot-v1's −500 floor, a Beta, and each variant's
recorded seeds of the seed report resampled as the truth.
"""

import argparse
import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks.common import DEFAULT_RESULTS_DIR
from benchmarks.studies import SEED_REPORT_STUDIES
from sb3_classic.studies import sequential, stats
from sb3_classic.studies.spec import STATED, Claim, load_study

RESULTS = DEFAULT_RESULTS_DIR / "studies"
PAGE = RESULTS / "error-control.md"
#: The design the seed report's study files use, and the designs it is compared with
DESIGNS = {
    "Pocock, looks at 10, 20, 30 (the study files')": sequential.SequentialDesign(10, 10, 30, "pocock"),
    "Pocock, looks at 10, 20, 30, 40": sequential.SequentialDesign(10, 10, 40, "pocock"),
    "O'Brien–Fleming, looks at 10, 20, 30, 40": sequential.SequentialDesign(10, 10, 40, "obrien-fleming"),
    "Pocock, looks at 5, 10, ..., 40": sequential.SequentialDesign(5, 5, 40, "pocock"),
    "Pocock, looks at 10, 20": sequential.SequentialDesign(10, 10, 20, "pocock"),
}
CHOSEN = next(iter(DESIGNS))
#: The intervals compared at the chosen design's looks (``stats.INTERVAL_METHODS``)
INTERVALS = {"bootstrap-t and t (chosen)": "bootstrap-t", "BCa bootstrap": "bootstrap", "Welch's / Student's t": "t"}
MARGIN = 25.0


class Naive(sequential.SequentialDesign):
    """The same looks, each at 95%: the rule a sequential design replaces."""

    @cached_property
    def confidences(self) -> tuple[float, ...]:
        return (stats.CONFIDENCE,) * len(self.looks)

    @property
    def spread_level(self) -> float:
        return 1 - stats.CONFIDENCE


def _floor_and_learners(rng: np.random.Generator, n: int) -> np.ndarray:
    """CartPole-v1 REINFORCE-like: 70% of seeds at the floor (9–30), the rest anywhere up to 500."""
    learned = rng.random(n) < 0.3
    return np.where(learned, rng.uniform(100, 500, n), rng.uniform(9, 30, n))


def _acrobot_floor(rng: np.random.Generator, n: int) -> np.ndarray:
    """Acrobot-v1 REINFORCE-like: half the seeds at −500, the rest spread up to −80."""
    return np.where(rng.random(n) < 0.5, -500.0, rng.uniform(-500, -80, n))


def _solved(rng: np.random.Generator, n: int) -> np.ndarray:
    """A CartPole-v1 variant that mostly solves it: 80% of seeds at 500, the rest anywhere from 100."""
    return np.where(rng.random(n) < 0.8, 500.0, rng.uniform(100, 500, n))


def _failed(rng: np.random.Generator, n: int) -> np.ndarray:
    """An Acrobot-v1 variant that mostly fails: 90% of seeds at −500, the rest anywhere up to −80."""
    return np.where(rng.random(n) < 0.9, -500.0, rng.uniform(-500, -80, n))


def _beta(rng: np.random.Generator, n: int) -> np.ndarray:
    """A right-skewed Beta(2, 5) on [0, 500]."""
    return 500 * rng.beta(2, 5, n)


DISTRIBUTIONS: dict[str, Callable[[np.random.Generator, int], np.ndarray]] = {
    "floor and a few learners (CartPole-v1-like)": _floor_and_learners,
    "half at −500 (Acrobot-v1-like)": _acrobot_floor,
    "Beta(2, 5) × 500": _beta,
    "80% at 500 (solved CartPole-v1-like)": _solved,
    "90% at −500 (failed Acrobot-v1-like)": _failed,
}
#: The distributions of the comparison of intervals
COMPARED = ("floor and a few learners (CartPole-v1-like)", "Beta(2, 5) × 500", "80% at 500 (solved CartPole-v1-like)")
CARTPOLE, ACROBOT = (1.0, 500.0), (-500.0, 0.0)
#: Each distribution's range of values, as a study gives its env's range of returns
BOUNDS = {
    "floor and a few learners (CartPole-v1-like)": CARTPOLE,
    "half at −500 (Acrobot-v1-like)": ACROBOT,
    "Beta(2, 5) × 500": (0.0, 500.0),
    "80% at 500 (solved CartPole-v1-like)": CARTPOLE,
    "90% at −500 (failed Acrobot-v1-like)": ACROBOT,
}


def recorded_distributions() -> dict[str, np.ndarray]:
    """:return: per study of the seed report, its first variant whose recorded seeds differ (as stated, the mean
    return over the last 100 episodes), by name"""
    found = {}
    for path in sorted(RESULTS.glob("fig*-seeds.csv")):
        frame = pd.read_csv(path)
        for variant, rows in frame[frame["reading"] == STATED].groupby("variant"):
            values = rows["last_100_return"].to_numpy(dtype=float)
            if np.ptp(values) > 0:
                found[f"{path.name.removesuffix('-seeds.csv')} {variant}"] = values
                break
    # Every third study's: the recorded rows are a sample of the report's shapes, not a census
    return dict(list(found.items())[::3])


@dataclass(frozen=True)
class Case:
    """A kind of truth: what is simulated and which verdicts are wrong."""

    name: str
    claim: Claim
    shift: float  # added to the other variant's draws (or the level's offset from the mean)
    wrong: Callable[[str], bool]


def _metrics(values: np.ndarray) -> dict[str, np.ndarray]:
    return {"mean_return": values, "reached": np.ones(len(values), dtype=bool)}


def simulate(
    case: Case,
    draw: Callable[[np.random.Generator, int], np.ndarray],
    design: sequential.SequentialDesign,
    n: int,
    seed: int,
    bounds: tuple[float, float] | None = None,
) -> tuple[float, float, float]:
    """:return: the rate of wrong verdicts, of decided ones, and the mean seeds per variant at the stop"""
    rng = np.random.default_rng(seed)
    wrong = decided = 0
    seeds = 0.0
    for _ in range(n):
        a = draw(rng, design.max)
        metrics = {"A": _metrics(a)}
        if case.claim.kind == "better":
            metrics["B"] = _metrics(draw(rng, design.max) + case.shift)
        margin = MARGIN if case.claim.kind == "better" else None
        verdict = sequential.judge_sequentially(case.claim, metrics, design, margin, bounds)
        assert verdict is not None
        wrong += case.wrong(verdict.result.verdict)
        decided += verdict.decided
        seeds += verdict.seeds
    return wrong / n, decided / n, seeds / n


def cases(spread: float, mean: float) -> list[Case]:
    """:return: the truths simulated for a distribution of this spread (sd) and mean"""
    better = Claim("A beats B", "better", "A", ("B",))
    return [
        Case("no difference", better, 0.0, lambda verdict: verdict in (stats.SUPPORTED, stats.REVERSED)),
        Case(
            f"B better by 2 × the margin ({2 * MARGIN:g})",
            better,
            2 * MARGIN,
            lambda verdict: verdict == stats.SUPPORTED or stats.is_alike(verdict),
        ),
        Case(f"B better by exactly the margin ({MARGIN:g})", better, MARGIN, lambda verdict: stats.is_alike(verdict)),
        Case(
            "a level at the mean",
            Claim("A reaches its mean", "reaches", "A", value=mean),
            0.0,
            lambda verdict: verdict in (stats.SUPPORTED, stats.NOT_SUPPORTED),
        ),
        Case(
            "no difference in spread",
            Claim("A's seeds spread less", "better", "A", ("B",), statistic="std"),
            0.0,
            lambda verdict: verdict in (stats.SUPPORTED, stats.REVERSED),
        ),
    ]


def _resampler(values: np.ndarray) -> Callable[[np.random.Generator, int], np.ndarray]:
    """:return: draws of ``values`` with replacement (recorded seeds as the truth)"""

    def draw(rng: np.random.Generator, n: int) -> np.ndarray:
        return rng.choice(values, size=n)

    return draw


def error_table(
    n: int,
    designs: Sequence[tuple[str, sequential.SequentialDesign]],
    recorded: bool = True,
    kinds: Sequence[str] | None = None,
    distributions: Sequence[str] | None = None,
) -> list[str]:
    """
    :param n: simulated studies per row
    :param designs: the designs compared, by name
    :param recorded: whether to add rows of the seed report's recorded seeds as the truth (no difference)
    :param kinds: the cases' names to simulate (default: all)
    :param distributions: the names of ``DISTRIBUTIONS`` to simulate (default: all)
    :return: the markdown rows of wrong-verdict rates, per distribution and case
    """
    lines = [
        "| Distribution | Truth | " + " | ".join(f"{name}: wrong (decided, mean seeds)" for name, _ in designs) + " |",
        "|---|---|" + "---|" * len(designs),
    ]
    worst = {name: 0.0 for name, _ in designs}
    over: dict[str, list[str]] = {}
    truths = {name: draw for name, draw in DISTRIBUTIONS.items() if distributions is None or name in distributions}
    for name, values in recorded_distributions().items() if recorded else ():
        truths[f"recorded: {name}"] = _resampler(values)
    for index, (label, draw) in enumerate(truths.items()):
        sample = draw(np.random.default_rng(12345), 100_000)
        # (a recorded variant's truth: no difference only, its seeds against themselves)
        only_null = label.startswith("recorded")
        for case in cases(float(sample.std()), float(sample.mean())):
            if (only_null and case.name != "no difference") or (kinds is not None and case.name not in kinds):
                continue
            cells = []
            for design_name, design in designs:
                bounds = BOUNDS.get(label, ACROBOT if "acrobot" in label else CARTPOLE)
                wrong, decided, seeds = simulate(case, draw, design, n, seed=index, bounds=bounds)
                worst[design_name] = max(worst[design_name], wrong)
                if design_name == designs[0][0] and wrong > design.alpha + 2 * np.sqrt(design.alpha / n):
                    # (beyond the simulation's noise: two standard errors of a 5% rate)
                    over.setdefault(case.name, []).append(f"{label}: {wrong:.1%}")
                cells.append(f"{wrong:.1%} ({decided:.0%}, {seeds:.1f})")
            lines.append(f"| {label} | {case.name} | " + " | ".join(cells) + " |")
    lines.append("| **worst case** | | " + " | ".join(f"**{worst[name]:.1%}**" for name, _ in designs) + " |")
    if over:
        found = "; ".join(f"{case}: {', '.join(rows)}" for case, rows in over.items())
        lines += [
            "",
            f"Where the first design's rate is above {designs[0][1].alpha:.0%} beyond the simulation's noise: {found}.",
        ]
    return lines


def projection(n: int) -> list[str]:
    """
    :return: the markdown rows of what each design decides of the seed report's claims (as stated) and at what cost,
        each variant's recorded seeds resampled as the truth, its runs' mean CPU seconds as their cost; a setting that
        several studies share (the same settings key) is run once, for the most seeds any of its claims draws
    """
    lines = ["| Design | Claims decided of 42 (mean) | Runs (mean) | CPU hours (mean) |", "|---|---|---|---|"]
    studies = [load_study(path) for path in sorted(SEED_REPORT_STUDIES.glob("*.yml"))]
    truths: dict[str, dict[str, pd.DataFrame]] = {}
    setting: dict[tuple[str, str], str] = {}
    for study in studies:
        frame = pd.read_csv(RESULTS / f"{study.name}-seeds.csv")
        frame = frame[frame["reading"] == STATED]
        truths[study.name] = {str(variant): rows for variant, rows in frame.groupby("variant")}
        for variant, rows in truths[study.name].items():
            # (a setting's identity: its first seed's settings key, seed 0 in every study)
            setting[(study.name, variant)] = str(rows.sort_values("seed")["settings"].iloc[0])
    cost = {
        setting[(name, variant)]: float(rows["cpu_seconds"].mean())
        for name, truth in truths.items()
        for variant, rows in truth.items()
    }
    rows = [("10 seeds each, one look at 95% (the fixed design)", sequential.SequentialDesign(10, 10, 10), True)]
    rows += [(name, design, False) for name, design in DESIGNS.items()]
    rows += [("naive: the study files' looks, 95% at each", Naive(10, 10, 40), False)]
    for name, design, fixed in rows:
        rng = np.random.default_rng(0)
        decided_total = runs_total = hours_total = 0.0
        for _ in range(n):
            seeds = dict.fromkeys(cost, 0)
            for study in studies:
                truth = truths[study.name]
                draws = {variant: rows.sample(design.max, replace=True, random_state=rng) for variant, rows in truth.items()}
                for claim in study.claims:
                    metrics = {
                        variant: {
                            key: draws[variant][key].to_numpy(dtype=bool if key == "reached" else float)
                            for key in (*stats.METRIC_LABELS, "reached")
                        }
                        for variant in (claim.variant, *claim.others)
                    }
                    margin = sequential.claim_margin(study, claim)
                    if fixed:
                        result = stats.judge(claim, metrics, margin=margin)
                        decided_total += stats.is_decided(result.verdict)
                        used = design.max
                    else:
                        verdict = sequential.judge_sequentially(claim, metrics, design, margin, study.return_range())
                        assert verdict is not None
                        decided_total += verdict.decided
                        used = verdict.seeds
                    for variant in (claim.variant, *claim.others):
                        key = setting[(study.name, variant)]
                        seeds[key] = max(seeds[key], used)
            runs_total += sum(seeds.values())
            hours_total += sum(count * cost[key] for key, count in seeds.items()) / 3600
        lines.append(f"| {name} | {decided_total / n:.1f} | {runs_total / n:.0f} | {hours_total / n:.1f} |")
    return lines


def main(argv: Sequence[str] | None = None) -> int:
    """The command line. :return: the exit status"""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.studies.error_rates", description=__doc__)
    parser.add_argument("--studies", type=int, default=2_000, help="simulated studies per case (default 2,000)")
    parser.add_argument("--projections", type=int, default=20, help="resampled seed reports per design (default 20)")
    parser.add_argument("--page", type=Path, default=PAGE, help=f"where to write (default {PAGE})")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    chosen = DESIGNS[CHOSEN]
    designs = [
        (f"chosen ({CHOSEN.split(' (')[0]})", chosen),
        ("naive (95% at each look)", Naive(chosen.start, chosen.step, chosen.max)),
    ]
    errors = error_table(args.studies, designs)
    methods = [(name, dataclasses.replace(chosen, method=method)) for name, method in INTERVALS.items()]
    # The fixed design: one look at 10 seeds, 95% BCa
    methods.append(("fixed design: 10 seeds, 95% BCa", sequential.SequentialDesign(10, 10, 10, method="bootstrap")))
    compared = error_table(
        args.studies, methods, recorded=False, kinds=("no difference", "a level at the mean"), distributions=COMPARED
    )
    projected = projection(args.projections)
    bounds = ", ".join(f"{100 * level:.2f}%" for level in chosen.confidences)
    family = 42 * chosen.alpha
    page = [
        "# Error control of the sequential design",
        "",
        "Produced by:",
        "",
        "```",
        "python -m benchmarks.studies.error_rates"
        + ("" if args.studies == 2_000 else f" --studies {args.studies}")
        + ("" if args.projections == 20 else f" --projections {args.projections}"),
        "```",
        "",
        f"{args.studies:,} simulated studies per row, on synthetic per-seed values where the truth is known (no RL "
        f"training); {math.ceil((time.perf_counter() - start) / 60)} minutes. The chosen design: looks at "
        f"{', '.join(map(str, chosen.looks))} seeds per variant, Pocock boundaries (intervals at {bounds}), studentized "
        "bootstrap intervals joined with Student's (Welch's) t-intervals, equivalence margin "
        f"±{MARGIN:g}; a claim stops at its first decided look. "
        "The naive rule takes the same looks with a 95% interval at each.",
        "",
        "A cell: the rate of wrong verdicts, then the rate of decided claims and the mean seeds per variant at the "
        "stop. Wrong: with no difference (in means, or in spread over seeds), *supported* or *reversed*; with B better "
        "by twice the margin, *supported* or *alike*; with B better by exactly the margin, *alike*; with a level at the "
        "true mean, any verdict. Rows "
        "'recorded' resample one variant of the seed report (as stated, its 10 seeds' last-100-episode returns) as "
        "both variants' truth.",
        "",
        *errors,
        "",
        "## Why the bootstrap-t",
        "",
        "The same looks and boundaries with other intervals over seeds, and the fixed design (one look at 10 seeds, "
        "95% BCa): BCa (`scipy.stats.bootstrap`) is too narrow at these seed counts and levels; Student's t-interval of "
        "one variant's mean misses on the skewed side (Welch's of a difference of two like distributions holds, the "
        "skews cancelling); the bootstrap-t alone misses on the side of a few rare values among many equal ones. The "
        "chosen intervals join the bootstrap-t and Student's (Welch's) t, the wider bound of each side. A claim on the "
        "spread over seeds (`statistic: std`) keeps BCa's interval, whose intervals of a standard deviation are too "
        "narrow at these seed counts, and is decided one way or the other only where a permutation test of equal "
        "spreads (`scipy.stats.permutation_test`) also rejects: at α/K at each of the K looks (Bonferroni's bound, the "
        "test being exact at each look), at 5% at each look in the naive rule.",
        "",
        *compared,
        "",
        "## For 42 claims",
        "",
        f"At ≤ {chosen.alpha:.0%} wrong verdicts per claim where there is no difference, 42 claims where none had a "
        f"difference would expect at most {family:.1f} wrong verdicts; claims whose variants do differ cannot be "
        "wrong by a *difference*, so the expected number among the seed report's 42 is lower. No correction across "
        "claims is made: each claim is its own question, as the report asks it. A verdict of a kind whose rate above "
        "is higher is less sure than the rest.",
        "",
        "## What each design decides of the seed report",
        "",
        f"Each variant's recorded seeds (as stated) resampled as the truth, {args.projections} resampled reports per "
        "design; the runs and CPU hours are of the as-stated reading, each run costing its variant's mean recorded CPU "
        "seconds; a variant draws the seeds of its longest-running claim.",
        "",
        *projected,
        "",
    ]
    args.page.parent.mkdir(parents=True, exist_ok=True)
    args.page.write_text("\n".join(page))
    print(f"wrote {args.page} in {time.perf_counter() - start:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
