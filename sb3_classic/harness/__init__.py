"""
The run harness of the studies (``sb3_classic.studies``) and of the repository's benchmarks: one learning run built
by rl-zoo3's ``ExperimentManager`` from a zoo YAML entry, cached on disk under a key of its settings and code
versions, run in a pool of processes or on a Dask cluster, with a progress display. Needs the ``zoo`` extra
(``pip install "sb3_classic[zoo]"``); the Dask cluster, the ``dask`` extra.

Modules, each importing only the ones before it:

- ``common``: what a run is (``RunSpec`` and its cache key, ``code_versions``, the algorithms' hyperparameter files,
  ``register_algorithms``, their population classes);
- ``runner``: one run (``execute_run`` trains it anywhere, ``store_run`` caches it, ``run_one`` both, ``load_run``), or
  the runs of one population (``execute_population``);
- ``lockstep``: which runs train in lockstep, the seeds of a setting as one population of the algorithm
  (``plan_lockstep``, ``lockstep_jobs``);
- ``cluster``: the runs on a Dask cluster (``--scheduler``), imported only then;
- ``pool``: the runs not cached, in parallel with a progress display (``run_pending``: a population is one job), and
  those that failed
  (``report_missing``).

Nothing here is imported by ``import sb3_classic``.
"""
