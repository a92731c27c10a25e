"""
Hyperparameter studies: a study file names an env, an algorithm, base hyperparameters in the zoo's YAML
form, variants, seeds, a budget and the claims under test; each (variant, seed) is a cached run of the harness
(``sb3_classic.harness``), and the claims are decided by bootstrap confidence intervals over seeds.

    pip install "sb3_classic[zoo]"
    python -m sb3_classic.studies my_study.yml        # cache in ./sb3_classic-cache/, outputs in ./studies-results/

Modules: ``spec`` (the file format and its checks), ``stats`` (metrics, intervals, verdicts), ``outputs`` (figures,
tables, STUDIES.md), ``cli`` (the command). Nothing here is imported by ``import sb3_classic``.
"""
