"""A study's sequential design: its boundaries, its looks, its stopping, resuming from recorded seeds, equivalence,
seeds needed, and its error rate on synthetic data."""

import dataclasses
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats as scipy_stats

from sb3_classic.studies import outputs, sequential, stats
from sb3_classic.studies.spec import STATED, Claim, StudyError, StudyRun, StudySpec, load_study

SEQUENTIAL = """
title: Tiny sequential
env: CartPole-v1
algo: nstep_sarsa
seeds: {start: 5, step: 5, max: 15}
budget: {episodes: 6}
hyperparams:
  policy: MlpPolicy
  learning_rate: !!float 1e-3
  policy_kwargs: {net_arch: [16]}
variants:
  n1: {n_steps: 1}
  n3: {n_steps: 3}
  n5: {n_steps: 5}
claims:
  - {text: "n = 3 beats n = 1", kind: better, variant: n3, others: [n1]}
  - {text: "n = 5 beats n = 1", kind: better, variant: n5, others: [n1]}
"""

BETTER = Claim("A beats B", "better", "A", ("B",))


def metrics_of(values: np.ndarray) -> dict[str, np.ndarray]:
    values = np.asarray(values, dtype=float)
    return {"mean_return": values, "reached": np.ones(len(values), dtype=bool)}


@pytest.mark.parametrize(
    ("looks", "shape", "expected"),
    [
        # Jennison & Turnbull (2000), Tables 2.1 and 2.3: two-sided α = 0.05, equally spaced looks
        (2, "pocock", [2.178, 2.178]),
        (4, "pocock", [2.361] * 4),
        (5, "pocock", [2.413] * 5),
        (4, "obrien-fleming", [4.049, 2.863, 2.337, 2.024]),
        (1, "pocock", [1.960]),
    ],
)
def test_boundaries_match_the_published_tables(looks: int, shape: str, expected: list[float]) -> None:
    found = sequential.boundaries([k / looks for k in range(1, looks + 1)], 0.05, shape)
    np.testing.assert_allclose(found, expected, atol=2e-3, err_msg=f"{shape}, {looks} looks: {found}")


def test_a_design_names_its_looks_and_levels() -> None:
    design = sequential.SequentialDesign(10, 10, 40)
    assert design.looks == (10, 20, 30, 40)
    assert sequential.SequentialDesign(5, 10, 30).looks == (5, 15, 25, 30)
    assert all(abs(level - 0.9818) < 1e-3 for level in design.confidences), design.confidences
    assert "looks at 10, 20, 30, 40 seeds" in design.describe()


def test_a_claim_decided_at_its_first_look_draws_no_more_seeds(tmp_path: Path) -> None:
    (tmp_path / "study.yml").write_text(SEQUENTIAL)
    study = load_study(tmp_path / "study.yml")
    assert study.design is not None
    assert study.margin == 25
    rng = np.random.default_rng(0)
    far = {
        "n1": metrics_of(rng.normal(20, 2, 5)),
        "n3": metrics_of(rng.normal(400, 2, 5)),
        "n5": metrics_of(rng.normal(40, 80, 5)),
    }
    verdicts = {}
    for claim in study.claims:
        verdict = sequential.judge_sequentially(claim, far, study.design)
        assert verdict is not None
        verdicts[claim.text] = verdict
    decided, undecided = verdicts["n = 3 beats n = 1"], verdicts["n = 5 beats n = 1"]
    assert decided.result.verdict == stats.SUPPORTED
    assert decided.looks_taken == 1
    assert decided.next_seeds == 0
    assert not undecided.decided
    assert undecided.next_seeds == 10
    wanted = sequential.seeds_wanted(study, verdicts)
    assert wanted is not None
    # n3 is decided; n1 and n5 go on for the undecided claim
    assert wanted[(STATED, "n3")] == 5
    assert wanted[(STATED, "n1")] == 10
    assert wanted[(STATED, "n5")] == 10
    planned = study.runs(wanted)
    assert sorted({run.seed for run in planned if run.variant == "n3"}) == list(range(5))
    assert sorted({run.seed for run in planned if run.variant == "n5"}) == list(range(10))


def test_a_look_judges_each_variants_first_seeds_only() -> None:
    design = sequential.SequentialDesign(5, 5, 10)
    # The first five seeds show the difference; five more drawn for another claim would hide it
    a = np.r_[np.full(5, 300.0) + np.arange(5), np.full(5, 10.0)]
    b = np.r_[np.full(5, 10.0) + np.arange(5), np.full(5, 300.0)]
    verdict = sequential.judge_sequentially(BETTER, {"A": metrics_of(a), "B": metrics_of(b)}, design)
    assert verdict is not None
    assert verdict.seeds == 5
    assert verdict.result.verdict == stats.SUPPORTED


def test_equivalence_decides_a_better_claim_within_the_margin() -> None:
    rng = np.random.default_rng(1)
    a, b = rng.normal(100, 5, 40), rng.normal(101, 5, 40)
    result = stats.judge(BETTER, {"A": metrics_of(a), "B": metrics_of(b)}, margin=25.0)
    assert result.verdict == stats.alike(25.0) == "not supported: alike within ±25"
    assert stats.judge(BETTER, {"A": metrics_of(a), "B": metrics_of(b)}).verdict == stats.TOO_CLOSE
    # Several comparisons: one alike, one supported: the claim is not supported (A does not beat every other)
    several = Claim("A beats B and C", "better", "A", ("B", "C"))
    data = {"A": metrics_of(a), "B": metrics_of(b), "C": metrics_of(rng.normal(10, 5, 40))}
    assert stats.judge(several, data, margin=25.0).verdict == stats.NOT_SUPPORTED


def test_an_undecided_claim_at_the_last_look_says_the_seeds_needed() -> None:
    design = sequential.SequentialDesign(10, 10, 20)
    rng = np.random.default_rng(2)
    # An effect of 30 with a spread of 60 per seed: about 2 × (2.38 + 0.84)² × 60² / 30² ≈ 83 seeds per variant
    a, b = rng.normal(130, 60, 20), rng.normal(100, 60, 20)
    a += 130 - a.mean()
    b += 100 - b.mean()
    verdict = sequential.judge_sequentially(BETTER, {"A": metrics_of(a), "B": metrics_of(b)}, design, margin=None)
    assert verdict is not None
    assert not verdict.decided
    assert verdict.looks_taken == 2
    count = int(verdict.needed.split("about ")[1].split(" ")[0])
    spread = np.hypot(a.std(ddof=1), b.std(ddof=1))
    level = design.confidences[-1]
    z = scipy_stats.norm.isf((1 - level) / 2) + scipy_stats.norm.ppf(0.8)
    assert count == int(np.ceil((z * spread / 30) ** 2)), verdict.needed
    # A tiny effect with a large spread is out of practical reach
    c = rng.normal(100, 200, 20)
    c += 101 - c.mean()
    far = sequential.judge_sequentially(BETTER, {"A": metrics_of(c), "B": metrics_of(b)}, design)
    assert far is not None
    assert "out of practical reach" in far.needed, far.needed


def test_a_study_resumes_from_its_recorded_seeds(tmp_path: Path) -> None:
    """The committed per-seed results count as run: the cache may be gone (another machine), and the verdicts and the
    next look are the same as from the runs themselves."""
    (tmp_path / "study.yml").write_text(SEQUENTIAL)
    study = load_study(tmp_path / "study.yml")
    results_dir, cache_dir = tmp_path / "results", tmp_path / "cache"
    results_dir.mkdir()
    rng = np.random.default_rng(3)
    # n5's seeds spread too widely for a verdict or an equivalence at 5 seeds
    level, spread = {"n1": 20.0, "n3": 400.0, "n5": 60.0}, {"n1": 3.0, "n3": 3.0, "n5": 80.0}
    rows = []
    for run in study.runs(sequential.seeds_wanted(study, {})):
        value = level[run.variant] + rng.normal(0, spread[run.variant])
        rows.append(
            {
                "reading": run.reading,
                "variant": run.variant,
                "seed": run.seed,
                "mean_return": value,
                "last_100_return": value,
                "episodes_to_threshold": 6.0,
                "reached": False,
                "run": f"key{run.seed}{run.variant}",
                "settings": outputs.settings_key(run.spec, study),
                "cpu_seconds": 2.0,
                "lockstep": True,
            }
        )
    pd.DataFrame(rows).to_csv(results_dir / f"{study.name}-seeds.csv", index=False)
    results = outputs.load_study_results(study, cache_dir, results_dir)
    assert results.recorded == 15
    assert results.n_runs == 15
    assert results.looks["n = 3 beats n = 1"].result.verdict == stats.SUPPORTED
    assert results.looks["n = 5 beats n = 1"].decided is False
    # The next look: 5 more seeds of n1 and n5, none of n3
    assert sorted((run.variant, run.seed) for run in results.missing) == [
        (variant, seed) for variant in ("n1", "n5") for seed in range(5, 10)
    ]
    # Written and read back: the same
    outputs.write_study(results, results_dir, "python -m sb3_classic.studies study.yml")
    again = outputs.load_study_results(study, cache_dir, results_dir)
    assert [r.verdict for r in again.verdicts[STATED]] == [r.verdict for r in results.verdicts[STATED]]
    page = (results_dir / f"{study.name}.md").read_text()
    assert "Sequential design: looks at 5, 10, 15 seeds per variant" in page
    assert "Looks to come" in page
    assert "5 seeds per variant, look 1" in page
    # A record of other settings (another budget) does not count
    other = study.with_budget(episodes=7)
    assert outputs.load_study_results(other, cache_dir, results_dir).recorded == 0


@pytest.mark.parametrize(
    ("seeds", "expected"),
    [
        ("{start: 5, max: 40, stpe: 5}", "seeds.stpe: unknown field: did you mean 'step'?"),
        ("{start: 5}", "lacks max"),
        ("{start: 2, step: 2, max: 10}", "seeds.start: 2: the first look needs at least 5 seeds"),
        ("{start: 10, step: 5, max: 5}", "seeds.max: 5 is below start (10)"),
        ("{start: 5, step: 5, max: 10, boundary: bonferroni}", "seeds.boundary: 'bonferroni': choose one of pocock"),
    ],
)
def test_a_wrong_design_names_the_field(tmp_path: Path, seeds: str, expected: str) -> None:
    (tmp_path / "study.yml").write_text(SEQUENTIAL.replace("{start: 5, step: 5, max: 15}", seeds))
    with pytest.raises(StudyError) as error:
        load_study(tmp_path / "study.yml")
    assert expected in str(error.value), str(error.value)


def test_the_margin_is_declared_or_five_percent_of_the_range(tmp_path: Path) -> None:
    (tmp_path / "study.yml").write_text(SEQUENTIAL + "margin: 10\n")
    assert load_study(tmp_path / "study.yml").margin == 10
    (tmp_path / "study.yml").write_text(SEQUENTIAL.replace("CartPole-v1", "Acrobot-v1"))
    assert load_study(tmp_path / "study.yml").margin == 25
    (tmp_path / "study.yml").write_text(SEQUENTIAL + "margin: -1\n")
    with pytest.raises(StudyError, match="margin: -1: the largest difference"):
        load_study(tmp_path / "study.yml")


@pytest.mark.slow
def test_the_error_rate_holds_under_optional_stopping() -> None:
    """With no difference, the design says "difference" at most 5% of the time over its looks (within the simulation's
    noise); the naive 95% at every look, far more often."""
    from benchmarks.studies import error_rates

    chosen = error_rates.DESIGNS[error_rates.CHOSEN]
    naive = error_rates.Naive(chosen.start, chosen.step, chosen.max)
    case = error_rates.cases(1.0, 0.0)[0]
    n = 1_000
    noise = 2.5 * np.sqrt(0.05 * 0.95 / n)
    for name, draw in error_rates.DISTRIBUTIONS.items():
        wrong, _, _ = error_rates.simulate(case, draw, chosen, n, seed=7)
        naive_wrong, _, _ = error_rates.simulate(case, draw, naive, n, seed=7)
        assert wrong <= 0.05 + noise, f"{name}: {wrong:.1%} wrong verdicts"
        assert naive_wrong > wrong, f"{name}: naive {naive_wrong:.1%}, chosen {wrong:.1%}"


LEVEL, SPREAD = {"n1": 20.0, "n3": 400.0, "n5": 60.0}, {"n1": 3.0, "n3": 3.0, "n5": 80.0}


def fake_runs(cache: Path, runs: Sequence[StudyRun], level: dict[str, float], spread: dict[str, float]) -> None:
    """Cache entries of ``runs`` (as the harness writes them), 6 episodes of one return per seed, drawn per variant."""
    for run in runs:
        run_dir = run.spec.run_dir(cache)
        if run_dir.exists():
            continue
        run_dir.mkdir(parents=True)
        (run_dir / "run.json").write_text('{"learn_time_s": 1.0, "eval_time_s": 0.0, "training": "lockstep"}')
        value = level[run.variant] + spread[run.variant] * np.sin(7.3 * run.seed + len(run.variant))
        (run_dir / "episodes.csv").write_text("return\n" + "\n".join([f"{value:.3f}"] * 6) + "\n")


def first_look(tmp_path: Path) -> tuple[StudySpec, Path, Path]:
    """:return: the sequential study, a cache holding its first look's runs (n3 far above n1, n5 spread too widely to
    tell), and where its outputs go"""
    (tmp_path / "study.yml").write_text(SEQUENTIAL)
    study = load_study(tmp_path / "study.yml")
    cache, results_dir = tmp_path / "cache", tmp_path / "results"
    fake_runs(cache, study.runs(sequential.seeds_wanted(study, {})), LEVEL, SPREAD)
    return study, cache, results_dir


def test_an_interrupted_study_resumes_look_by_look_from_its_cache_or_its_record(tmp_path: Path) -> None:
    study, cache, results_dir = first_look(tmp_path)
    first = outputs.load_study_results(study, cache)
    assert first.recorded == 0
    assert {run.variant for run in first.missing} == {"n1", "n5"}
    # The next look's runs done (as the runner would), then the study read again: the second look judged
    fake_runs(cache, first.missing, LEVEL, SPREAD)
    second = outputs.load_study_results(study, cache)
    verdict = second.looks["n = 5 beats n = 1"]
    assert verdict.looks_taken == 2 or verdict.decided
    outputs.write_study(second, results_dir, "python -m sb3_classic.studies study.yml")
    # Without the cache (another machine): the recorded seeds give the same verdicts and the same next look
    again = outputs.load_study_results(study, tmp_path / "empty-cache", results_dir)
    assert again.recorded == second.n_runs
    assert [r.verdict for r in again.verdicts[STATED]] == [r.verdict for r in second.verdicts[STATED]]
    assert {looked.seeds for looked in again.looks.values()} == {looked.seeds for looked in second.looks.values()}
    assert sorted(run.spec.key() for run in again.missing) == sorted(run.spec.key() for run in second.missing)


def test_seeds_at_one_value_give_a_finite_interval_within_the_envs_returns() -> None:
    # Eight seeds of ten solved at 500: resamples of only 500s have no spread, and the interval stayed open below
    solved = np.array([500.0] * 8 + [300.0, 400.0])
    value = stats.interval(solved, confidence=0.978, method="bootstrap-t")
    assert np.isfinite(value.low)
    assert value.low < 470 < value.high
    # Every seed at −500: n seeds at one value bound the share elsewhere by 1 − tail^(1/n) (Clopper–Pearson)
    failed = np.full(10, -500.0)
    share = 1 - 0.011 ** (1 / 10)
    value = stats.interval(failed, confidence=0.978, method="bootstrap-t", bounds=(-500.0, 0.0))
    assert value.low == -500.0
    assert value.high == pytest.approx(-500.0 + share * 500.0)
    level = Claim("reaches", "reaches", "A", value=-100.0)
    assert stats.judge(level, {"A": metrics_of(failed)}, 0.978, "bootstrap-t", bounds=(-500.0, 0.0)).verdict == (
        stats.NOT_SUPPORTED
    )
    near = Claim("reaches", "reaches", "A", value=-450.0)
    assert stats.judge(near, {"A": metrics_of(failed)}, 0.978, "bootstrap-t", bounds=(-500.0, 0.0)).verdict == (
        stats.TOO_CLOSE
    )


def test_a_record_is_kept_by_a_command_that_does_not_read_it(tmp_path: Path) -> None:
    study, cache, results_dir = first_look(tmp_path)
    outputs.write_study(outputs.load_study_results(study, cache), results_dir, "python -m sb3_classic.studies study.yml")
    recorded = pd.read_csv(results_dir / f"{study.name}-seeds.csv")
    # Each seed trained alone (--separate): other settings, not read from the record, which its outputs keep
    alone = dataclasses.replace(study, lockstep=False)
    outputs.write_study(outputs.load_study_results(alone, tmp_path / "no-cache", results_dir), results_dir, "command")
    kept = pd.read_csv(results_dir / f"{study.name}-seeds.csv")
    assert sorted(kept["settings"]) == sorted(recorded["settings"])
    assert outputs.load_study_results(study, tmp_path / "no-cache", results_dir).recorded == len(recorded)
