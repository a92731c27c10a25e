"""
The repository's studies: the seed report's study files (``seed_report/``), run by the package's study runner
(``sb3_classic.studies``) with the repository's folders: the cache in benchmarks/cache/, the committed outputs in
benchmarks/results/studies/, whose STUDIES.md lists every claim of the seed report, run or not.

    python -m benchmarks.studies benchmarks/studies/seed_report/fig15-sarsa-cartpole-n.yml
    python -m benchmarks.studies benchmarks/studies/seed_report      # every study of the seed report
"""

from collections.abc import Sequence
from pathlib import Path

from benchmarks.common import DEFAULT_CACHE_DIR, DEFAULT_RESULTS_DIR, REPO_ROOT
from sb3_classic.studies import cli

#: The seed report's comparisons and final models, as study files
SEED_REPORT_STUDIES = Path(__file__).resolve().parent / "seed_report"
#: ``python -m benchmarks.studies``'s folders and the command its outputs show
REPOSITORY = cli.Defaults(
    program="benchmarks.studies",
    cache_dir=DEFAULT_CACHE_DIR,
    results_dir=DEFAULT_RESULTS_DIR / "studies",
    root=REPO_ROOT,
    catalogue=SEED_REPORT_STUDIES,
)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m benchmarks.studies``: the package's command with the repository's folders. :return: the exit status"""
    return cli.main(argv, REPOSITORY)
