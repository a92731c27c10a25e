"""
The statistics of a study: per-seed metrics of the training returns, 95% bootstrap confidence intervals over seeds
(``scipy.stats.bootstrap``), and the verdict of each claim decided by the intervals.

The rule (also in ``STUDIES.md``):

- ``better`` (A beats B on a metric): the 95% interval of the difference A − B, bootstrapped over seeds (each
  variant's seeds resampled independently), oriented so that positive means A is better. *supported* if it lies
  above 0, *reversed* if below 0, *too close to call* if it contains 0. A claim against several variants is
  supported if every comparison is, reversed if every one is reversed, *not supported* if some are reversed and
  some not, too close to call otherwise.
- ``similar`` (A and B alike): *supported* if the interval of A − B lies within ± the claim's margin, *not
  supported* if it excludes 0, too close to call otherwise (it contains 0 but is wider than the margin).
- ``reaches`` (A's statistic is at least a level): the interval of A's statistic; *supported* if it lies at or above
  the level, *not supported* if it lies below it, too close to call otherwise. ``below`` (A's statistic is below the
  level) is the opposite claim. Both compare on the metric's own scale, whichever way is better: "the spread is
  below 20", "episodes to threshold below 200".

- With an equivalence margin m (``judge``'s ``margin``: the study's, ``sequential.claim_margin``), a ``better``
  comparison whose interval lies within ± m is decided: *not supported: alike within ±m*.
- Any claim whose variants have fewer than ``MIN_SEEDS`` seeds is *too close to call*, whatever its intervals: a
  bootstrap over 2–4 values gives an interval, but not a 95% one.
- Episodes to threshold is censored: a seed that never reaches the threshold counts as its episode budget, a lower
  bound of its own value. Comparisons between variants are then of the means within the budget (restricted means),
  which the budget bounds alike. A verdict that censoring could overturn is *too close to call* (``censored_verdict``):
  a mean shown below a level, two variants shown alike, any comparison where no seed of either variant reached the
  threshold, and the spread over seeds.

Statistics over seeds: ``mean`` (the mean over seeds) or ``std`` (their sample standard deviation: a claim of
consistent learning across seeds, where lower is better).

Intervals (``INTERVAL_METHODS``): ``bootstrap``, BCa over seeds at 95%, the fixed design's; ``bootstrap-t``, the
studentized bootstrap of a mean or a difference of means (Efron & Tibshirani 1993, *An Introduction to the Bootstrap*,
§12.5: the quantiles of (mean* − mean) / se* over resamples, se with Welch's standard error), the sequential design's at
each look's level, joined with Student's t-interval (``_studentized``). At 5–40 seeds of skewed, bounded returns,
BCa's intervals are too narrow at the higher levels a sequential design's looks need, Student's t-interval of one
variant's mean misses on the skewed side, and the bootstrap-t alone on the side of a few rare values among many equal
ones (``benchmarks/results/studies/error-control.md``). Written here by hand: SciPy's
``bootstrap`` has no studentized method. ``t``: Student's interval of a mean and Welch's of a difference
(``scipy.stats.ttest_1samp``, ``ttest_ind``), for comparison.

A spread (``std``) keeps BCa for its interval, but a ``better`` claim on it is decided one way or the other only where
a permutation test of the two spreads (``spread_p_value``) also rejects their equality: at 5% in the fixed design, at
5%/K at each of a sequential design's K looks (exact at each, so Bonferroni's bound holds over the looks). BCa
intervals of a standard deviation from 10–30 seeds of bounded, lumpy returns are far too narrow (9–17% wrong verdicts
with equal spreads), while permuting seeds between variants is exact where their distributions are alike.
"""

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats

from sb3_classic.studies.spec import Claim

CONFIDENCE = 0.95
N_RESAMPLES = 10_000
#: How an interval over seeds is computed (the module's docstring)
INTERVAL_METHODS = ("bootstrap", "bootstrap-t", "t")
#: Episodes of the "last episodes" metric
LAST_EPISODES = 100
SUPPORTED = "supported"
NOT_SUPPORTED = "not supported"
REVERSED = "reversed"
TOO_CLOSE = "too close to call"
#: The metrics that are returns (whose bounds are the env's range of returns)
RETURN_METRICS = ("mean_return", "last_100_return")
#: A ``better`` comparison whose interval lies within ± the margin (``alike``)
ALIKE = "alike within"
#: Fewer seeds than this in a variant of a claim: no verdict but too close to call (the report ran 5, the studies 10)
MIN_SEEDS = 5
METRIC_LABELS = {
    "mean_return": "mean return (all episodes)",
    "last_100_return": f"mean return (last {LAST_EPISODES} episodes)",
    "episodes_to_threshold": "episodes to threshold",
}


@dataclass(frozen=True)
class Interval:
    """An estimate and its confidence interval (NaN bounds with fewer than two seeds)."""

    estimate: float
    low: float
    high: float

    def format(self, digits: int = 1) -> str:
        """:return: e.g. ``412.3 [398.0, 425.1]``"""
        if np.isnan(self.low):
            return f"{self.estimate:.{digits}f}"
        return f"{self.estimate:.{digits}f} [{self.low:.{digits}f}, {self.high:.{digits}f}]"


def seed_returns(episodes: Sequence[pd.DataFrame], n_episodes: int | None = None) -> list[np.ndarray]:
    """
    :param episodes: per seed, its ``episodes.csv`` (one row per training episode, in end order)
    :param n_episodes: the episode budget: each seed's first ``n_episodes``; None (a budget in env steps): all of
        each seed's episodes, as many as it completed
    :return: per seed, the training return of each of its episodes
    :raise ValueError: if a seed has fewer than ``n_episodes``
    """
    returns = [frame["return"].to_numpy(dtype=float) for frame in episodes]
    if n_episodes is None:
        return returns
    if min(len(row) for row in returns) < n_episodes:
        raise ValueError(f"a seed has only {min(map(len, returns))} episodes, fewer than the {n_episodes} asked for")
    return [row[:n_episodes] for row in returns]


def returns_matrix(returns: Sequence[np.ndarray]) -> np.ndarray:
    """
    :param returns: per seed, its episodes' returns (``seed_returns``)
    :return: seeds × episodes, the episodes every seed has (the figure's: with a budget in env steps, seeds complete
        different numbers of episodes)
    """
    n = min(len(row) for row in returns)
    return np.stack([row[:n] for row in returns])


def moving_average(returns: np.ndarray, window: int) -> np.ndarray:
    """
    :param returns: ... × episodes
    :param window: episodes
    :return: the trailing mean over the last ``window`` episodes (fewer at the start), same shape
    """
    if window <= 1:
        return returns
    cumulative = np.cumsum(returns, axis=-1)
    shifted = np.concatenate([np.zeros_like(cumulative[..., :window]), cumulative[..., :-window]], axis=-1)
    counts = np.minimum(np.arange(1, returns.shape[-1] + 1), window)
    return (cumulative - shifted) / counts


def episodes_to_threshold(returns: np.ndarray, threshold: float, window: int) -> tuple[np.ndarray, np.ndarray]:
    """
    :param returns: seeds × episodes
    :param threshold: the return that counts as solved
    :param window: the mean of this many consecutive episodes must reach it (Gymnasium's "solved": 100)
    :return: per seed, the episode (1-based) that completes the first such window, or the episode count if none
        does (a lower bound: censored), and whether it did
    """
    n = returns.shape[1]
    if n < window:
        return np.full(returns.shape[0], float(n)), np.zeros(returns.shape[0], dtype=bool)
    windows = moving_average(returns, window)[:, window - 1 :]
    hit = windows >= threshold
    reached = hit.any(axis=1)
    first = np.where(reached, hit.argmax(axis=1) + window, n)
    return first.astype(float), np.asarray(reached, dtype=bool)


def seed_metrics(returns: Sequence[np.ndarray] | np.ndarray, threshold: float, window: int) -> dict[str, np.ndarray]:
    """
    :param returns: per seed, the return of each of its episodes (seeds × episodes, or one array per seed of its
        own length: with a budget in env steps, each seed's metrics are over the episodes it completed, and a seed
        that never reaches the threshold is censored at its own episode count)
    :param threshold: see ``episodes_to_threshold``
    :param window: see ``episodes_to_threshold``
    :return: per metric of ``METRIC_LABELS``, its value for each seed; and ``reached`` (bool per seed)
    """
    rows = [np.asarray(row, dtype=float) for row in returns]
    to_threshold = [episodes_to_threshold(row[None], threshold, window) for row in rows]
    # A seed with no episode (a budget in env steps shorter than one) has no return to average: NaN, without NumPy's
    # "Mean of empty slice" warning
    return {
        "mean_return": np.array([row.mean() if len(row) else np.nan for row in rows]),
        "last_100_return": np.array([row[-LAST_EPISODES:].mean() if len(row) else np.nan for row in rows]),
        "episodes_to_threshold": np.concatenate([first for first, _ in to_threshold]),
        "reached": np.concatenate([reached for _, reached in to_threshold]),
    }


def _statistic(name: str) -> Callable[..., Any]:
    if name == "mean":
        return np.mean
    if name == "std":
        return lambda values, axis=-1: np.std(values, axis=axis, ddof=1)
    raise ValueError(f"statistic={name!r}: choose 'mean' or 'std'")


def interval(
    values: np.ndarray,
    statistic: str = "mean",
    seed: int = 0,
    confidence: float = CONFIDENCE,
    method: str = "bootstrap",
    bounds: tuple[float, float] | None = None,
) -> Interval:
    """
    :param values: one value per seed
    :param statistic: ``mean`` or ``std``
    :param seed: of the resampling
    :param confidence: the interval's level
    :param method: ``bootstrap`` (BCa; percentile where BCa is undefined), ``bootstrap-t`` (studentized, of a mean; a
        ``std`` keeps BCa) or ``t`` (Student's)
    :param bounds: the lowest and highest value a seed can have (an env's range of returns), for ``bootstrap-t``'s
        interval of seeds that all have one value (``point_mass``); None: that value alone
    :return: the statistic and its interval
    """
    values = np.asarray(values, dtype=float)
    function = _statistic(statistic)
    with np.errstate(invalid="ignore", divide="ignore"):
        estimate = float(function(values, axis=-1)) if len(values) else float("nan")
    if len(values) < (3 if statistic == "std" else 2) or np.isnan(values).any():
        # (NaN: a seed that completed no episode, which has no return)
        return Interval(estimate, float("nan"), float("nan"))
    if np.ptp(values) == 0:
        if method == "bootstrap-t" and statistic == "mean" and bounds is not None:
            return Interval(estimate, *point_mass(estimate, len(values), confidence, bounds))
        return Interval(estimate, estimate, estimate)
    if method == "bootstrap-t" and statistic == "mean":
        return _studentized((values,), confidence, seed)
    if method == "t" and statistic == "mean":
        student = stats.ttest_1samp(values, 0.0).confidence_interval(confidence)
        return Interval(estimate, float(student.low), float(student.high))
    return _bootstrap((values,), lambda x, axis=-1: function(x, axis=axis), estimate, seed, confidence)


def difference_interval(
    a: np.ndarray,
    b: np.ndarray,
    statistic: str = "mean",
    seed: int = 0,
    confidence: float = CONFIDENCE,
    method: str = "bootstrap",
    bounds: tuple[float, float] | None = None,
) -> Interval:
    """
    :param a: one value per seed of a variant
    :param b: the same of another (not paired: seeds are independent runs)
    :param statistic: ``mean`` or ``std``
    :param seed: of the resampling
    :param confidence: the interval's level
    :param method: ``bootstrap`` (BCa), ``bootstrap-t`` (studentized, of a difference of means; a ``std`` keeps BCa) or
        ``t`` (Welch's)
    :param bounds: as ``interval``'s, for two variants whose seeds each have one value
    :return: statistic(a) − statistic(b) and its interval
    """
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    function = _statistic(statistic)
    with np.errstate(invalid="ignore", divide="ignore"):
        estimate = float(function(a, axis=-1) - function(b, axis=-1)) if len(a) and len(b) else float("nan")
    if min(len(a), len(b)) < (3 if statistic == "std" else 2) or np.isnan(a).any() or np.isnan(b).any():
        return Interval(estimate, float("nan"), float("nan"))
    if np.ptp(a) == 0 and np.ptp(b) == 0:
        if method == "bootstrap-t" and statistic == "mean" and bounds is not None:
            # Each variant's interval at half the miss rate, so that the difference's holds at its level
            level = 1 - (1 - confidence) / 2
            low_a, high_a = point_mass(float(a[0]), len(a), level, bounds)
            low_b, high_b = point_mass(float(b[0]), len(b), level, bounds)
            return Interval(estimate, low_a - high_b, high_a - low_b)
        return Interval(estimate, estimate, estimate)
    if method == "bootstrap-t" and statistic == "mean":
        return _studentized((a, b), confidence, seed)
    if method == "t" and statistic == "mean":
        welch = stats.ttest_ind(a, b, equal_var=False).confidence_interval(confidence)
        return Interval(estimate, float(welch.low), float(welch.high))
    difference = lambda x, y, axis=-1: function(x, axis=axis) - function(y, axis=axis)  # noqa: E731
    return _bootstrap((a, b), difference, estimate, seed, confidence)


def spread_p_value(a: np.ndarray, b: np.ndarray, seed: int = 0, n_resamples: int = N_RESAMPLES) -> float:
    """
    The two-sided permutation test of equal spreads over seeds (``scipy.stats.permutation_test``): the statistic the
    difference of the variants' sample standard deviations, the seeds shuffled between variants (``n_resamples``
    permutations, or all where fewer). Exact where the two variants' seeds are alike in distribution (its rate of
    rejections at most the level), and conservative where they differ in location alone: shuffled seeds then mix
    two locations, which widens the spreads the observed one is compared with. (Centring each variant at its median,
    Brown & Forsythe's way, would test a shift too but is no longer exact at 10–30 seeds of lumpy returns.)

    :param a: one value per seed of a variant (at least 2)
    :param b: the same of another
    :param seed: of the permutations
    :param n_resamples: how many
    :return: the p-value of equal spreads
    """
    spread = _statistic("std")
    result = stats.permutation_test(
        (np.asarray(a, dtype=float), np.asarray(b, dtype=float)),
        lambda x, y, axis=-1: spread(x, axis=axis) - spread(y, axis=axis),
        permutation_type="independent",
        vectorized=True,
        n_resamples=n_resamples,
        alternative="two-sided",
        rng=np.random.default_rng(seed),
    )
    return float(result.pvalue)


def point_mass(value: float, n: int, confidence: float, bounds: tuple[float, float]) -> tuple[float, float]:
    """
    The interval of a mean from ``n`` seeds that all have one value, where each seed's value lies within ``bounds``:
    n seeds at a value do not show that every seed lands there. The share p of seeds elsewhere is at most
    1 − (tail)^(1/n) at one-sided level 1 − tail (Clopper–Pearson's bound at 0 successes; about 3/n at 95%, the
    "rule of three"), and those seeds are at most at a bound: the mean lies within value ± p · (distance to the bound).

    :return: the interval's bounds
    """
    tail = (1 - confidence) / 2
    share = 1 - tail ** (1 / n)
    low, high = bounds
    return value - share * max(value - low, 0.0), value + share * max(high - value, 0.0)


def _studentized(data: tuple[np.ndarray, ...], confidence: float, seed: int) -> Interval:
    """
    The studentized bootstrap (bootstrap-t) interval of a mean, or of the difference of two means (each variant's seeds
    resampled apart): estimate − q_{1−a} · se to estimate − q_a · se, where q are the quantiles of t* = (estimate* −
    estimate) / se* over ``N_RESAMPLES`` resamples and se is Welch's standard error (√(Σ s_i² / n_i)); joined with
    Student's (Welch's) t-interval, the wider bound of the two on each side.

    Why both: many seeds at one return (a solved CartPole-v1 at 500, a failed Acrobot-v1 at −500) make resamples of
    constant values, whose se* is 0 (floored here at the smallest positive se* of the resamples, not to divide by 0),
    and the bootstrap-t then undercovers the side of the rare values, where the t-interval holds; on skewed returns it
    is the other way. An interval that contains both misses only where both miss.
    """
    rng = np.random.default_rng(seed)
    signs = (1.0, -1.0)[: len(data)]
    estimate = float(sum(sign * values.mean() for sign, values in zip(signs, data, strict=False)))
    se = float(np.sqrt(sum(values.var(ddof=1) / len(values) for values in data)))
    resampled = [values[rng.integers(0, len(values), (N_RESAMPLES, len(values)))] for values in data]
    estimates = sum(sign * sample.mean(axis=1) for sign, sample in zip(signs, resampled, strict=False))
    errors = np.sqrt(sum(sample.var(axis=1, ddof=1) / sample.shape[1] for sample in resampled))
    positive = errors[errors > 0]
    t = (estimates - estimate) / np.maximum(errors, positive.min() if len(positive) else se)
    tail = (1 - confidence) / 2
    low_t, high_t = np.quantile(t, [1 - tail, tail], method="inverted_cdf")
    if len(data) == 1:
        student = stats.ttest_1samp(data[0], 0.0).confidence_interval(confidence)
    else:
        student = stats.ttest_ind(data[0], data[1], equal_var=False).confidence_interval(confidence)
    low, high = min(estimate - low_t * se, float(student.low)), max(estimate - high_t * se, float(student.high))
    return Interval(estimate, float(low), float(high))


def _bootstrap(
    data: tuple[np.ndarray, ...], statistic: Callable[..., np.ndarray], estimate: float, seed: int, confidence: float
) -> Interval:
    for method in ("BCa", "percentile"):
        with np.errstate(invalid="ignore", divide="ignore"):
            result = stats.bootstrap(
                data,
                statistic,
                n_resamples=N_RESAMPLES,
                confidence_level=confidence,
                method=method,
                vectorized=True,
                paired=False,
                rng=np.random.default_rng(seed),
            )
        low, high = float(result.confidence_interval.low), float(result.confidence_interval.high)
        if np.isfinite(low) and np.isfinite(high):
            return Interval(estimate, low, high)
    return Interval(estimate, float("nan"), float("nan"))


def episode_band(returns: np.ndarray, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    :param returns: seeds × episodes
    :param seed: of the resampling
    :return: per episode, the mean over seeds and its 95% bootstrap interval (percentile, 2,000 resamples)
    """
    mean = returns.mean(axis=0)
    if returns.shape[0] < 2:
        return mean, mean, mean
    result = stats.bootstrap(
        (returns,),
        np.mean,
        n_resamples=2_000,
        confidence_level=CONFIDENCE,
        method="percentile",
        vectorized=True,
        axis=0,
        rng=np.random.default_rng(seed),
    )
    return mean, np.asarray(result.confidence_interval.low), np.asarray(result.confidence_interval.high)


@dataclass(frozen=True)
class Comparison:
    """One comparison of a claim: ``variant`` against ``other`` (or against the level, ``other`` None)."""

    other: str | None
    interval: Interval
    verdict: str


@dataclass(frozen=True)
class ClaimResult:
    """A claim's verdict, its comparisons, and what was measured, in words."""

    claim: Claim
    verdict: str
    comparisons: tuple[Comparison, ...]
    measured: str
    #: Said beside the verdict where no compared variant rose above a random policy's return (``untrained_note``)
    untrained: str = ""


def untrained_note(claim: Claim, metrics: Mapping[str, Mapping[str, np.ndarray]], levels: Mapping[str, Interval]) -> str:
    """
    Whether a claim compares runs that did not measurably learn: none of its variants has a mean return over its last
    ``LAST_EPISODES`` episodes whose interval over seeds lies above the interval of a uniformly random policy's return
    on its env (``untrained.random_returns``; with fewer than two seeds, or a single random episode, the estimates). A
    variant below that level has not learned either (it settled on a policy worse than chance).

    :param claim: the claim
    :param metrics: per variant, its ``seed_metrics``
    :param levels: per variant, the random policy's mean return on its env and its interval over episodes (a
        variant without one: the note is not given)
    :return: the note to give beside the verdict, or '' if some variant rose above the level (or a level is unknown)
    """
    variants = (claim.variant, *claim.others)
    if any(variant not in levels for variant in variants):
        return ""
    for variant in variants:
        ours, level = interval(metrics[variant]["last_100_return"]), levels[variant]
        low = ours.low if np.isfinite(ours.low) else ours.estimate
        high = level.high if np.isfinite(level.high) else level.estimate
        if low > high:
            return ""
    shown = " or ".join(sorted({levels[variant].format() for variant in variants}))
    last = f"its last {LAST_EPISODES} episodes (all, in a shorter run)"
    if len(variants) == 1:
        what = f"{claim.variant}'s mean return over {last} is not"
    else:
        what = f"none of the {len(variants)} compared variants has a mean return over {last}"
    return f"{what} above a uniformly random policy's ({shown}): the verdict compares runs that did not measurably learn"


def higher_is_better(claim: Claim) -> bool:
    """:return: whether a larger value of the claim's statistic of its metric is better"""
    return claim.statistic == "mean" and claim.metric != "episodes_to_threshold"


def favour(result: ClaimResult) -> float:
    """
    :param result: a claim's verdict under one reading
    :return: how far its measurement goes the claim's way, in the metric's units (the larger, the more the reading
        favours the claim; NaN if nothing was measured): for ``reaches`` the estimate's margin above the level, for
        ``below`` below it, for ``better`` the smallest of its comparisons' differences oriented so that positive is
        the claim's way, for ``similar`` minus the largest distance from 0 of its differences
    """
    claim = result.claim
    estimates = np.array([comparison.interval.estimate for comparison in result.comparisons], dtype=float)
    if estimates.size == 0 or np.isnan(estimates).any():
        return float("nan")
    if claim.kind == "reaches":
        return float(estimates[0] - (claim.value or 0.0))
    if claim.kind == "below":
        return float((claim.value or 0.0) - estimates[0])
    if claim.kind == "better":
        sign = 1.0 if higher_is_better(claim) else -1.0
        return float(np.min(sign * estimates))
    return float(-np.max(np.abs(estimates)))


def judge(
    claim: Claim,
    metrics: Mapping[str, Mapping[str, np.ndarray]],
    confidence: float = CONFIDENCE,
    method: str = "bootstrap",
    margin: float | None = None,
    bounds: tuple[float, float] | None = None,
    spread_level: float | None = None,
) -> ClaimResult:
    """
    :param claim: the claim
    :param metrics: per variant, its ``seed_metrics``
    :param confidence: the level of its intervals
    :param method: how they are computed (``INTERVAL_METHODS``)
    :param margin: a ``better`` claim's equivalence margin, in the metric's units: a comparison whose interval lies
        within ± it is *not supported: alike within ±margin* (None: no such verdict)
    :param bounds: the env's range of returns, for a return metric's intervals (``interval``)
    :param spread_level: the level at which a ``better`` claim on a spread (``std``) needs the permutation test of
        equal spreads to reject (``spread_p_value``); None: 1 − ``confidence``
    :return: the verdict by the rule of this module's docstring
    """
    sign = 1.0 if higher_is_better(claim) else -1.0
    ours = metrics[claim.variant][claim.metric]
    bounds = bounds if claim.metric in RETURN_METRICS else None
    censored_notes: list[str] = []
    what = METRIC_LABELS[claim.metric] + (", spread over seeds (std)" if claim.statistic == "std" else "")
    comparisons = []
    if claim.kind in ("better", "similar"):
        parts = []
        for other in claim.others:
            difference = difference_interval(
                ours, metrics[other][claim.metric], claim.statistic, confidence=confidence, method=method, bounds=bounds
            )
            tested = ""
            if claim.kind == "better":
                oriented = sorted((sign * difference.low, sign * difference.high))
                verdict = _directional(oriented[0], oriented[1])
                if claim.statistic == "std" and verdict in (SUPPORTED, REVERSED):
                    # A spread's direction also needs the permutation test (the module's docstring)
                    p_value = spread_p_value(ours, metrics[other][claim.metric])
                    tested = f", equal spreads' permutation test p = {p_value:.3f}"
                    if p_value >= (1 - confidence if spread_level is None else spread_level):
                        verdict = TOO_CLOSE
                if verdict == TOO_CLOSE and margin is not None and _similar(difference, margin) == SUPPORTED:
                    verdict = alike(margin)
            else:
                assert claim.margin is not None
                verdict = _similar(difference, claim.margin)
            verdict = censored_verdict(claim, verdict, difference, metrics, other, censored_notes)
            comparisons.append(Comparison(other, difference, verdict))
            # (each comparison's verdict where there are several: the claim's own is given beside it)
            each = f" ({verdict})" if len(claim.others) > 1 else ""
            parts.append(f"{claim.variant} − {other}: {_signed(difference)}{tested}{each}")
        overall = _overall(claim, [comparison.verdict for comparison in comparisons], margin)
        measured = f"{what}: " + "; ".join(parts)
        if claim.kind == "similar":
            measured += f" (similar: within ±{claim.margin:g})"
        elif margin is not None:
            measured += f" (equivalence margin ±{margin:g})"
    else:
        assert claim.value is not None
        value = interval(ours, claim.statistic, confidence=confidence, method=method, bounds=bounds)
        # On the metric's own scale, whichever way is better: "reaches" is ≥ the level, "below" is < it
        low, high = value.low - claim.value, value.high - claim.value
        if np.isnan(low):
            verdict = TOO_CLOSE
        elif low >= 0:
            verdict = SUPPORTED if claim.kind == "reaches" else NOT_SUPPORTED
        elif high < 0:
            verdict = NOT_SUPPORTED if claim.kind == "reaches" else SUPPORTED
        else:
            verdict = TOO_CLOSE
        verdict = censored_verdict(claim, verdict, value, metrics, None, censored_notes)
        comparisons.append(Comparison(None, value, verdict))
        overall = verdict
        measured = f"{what} of {claim.variant}: {value.format()} against {claim.value:g}"
    if claim.metric == "episodes_to_threshold":
        never = [
            f"{name} {np.count_nonzero(~metrics[name]['reached'])}/{len(metrics[name]['reached'])}"
            for name in (claim.variant, *claim.others)
            if not metrics[name]["reached"].all()
        ]
        if never:
            measured += (
                f" (seeds that never reached the threshold, counted as the budget: {', '.join(never)}"
                + "".join(f"; {note}" for note in dict.fromkeys(censored_notes))
                + ")"
            )
    n_seeds = min(len(metrics[name][claim.metric]) for name in (claim.variant, *claim.others))
    if n_seeds < MIN_SEEDS:
        overall = TOO_CLOSE
        measured += f" (only {n_seeds} seeds in a variant: too few for a verdict, at least {MIN_SEEDS} are needed)"
    return ClaimResult(claim, overall, tuple(comparisons), measured)


def _overall(claim: Claim, verdicts: Sequence[str], margin: float | None) -> str:
    """:return: the verdict of a claim over several variants from those of its comparisons (the module's docstring)"""
    if all(verdict == SUPPORTED for verdict in verdicts):
        return SUPPORTED
    if claim.kind == "better" and all(verdict == REVERSED for verdict in verdicts):
        return REVERSED
    if margin is not None and all(verdict == alike(margin) for verdict in verdicts):
        return alike(margin)
    if any(verdict in (REVERSED, NOT_SUPPORTED) or is_alike(verdict) for verdict in verdicts):
        return NOT_SUPPORTED
    return TOO_CLOSE


def alike(margin: float) -> str:
    """:return: the verdict of a ``better`` comparison shown within ± ``margin``: ``not supported: alike within ±25``"""
    return f"{NOT_SUPPORTED}: {ALIKE} ±{margin:g}"


def is_alike(verdict: str) -> bool:
    """:return: whether ``verdict`` is ``alike``'s"""
    return verdict.startswith(f"{NOT_SUPPORTED}: {ALIKE}")


def is_decided(verdict: str) -> bool:
    """:return: whether ``verdict`` decides its claim (anything but too close to call)"""
    return verdict != TOO_CLOSE


def censored_verdict(
    claim: Claim,
    verdict: str,
    value: Interval,
    metrics: Mapping[str, Mapping[str, np.ndarray]],
    other: str | None,
    notes: list[str],
) -> str:
    """
    A comparison's verdict on episodes to threshold, where a seed that never reached the threshold counts as its
    budget: a lower bound of its value, which may be any number of episodes beyond. What the budget bounds alike in
    both variants (one reaching it earlier within the budget: the restricted means) stands; what a censored seed's
    unknown value could overturn is too close to call.

    :param claim: the claim
    :param verdict: the comparison's verdict from its interval
    :param value: that interval: of ``claim.variant`` − ``other``, or of the variant's statistic (``other`` None)
    :param metrics: per variant, its ``seed_metrics``
    :param other: the variant compared with, or None for a level
    :param notes: where to append why a verdict was made too close to call
    :return: the verdict, or too close to call
    """
    if claim.metric != "episodes_to_threshold" or verdict == TOO_CLOSE:
        return verdict
    names = [claim.variant] if other is None else [claim.variant, other]
    censored = {name: not metrics[name]["reached"].all() for name in names}
    if not any(censored.values()):
        return verdict
    if claim.statistic == "std":
        notes.append("the spread over seeds of censored values is not known: too close to call")
    elif other is None:
        # Censoring only hides larger values: the interval above the level stands, one below it does not
        if value.high - (claim.value or 0.0) < 0:
            notes.append(
                f"such a seed may take any number of episodes beyond the budget: the mean is not shown below {claim.value:g}"
            )
        else:
            return verdict
    elif not any(metrics[name]["reached"].any() for name in names):
        notes.append(f"no seed of {claim.variant} or {other} reached it: both are the budget, nothing was measured")
    elif (claim.kind == "similar" and verdict == SUPPORTED) or is_alike(verdict):
        notes.append("alike within the budget does not show them alike beyond it: too close to call")
    else:
        return verdict
    return TOO_CLOSE


def _directional(low: float, high: float) -> str:
    if np.isnan(low) or np.isnan(high):
        return TOO_CLOSE
    if low > 0:
        return SUPPORTED
    if high < 0:
        return REVERSED
    return TOO_CLOSE


def _similar(difference: Interval, margin: float) -> str:
    if np.isnan(difference.low):
        return TOO_CLOSE
    if -margin <= difference.low and difference.high <= margin:
        return SUPPORTED
    if difference.low > 0 or difference.high < 0:
        return NOT_SUPPORTED
    return TOO_CLOSE


def _signed(value: Interval) -> str:
    if np.isnan(value.low):
        return f"{value.estimate:+.1f}"
    return f"{value.estimate:+.1f} [{value.low:+.1f}, {value.high:+.1f}]"
