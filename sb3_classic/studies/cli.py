"""
Run hyperparameter studies: every (variant, seed) of each study file as a cached run of the benchmark harness (built
by rl-zoo3's ExperimentManager, resumable, in parallel or on a Dask cluster), then per study its figure, table and
verdicts, and STUDIES.md.

    python -m benchmarks.studies STUDY.yml [STUDY.yml | FOLDER ...]
    python -m benchmarks.studies benchmarks/studies/seed_report            # the seed report's studies (CPU-days)
    python -m benchmarks.studies STUDY.yml --seeds 2 --episodes 20         # a reduced run, into scratch
    python -m benchmarks.studies STUDY.yml --list                          # runs and cached runs, nothing run

Results go to benchmarks/results/studies/ (committed); a reduced run (--seeds, --episodes, --steps) goes to
benchmarks/cache/quick-studies/, as it is not the study's result.
"""

import argparse
import os
import shlex
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from rich.console import Console
from rich.markup import escape

from benchmarks.common import DEFAULT_CACHE_DIR, DEFAULT_RESULTS_DIR
from benchmarks.run import report_missing, run_pending
from benchmarks.runner import RUN_FILE, ClusterError
from benchmarks.studies import SEED_REPORT_STUDIES
from benchmarks.studies.outputs import load_study_results, study_command, write_studies_index, write_study
from benchmarks.studies.spec import StudyError, StudySpec, load_study

DEFAULT_STUDY_RESULTS_DIR = DEFAULT_RESULTS_DIR / "studies"
#: Where reduced runs write their outputs: scratch, git-ignored with the cache
REDUCED_RESULTS_DIR = DEFAULT_CACHE_DIR / "quick-studies"


def study_files(paths: Sequence[Path]) -> list[Path]:
    """:return: the study files named, and those (``*.yml``) in the folders named, in order"""
    files = []
    for path in paths:
        if path.is_dir():
            found = sorted(path.glob("*.yml")) + sorted(path.glob("*.yaml"))
            if not found:
                raise StudyError(f"{path}: a folder with no study file (*.yml) in it")
            files += found
        elif path.exists():
            files.append(path)
        else:
            raise StudyError(f"{path}: no such study file or folder")
    return files


def main(argv: Sequence[str] | None = None) -> int:
    """The command line (``python -m benchmarks.studies --help``). :return: the exit status"""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("studies", nargs="+", type=Path, help="study files (YAML), or folders of them")
    parser.add_argument("--seeds", type=int, help="seeds 0 to K − 1 instead of the files' (a reduced run)")
    parser.add_argument("--episodes", type=int, help="episodes per run instead of the files' budget (a reduced run)")
    parser.add_argument("--steps", type=int, help="env steps per run instead of the files' budget (a reduced run)")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="runs in parallel (default: the cores)")
    parser.add_argument(
        "--scheduler", metavar="tcp://HOST:PORT", help="run on the Dask cluster of this scheduler (needs the dask extra)"
    )
    parser.add_argument("--cache-dir", type=Path, default=DEFAULT_CACHE_DIR, help="where finished runs are kept")
    parser.add_argument(
        "--results-dir",
        type=Path,
        help=f"figures, tables and STUDIES.md (default {DEFAULT_STUDY_RESULTS_DIR}; reduced runs: {REDUCED_RESULTS_DIR})",
    )
    parser.add_argument("--list", action="store_true", help="list each study's runs and how many are cached; run nothing")
    parser.add_argument("--report-only", action="store_true", help="run nothing: outputs from the runs already cached")
    args = parser.parse_args(argv)
    console = Console()
    if args.episodes is not None and args.steps is not None:
        parser.error("--episodes and --steps: give one budget")

    reduced = args.seeds is not None or args.episodes is not None or args.steps is not None
    try:
        studies = [
            load_study(path).with_budget(args.seeds, args.episodes, args.steps) if reduced else load_study(path)
            for path in study_files(args.studies)
        ]
    except StudyError as error:
        console.print(f"[red]{escape(str(error))}[/red]", highlight=False, soft_wrap=True)
        return 2
    names = [study.name for study in studies]
    duplicates = sorted({name for name in names if names.count(name) > 1})
    if duplicates:
        console.print(f"[red]Two study files have the same name: {escape(', '.join(duplicates))}[/red]", highlight=False)
        return 2
    results_dir = args.results_dir or (REDUCED_RESULTS_DIR if reduced else DEFAULT_STUDY_RESULTS_DIR)

    runs = [run for study in studies for run in study.runs()]
    pending = [run.spec for run in runs if not (run.spec.run_dir(args.cache_dir) / RUN_FILE).exists()]
    if args.list:
        for study in studies:
            study_runs = study.runs()
            cached = sum((run.spec.run_dir(args.cache_dir) / RUN_FILE).exists() for run in study_runs)
            console.print(
                f"{study.name}: {len(study.variants)} variants × {len(study.readings)} readings × {len(study.seeds)} seeds, "
                f"{study.budget.describe()}: {len(study_runs)} runs, {cached} cached",
                highlight=False,
            )
        return 0

    if not args.report_only and pending:
        where = f"the Dask cluster at {args.scheduler}" if args.scheduler else f"{args.workers} workers"
        console.print(f"{len(runs)} runs: {len(runs) - len(pending)} cached, {len(pending)} to run on {where}")
        start = time.perf_counter()
        try:
            run_pending(pending, args.workers, args.cache_dir, console, args.scheduler)
        except KeyboardInterrupt:
            console.print("Interrupted: the finished runs are cached; run the same command again to resume.")
            return 130
        except ClusterError as error:
            console.print(f"[red]{escape(str(error))}[/red]", highlight=False)
            return 2
        console.print(f"Runs: {time.perf_counter() - start:.0f} s")

    command_args = sys.argv[1:] if argv is None else list(argv)
    missing = []
    for study in studies:
        results = load_study_results(study, args.cache_dir)
        missing += [run.spec for run in results.missing]
        extra = [arg for arg in command_args if not _is_study_path(arg, args.studies)]
        command = (
            study_command(study, extra)
            if len(studies) > 1
            else shlex.join(["python", "-m", "benchmarks.studies", *command_args])
        )
        path = write_study(results, results_dir, command, reduced)
        for reading, judged in results.verdicts.items():
            for result in judged:
                where = "" if len(results.verdicts) == 1 else f" [{reading}]"
                console.print(f"{study.name}{where}: {result.verdict}: {result.claim.text}", highlight=False, markup=False)
        console.print(f"wrote {path}", highlight=False)
    catalogue = list(studies)
    if not reduced and results_dir.resolve() == DEFAULT_STUDY_RESULTS_DIR.resolve():
        # The committed index lists every claim of the seed report, run or not
        shipped = {study.name for study in catalogue}
        catalogue += [
            study for study in map(load_study, sorted(SEED_REPORT_STUDIES.glob("*.yml"))) if study.name not in shipped
        ]
    index = write_studies_index(catalogue, results_dir, title="Studies" + (" (reduced runs)" if reduced else ""))
    console.print(f"wrote {index}", highlight=False)
    return report_missing(missing, console)


def _is_study_path(arg: str, studies: Sequence[Path]) -> bool:
    return any(Path(arg) == path for path in studies)


def studies_of(paths: Sequence[Path]) -> list[StudySpec]:
    """:return: the studies of the files and folders named, loaded and checked"""
    return [load_study(path) for path in study_files(paths)]
