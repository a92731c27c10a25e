"""
A sequential design for a study: seeds drawn in looks, where a verdict needs them, with an error rate that holds
however early a claim stops.

A study file's ``seeds: {start: 10, step: 10, max: 40}`` plans looks at 10, 20, 30 and 40 seeds per variant. At each
look every undecided claim is judged on the first ``n`` seeds of each of its variants; a claim decided there keeps
that verdict and draws no more seeds, and a variant draws the next look's seeds while some claim over it is
undecided. A claim still undecided at ``max`` says how many seeds per variant would decide it (``seeds_needed``).

Why the looks need wider intervals: a 95% interval taken at each of several looks, stopping at the first that excludes
0, says "difference" where there is none more often than 5% (up to 10% over 3 looks on data like the seed report's,
``benchmarks/results/studies/error-control.md``). A group-sequential plan fixes this (Jennison & Turnbull 2000, *Group
Sequential Methods*, ch. 2): the z-statistics of the looks of one claim are jointly normal with correlation √(n_i /
n_j) (its information grows with the seeds), and the two-sided boundaries b_k are chosen so that P(|Z_k| ≥ b_k at some
look) = α when there is no difference. ``boundaries`` solves for them with SciPy's multivariate normal distribution;
the shapes:

- ``pocock``: the same b at every look (Pocock 1977, *Biometrika* 64(2)); 2.361 for 4 looks at α = 0.05;
- ``obrien-fleming``: b_k = c √(n_max / n_k), strict early and near 1.96 at the last (O'Brien & Fleming 1979,
  *Biometrics* 35(3)); 4.049, 2.863, 2.337, 2.024 for 4 looks.

Each look's verdict is then the fixed rule (``stats.judge``) at the confidence 1 − 2 Φ(−b_k), with studentized
bootstrap intervals (``stats.INTERVAL_METHODS``): ``benchmarks/results/studies/error-control.md`` measures the rate of
wrong verdicts of this design on synthetic per-seed data, beside the naive repeated 95% interval's. Written here by
hand: the boundaries' equation (SciPy computes the normal probabilities) and the seeds-needed formula; no library of
the ecosystem plans looks.
"""

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cache, cached_property
from typing import TYPE_CHECKING

import numpy as np
from scipy import optimize
from scipy import stats as scipy_stats

from sb3_classic.studies import stats
from sb3_classic.studies.spec import MARGIN_FRACTION, STATED, Claim

if TYPE_CHECKING:
    from sb3_classic.studies.spec import StudySpec

BOUNDARIES = ("pocock", "obrien-fleming")
#: The error rate per claim of a sequential design (two-sided)
ALPHA = 0.05
#: The power that ``seeds_needed`` plans for
POWER = 0.8
#: Seeds per variant beyond which ``seeds_needed`` calls a verdict out of practical reach
PRACTICAL_SEEDS = 200


@cache
def _boundaries(fractions: tuple[float, ...], alpha: float, shape: str) -> tuple[float, ...]:
    return tuple(boundaries(fractions, alpha, shape))


def boundaries(fractions: Sequence[float], alpha: float = ALPHA, shape: str = "pocock") -> np.ndarray:
    """
    The two-sided group-sequential boundaries of a plan's looks (the module's docstring).

    :param fractions: each look's information as a fraction of the last's (seeds per variant n_k / n_max), increasing,
        the last 1
    :param alpha: the probability, with no difference, that some look's |Z_k| reaches its boundary
    :param shape: ``pocock`` or ``obrien-fleming``
    :return: b_k per look, on the z scale
    :raise ValueError: for an unknown ``shape``, or fractions not increasing to 1
    """
    t = np.asarray(fractions, dtype=float)
    if shape not in BOUNDARIES:
        raise ValueError(f"boundary {shape!r}: choose one of {', '.join(BOUNDARIES)}")
    if len(t) == 0 or np.any(np.diff(t) <= 0) or t[0] <= 0 or not np.isclose(t[-1], 1.0):
        raise ValueError(f"fractions {list(t)}: increasing, in (0, 1], the last 1")
    if len(t) == 1:
        return np.array([scipy_stats.norm.isf(alpha / 2)])
    # Cov(Z_i, Z_j) = √(t_i / t_j) for t_i ≤ t_j: the sum over seeds grows by independent increments
    covariance = np.sqrt(np.minimum.outer(t, t) / np.maximum.outer(t, t))
    shape_of = np.ones_like(t) if shape == "pocock" else 1 / np.sqrt(t)
    # A seeded quasi-Monte Carlo integration (Genz's): the same boundaries on every call, the probability to ~1e-5
    normal = scipy_stats.multivariate_normal(np.zeros(len(t)), covariance, seed=0)

    def excess(c: float) -> float:
        bound = c * shape_of
        inside = normal.cdf(bound, lower_limit=-bound)
        return float(1 - inside - alpha)

    return optimize.brentq(excess, scipy_stats.norm.isf(alpha / 2) * 0.5, 10.0, xtol=1e-4) * shape_of


@dataclass(frozen=True)
class SequentialDesign:
    """
    A study's seeds in looks (the module's docstring): ``seeds: {start: 10, step: 10, max: 40}`` in a study file.

    :param start: seeds per variant at the first look (at least ``stats.MIN_SEEDS``)
    :param step: seeds added at each later look
    :param max: the most seeds per variant (the last look)
    :param boundary: the shape of the looks' boundaries (``BOUNDARIES``)
    :param alpha: the error rate per claim, over all its looks
    :param method: the looks' intervals (``stats.INTERVAL_METHODS``: by default the bootstrap-t joined with Student's t,
        which hold α at these seed counts where BCa does not, ``benchmarks/results/studies/error-control.md``)
    """

    start: int
    step: int
    max: int
    boundary: str = "pocock"
    alpha: float = ALPHA
    method: str = "bootstrap-t"

    @property
    def looks(self) -> tuple[int, ...]:
        """Seeds per variant at each look: ``start``, ``start + step``, ..., ``max``."""
        looks = list(range(self.start, self.max + 1, self.step))
        return tuple(looks if looks[-1] == self.max else [*looks, self.max])

    @cached_property
    def confidences(self) -> tuple[float, ...]:
        """Each look's interval level, 1 − 2 Φ(−b_k)."""
        fractions = [n / self.max for n in self.looks]
        bounds = _boundaries(tuple(fractions), self.alpha, self.boundary)
        return tuple(float(1 - 2 * scipy_stats.norm.sf(b)) for b in bounds)

    @property
    def spread_level(self) -> float:
        """The level of a spread's permutation test at each look (``stats.judge``): α/K over the K looks, Bonferroni's
        bound, since the test is exact at each look and the boundaries' normal approximation is not."""
        return self.alpha / len(self.looks)

    def describe(self) -> str:
        """:return: e.g. ``looks at 10, 20, 30 seeds per variant (Pocock boundaries, 97.79% intervals at each)``"""
        levels = sorted({f"{100 * level:.2f}%" for level in self.confidences})
        name = {"pocock": "Pocock", "obrien-fleming": "O'Brien–Fleming"}[self.boundary]
        each = (
            f"{levels[0]} intervals at each"
            if len(levels) == 1
            else "intervals at " + ", ".join(f"{100 * level:.2f}%" for level in self.confidences)
        )
        return f"looks at {', '.join(map(str, self.looks))} seeds per variant ({name} boundaries, {each})"


@dataclass(frozen=True)
class SequentialVerdict:
    """
    A claim judged look by look.

    :param result: its verdict at the look where it stopped (decided), else at the last look taken
    :param seeds: seeds per variant at that look
    :param looks_taken: the looks judged (1-based count)
    :param next_seeds: seeds per variant its next look needs (0: none, it is decided or at the plan's last look)
    :param needed: for a claim undecided at the last look, how many seeds would decide it (``seeds_needed``)
    """

    result: stats.ClaimResult
    seeds: int
    looks_taken: int
    next_seeds: int = 0
    needed: str = ""

    @property
    def decided(self) -> bool:
        """Whether the claim stopped with a verdict."""
        return stats.is_decided(self.result.verdict)


def judge_sequentially(
    claim: Claim,
    metrics: Mapping[str, Mapping[str, np.ndarray]],
    design: SequentialDesign,
    margin: float | None = None,
    bounds: tuple[float, float] | None = None,
) -> SequentialVerdict | None:
    """
    Replay a claim's looks on the seeds found: at look k, each variant's first n_k seeds, judged at that look's level;
    the first decided look is the verdict (what follows it was drawn for other claims and is not looked at).

    :param claim: the claim
    :param metrics: per variant, its ``stats.seed_metrics``, the seeds in the order of the study's (0, 1, ...)
    :param design: the looks
    :param margin: a ``better`` claim's equivalence margin (``stats.judge``)
    :param bounds: the env's range of returns (``stats.judge``), or None
    :return: its verdict, or None if its variants lack the first look's seeds
    """
    found = min(len(metrics[name][claim.metric]) for name in (claim.variant, *claim.others))
    verdict = None
    for index, (n, confidence) in enumerate(zip(design.looks, design.confidences, strict=True)):
        if found < n:
            break
        first = {name: {key: values[:n] for key, values in metrics[name].items()} for name in (claim.variant, *claim.others)}
        result = stats.judge(claim, first, confidence, design.method, margin, bounds, design.spread_level)
        last = index == len(design.looks) - 1
        if stats.is_decided(result.verdict) or last:
            needed = "" if stats.is_decided(result.verdict) else seeds_needed(claim, first, design, margin)
            return SequentialVerdict(result, n, index + 1, 0, needed)
        verdict = SequentialVerdict(result, n, index + 1, design.looks[index + 1])
    return verdict


def seeds_needed(
    claim: Claim, metrics: Mapping[str, Mapping[str, np.ndarray]], design: SequentialDesign, margin: float | None = None
) -> str:
    """
    How many seeds per variant would decide a claim at ``POWER`` power, if its observed effect and spread are the
    truth: a fixed design at the last look's level, n = (z_{1−α'/2} + z_{power})² · (s_A² + s_B²) / d² for a difference
    d of means (s²/d² for a mean against a level; the sample spread's variance ≈ s² / 2(n − 1) for a spread), and for
    an equivalence verdict within ± m, d replaced by m − |d|. Normal approximations, written here: at such seed counts
    the t's quantiles differ from the normal's by a seed or two.

    :param claim: the claim
    :param metrics: per variant, its ``stats.seed_metrics`` (the seeds of its last look)
    :param design: the design (its last look's level is the α')
    :param margin: a ``better`` claim's equivalence margin, or None
    :return: e.g. ``about 64 seeds per variant would decide it``, or why no count of seeds is realistic
    """
    z = scipy_stats.norm.isf((1 - design.confidences[-1]) / 2) + scipy_stats.norm.ppf(POWER)
    ours = np.asarray(metrics[claim.variant][claim.metric], dtype=float)
    if claim.metric == "episodes_to_threshold" and not all(
        np.asarray(metrics[name]["reached"]).any() for name in (claim.variant, *claim.others)
    ):
        return "no seed of a variant reached the threshold: more episodes per run, not more seeds, would measure it"
    sign = 1.0 if stats.higher_is_better(claim) else -1.0
    if claim.kind in ("reaches", "below"):
        assert claim.value is not None
        gap = abs(_statistic(ours, claim.statistic) - claim.value)
        difference, equivalence = _count(z, _spread(ours, claim.statistic), gap), None
    else:
        width = claim.margin if claim.kind == "similar" else margin
        shown: list[float] = []
        against: list[float] = []
        alike: list[float] = []
        for other in claim.others:
            theirs = np.asarray(metrics[other][claim.metric], dtype=float)
            gap = _statistic(ours, claim.statistic) - _statistic(theirs, claim.statistic)
            spread = float(np.hypot(_spread(ours, claim.statistic), _spread(theirs, claim.statistic)))
            # A difference the claim's way (shown), or against it, and how many seeds would show it alike
            (shown if sign * gap > 0 or claim.kind == "similar" else against).append(_count(z, spread, abs(gap)))
            if width is not None:
                alike.append(_count(z, spread, width - abs(gap)) if abs(gap) < width else np.inf)
        if claim.kind == "similar":
            # Supported: every comparison alike; not supported: one difference shown
            difference, equivalence = min(shown), max(alike) if alike else None
        else:
            # Supported: every comparison shown the claim's way; not supported: one shown against it, or alike
            difference = min([max(shown) if shown and not against else np.inf, *against])
            equivalence = min(alike) if alike else None
    best = min(difference, equivalence if equivalence is not None else np.inf)
    if best <= PRACTICAL_SEEDS:
        which = "an equivalence verdict" if equivalence is not None and equivalence < difference else "a verdict"
        # (at least one more look's worth: the claim was not decided by the seeds it has)
        count = max(int(np.ceil(best)), design.max + design.step)
        return f"about {count} seeds per variant would give {which} at {POWER:.0%} power"
    if equivalence is not None and np.isfinite(equivalence):
        return f"out of practical reach (over {PRACTICAL_SEEDS} seeds per variant, even for an equivalence verdict)"
    return f"out of practical reach (over {PRACTICAL_SEEDS} seeds per variant)"


def _statistic(values: np.ndarray, statistic: str) -> float:
    return float(np.mean(values) if statistic == "mean" else np.std(values, ddof=1))


def _spread(values: np.ndarray, statistic: str) -> float:
    """:return: the standard deviation of one seed's contribution to the statistic (n seeds: this / √n)"""
    sd = float(np.std(values, ddof=1)) if len(values) > 1 else 0.0
    # The sample spread's standard error ≈ s / √(2(n − 1)) ≈ (s / √2) / √n
    return sd if statistic == "mean" else sd / np.sqrt(2)


def _count(z: float, spread: float, gap: float) -> float:
    """:return: seeds per variant for a gap of ``gap`` at ``spread`` per seed (inf: no gap to detect)"""
    if gap <= 0:
        return np.inf
    if spread == 0:
        return float(stats.MIN_SEEDS)
    return float((z * spread / gap) ** 2)


def claim_margin(study: "StudySpec", claim: Claim) -> float | None:
    """
    :return: the equivalence margin of a ``better`` claim (None for the other kinds: ``similar`` has its own): its
        ``margin``, else the study's (a return's units) for a return or its spread, else 5% of the episode budget for
        episodes to threshold (None without one)
    """
    if claim.kind != "better":
        return None
    if claim.margin is not None:
        return claim.margin
    if claim.metric == "episodes_to_threshold" and claim.statistic == "mean":
        episodes = study.budget.episodes
        return None if episodes is None else float(f"{MARGIN_FRACTION * episodes:.2g}")
    return study.margin


def seeds_planned(study: "StudySpec") -> dict[tuple[str, str], int] | None:
    """:return: per (reading, variant), the most seeds its design may run (the last look's as stated, the first look's
    under the other readings); None without a design (every seed)"""
    if study.design is None:
        return None
    return {
        (reading, variant): study.design.max if reading == STATED else study.design.looks[0]
        for reading in study.readings
        for variant in study.variants
    }


def seeds_wanted(study: "StudySpec", verdicts: Mapping[str, SequentialVerdict]) -> dict[tuple[str, str], int] | None:
    """
    :param study: the study
    :param verdicts: its claims' sequential verdicts so far, by text (a claim without one: its variants lack the
        first look's seeds)
    :return: per (reading, variant), the seeds to have run: the first look's, and as stated the next look of every
        undecided claim over the variant; None without a design (every seed)
    """
    if study.design is None:
        return None
    first = study.design.looks[0]
    counts = {(reading, variant): first for reading in study.readings for variant in study.variants}
    for claim in study.claims:
        verdict = verdicts.get(claim.text)
        wanted = first if verdict is None else max(verdict.seeds, verdict.next_seeds)
        for name in (claim.variant, *claim.others):
            counts[(STATED, name)] = max(counts[(STATED, name)], wanted)
    return counts
