"""
Hyperparameter studies on the benchmark harness (issue 14): a study file names an env, an algorithm, base
hyperparameters in the zoo's YAML form, variants, seeds, a budget and the claims under test; each (variant, seed) is
a cached run of the harness, and the claims are decided by bootstrap confidence intervals over seeds.

    python -m benchmarks.studies benchmarks/studies/seed_report/fig15-sarsa-cartpole-n.yml
    python -m benchmarks.studies benchmarks/studies/seed_report      # every study of the seed report

Modules: ``spec`` (the file format and its checks), ``stats`` (metrics, intervals, verdicts), ``outputs`` (figures,
tables, STUDIES.md), ``cli`` (the command).
"""

from pathlib import Path

#: The seed report's comparisons and final models, as study files
SEED_REPORT_STUDIES = Path(__file__).resolve().parent / "seed_report"
