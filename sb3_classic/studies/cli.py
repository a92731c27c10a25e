"""
The command of the studies, ``python -m sb3_classic.studies STUDY.yml [STUDY.yml | FOLDER ...]``: every (variant,
seed) of each study file as a cached run of the harness (built by rl-zoo3's ExperimentManager, resumable, in parallel
or on a Dask cluster), then per study its figure, table and verdicts, and STUDIES.md. ``main`` takes the defaults of
where it runs: ``INSTALLED`` (folders in the working directory) or the repository's (``benchmarks.studies``).
"""

import argparse
import contextlib
import dataclasses
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from rich.console import Console
from rich.markup import escape

from sb3_classic.harness.common import positive_int
from sb3_classic.harness.pool import report_missing, run_missing_runs
from sb3_classic.harness.runner import RUN_FILE, DamagedRunError, RunError, check_run
from sb3_classic.studies import sequential, stats
from sb3_classic.studies.outputs import (
    PROGRAM,
    StudyResults,
    load_study_results,
    plural,
    recorded_seeds,
    settings_key,
    study_command,
    training_summary,
    write_studies_index,
    write_study,
)
from sb3_classic.studies.spec import STATED, StudyError, StudyRun, StudySpec, load_study

#: Where reduced runs (--seeds, --episodes, --steps) write their outputs, inside the cache: they are not the study's.
#: One folder per budget (e.g. ``quick-studies/seeds-2_episodes-20``), so that one reduced run's outputs do not
#: overwrite another's
REDUCED_RESULTS = "quick-studies"

DESCRIPTION = """\
Run hyperparameter studies: every (variant, seed) of each study file as a cached run (built by rl-zoo3's
ExperimentManager, resumable, in parallel or on a Dask cluster), then per study its figure, table and verdicts, and
STUDIES.md, the index of every claim.

    python -m {program} STUDY.yml [STUDY.yml | FOLDER ...]
    python -m {program} STUDY.yml --seeds 2 --episodes 20         # a reduced run, into scratch
    python -m {program} STUDY.yml --list                          # runs and cached runs, nothing run
    python -m {program} STUDY.yml --scheduler tcp://HOST:8786     # on a Dask cluster (the dask extra)

Finished runs are kept in {cache}/ and never run again: an interrupted study resumes where it stopped. Outputs go
to {results}/; a reduced run's to {cache}/{reduced}/ (a folder per budget, e.g. seeds-2_episodes-20/), as they are
not the study's result.
"""


@dataclass(frozen=True)
class Defaults:
    """
    What the command does unless told: where it keeps runs and writes outputs, and the command its outputs show.

    :param program: the module run (``python -m <program>``), as the outputs and ``--help`` show it
    :param cache_dir: the cache of finished runs (``--cache-dir``); relative: in the working directory
    :param results_dir: the outputs (``--results-dir``); relative: in the working directory
    :param root: the folder the outputs' commands show study paths relative to (default: the working directory)
    :param catalogue: a folder of study files whose claims the index in ``results_dir`` always lists, run or not
    """

    program: str = PROGRAM
    cache_dir: Path = Path("sb3_classic-cache")
    results_dir: Path = Path("studies-results")
    root: Path | None = None
    catalogue: Path | None = None


#: The installed package's: ``./sb3_classic-cache/`` and ``./studies-results/``
INSTALLED = Defaults()


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


def load_studies(
    paths: Sequence[Path], seeds: int | None = None, episodes: int | None = None, steps: int | None = None
) -> tuple[list[StudySpec], list[StudyError]]:
    """
    :param paths: study files and folders of them
    :param seeds: a reduced run's seeds (``StudySpec.with_budget``), if any
    :param episodes: its episode budget, if any
    :param steps: its step budget, if any
    :return: the studies, and the errors of every file that failed (all of them, so that a folder of studies does not
        stop at its first bad file)
    """
    studies, errors = [], []
    try:
        files = study_files(paths)
    except StudyError as error:
        return [], [error]
    reduced = seeds is not None or episodes is not None or steps is not None
    for path in files:
        try:
            study = load_study(path)
            studies.append(study.with_budget(seeds, episodes, steps) if reduced else study)
        except StudyError as error:
            errors.append(error)
    return studies, errors


def main(argv: Sequence[str] | None = None, defaults: Defaults = INSTALLED) -> int:
    """
    The command line (``python -m sb3_classic.studies --help``).

    :param argv: its arguments (default: ``sys.argv[1:]``)
    :param defaults: where it keeps runs and writes outputs, and the command the outputs show
    :return: the exit status
    """
    description = DESCRIPTION.format(
        program=defaults.program, cache=defaults.cache_dir, results=defaults.results_dir, reduced=REDUCED_RESULTS
    )
    parser = argparse.ArgumentParser(
        prog=f"python -m {defaults.program}", description=description, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("studies", nargs="+", type=Path, help="study files (YAML), or folders of them")
    parser.add_argument("--seeds", type=positive_int, help="seeds 0 to K − 1 instead of the files' (a reduced run)")
    parser.add_argument("--episodes", type=positive_int, help="episodes per run instead of the files' budget (a reduced run)")
    parser.add_argument("--steps", type=positive_int, help="env steps per run instead of the files' budget (a reduced run)")
    parser.add_argument(
        "--workers", type=positive_int, default=os.cpu_count() or 1, help="runs in parallel (default: the cores)"
    )
    parser.add_argument(
        "--scheduler", metavar="tcp://HOST:PORT", help="run on the Dask cluster of this scheduler (needs the dask extra)"
    )
    cache_help = f"where finished runs are kept (default {defaults.cache_dir})"
    parser.add_argument("--cache-dir", type=Path, default=defaults.cache_dir, help=cache_help)
    parser.add_argument(
        "--results-dir",
        type=Path,
        help=(
            f"figures, tables and STUDIES.md (default {defaults.results_dir}; reduced runs: "
            f"CACHE_DIR/{REDUCED_RESULTS}/BUDGET)"
        ),
    )
    parser.add_argument(
        "--separate",
        action="store_true",
        help="train every run alone, not the seeds of a setting in lockstep (other cache entries: the two ways draw the "
        "actions from different generators)",
    )
    parser.add_argument("--list", action="store_true", help="list each study's runs and how many are cached; run nothing")
    parser.add_argument("--report-only", action="store_true", help="run nothing: outputs from the runs already cached")
    args = parser.parse_args(argv)
    console = Console()

    reduced = args.seeds is not None or args.episodes is not None or args.steps is not None
    studies, errors = load_studies(args.studies, args.seeds, args.episodes, args.steps)
    if args.separate:
        studies = [dataclasses.replace(study, lockstep=False) for study in studies]
    if errors:
        for error in errors:
            console.print(f"[red]{escape(str(error))}[/red]", highlight=False, soft_wrap=True)
        return 2
    names = [study.name for study in studies]
    duplicates = sorted({name for name in names if names.count(name) > 1})
    if duplicates:
        console.print(f"[red]Two study files have the same name: {escape(', '.join(duplicates))}[/red]", highlight=False)
        return 2
    # The options that change what is run (not --workers, --scheduler, the folders or --report-only, which change
    # where and how, not the results): in the command each study's outputs show, and in a reduced run's folder
    options = {name: getattr(args, name) for name in ("seeds", "episodes", "steps") if getattr(args, name) is not None}
    budget = [item for name, value in options.items() for item in (f"--{name}", str(value))]
    reduced_dir = (
        args.cache_dir
        / REDUCED_RESULTS
        / "_".join([f"{name}-{value}" for name, value in options.items()] + (["separate"] if args.separate else []))
    )
    budget += ["--separate"] if args.separate else []
    results_dir = args.results_dir or (reduced_dir if reduced else defaults.results_dir)

    if args.list:
        for study in studies:
            study_runs = study.runs(sequential.seeds_planned(study))
            recorded = recorded_seeds(study, results_dir)
            cached = sum((run.spec.run_dir(args.cache_dir) / RUN_FILE).exists() for run in study_runs)
            counted = sum(settings_key(run.spec, study) in recorded for run in study_runs)
            seeds = f"{len(study.seeds)} seeds" if study.design is None else study.design.describe()
            console.print(
                f"{study.name}: {len(study.variants)} variants × {len(study.readings)} "
                f"{plural(len(study.readings), 'reading', 'readings')} × {seeds}, "
                f"{study.budget.describe()}: {len(study_runs)} runs{'' if study.design is None else ' at most'}, "
                f"{cached} cached" + (f", {counted} recorded in {study.name}-seeds.csv" if counted else ""),
                highlight=False,
            )
        return 0

    # Look by look: the runs the studies want now (every run of a fixed design; a sequential design's next look), run,
    # then read again, until none is wanted. What a look ran is written before the next starts
    ran, tried = False, set[str]()
    while True:
        try:
            # All read before anything is written: a damaged cache entry names its folder, and no output is half done
            loaded = [load_study_results(study, args.cache_dir, results_dir) for study in studies]
        except DamagedRunError as error:
            console.print(f"[red]{escape(str(error))}[/red]", highlight=False, soft_wrap=True)
            return 2
        pending = [run.spec for results in loaded for run in results.missing]
        # (a run that failed is reported below, not tried again)
        if args.report_only or not {spec.key() for spec in pending} - tried:
            break
        tried |= {spec.key() for spec in pending}
        if ran:
            write_outputs(studies, loaded, results_dir, budget, defaults, reduced, console, quiet=True)
        problems = check_settings(studies, {spec.key() for spec in pending}, console)
        if problems:
            console.print(
                "[red]Nothing was run: rl-zoo3 or the algorithm rejects these settings (fix the study file):\n  "
                + "\n  ".join(escape(problem) for problem in problems)
                + "[/red]",
                highlight=False,
                soft_wrap=True,
            )
            return 2
        for results in loaded:
            if results.study.design is not None and results.missing:
                console.print(f"{results.study.name}: {next_look(results)}", highlight=False)
        start = time.perf_counter()
        n_runs = sum(results.n_runs for results in loaded) + len(pending)
        status = run_missing_runs(n_runs, pending, args.workers, args.cache_dir, console, args.scheduler)
        if status is not None:
            # Interrupted: the runs it finished are recorded in the outputs before it stops
            with contextlib.suppress(DamagedRunError):
                done = [load_study_results(study, args.cache_dir, results_dir) for study in studies]
                write_outputs(studies, done, results_dir, budget, defaults, reduced, console, quiet=True)
            return status
        console.print(f"Runs: {time.perf_counter() - start:.0f} s")
        ran = True
    missing = [run.spec for results in loaded for run in results.missing]
    write_outputs(studies, loaded, results_dir, budget, defaults, reduced, console)
    return report_missing(missing, console, ran=not args.report_only)


def next_look(results: StudyResults) -> str:
    """:return: what a sequential study's next look runs and why, e.g. ``2 claims undecided: 20 runs, to 20 seeds``"""
    undecided = [verdict for verdict in results.looks.values() if not verdict.decided]
    wanted = sorted({verdict.next_seeds for verdict in undecided if verdict.next_seeds})
    to = f", to {', '.join(map(str, wanted))} seeds per variant" if wanted else ""
    count = len(undecided) or len(results.study.claims)
    return f"{count} {plural(count, 'claim', 'claims')} undecided: {len(results.missing)} runs{to}"


def write_outputs(
    studies: Sequence[StudySpec],
    loaded: Sequence[StudyResults],
    results_dir: Path,
    budget: Sequence[str],
    defaults: Defaults,
    reduced: bool,
    console: Console,
    quiet: bool = False,
) -> None:
    """Write each study's outputs and STUDIES.md, and say the verdicts (``quiet``: only where they were written)."""
    # The command each study's outputs show re-runs it from scratch: its file and the budget options
    for study, results in zip(studies, loaded, strict=True):
        path = write_study(results, results_dir, study_command(study, budget, defaults.program, defaults.root), reduced)
        if not quiet:
            print_verdicts(results, console)
        console.print(f"wrote {path}", highlight=False)
    catalogue = list(studies)
    if defaults.catalogue is not None and not reduced and results_dir.resolve() == defaults.results_dir.resolve():
        # The index of the default results lists every claim of the catalogue (the repository's: the seed report's),
        # run or not
        shipped = {study.name for study in catalogue}
        catalogue += [
            study for study in map(load_study, sorted(defaults.catalogue.glob("*.yml"))) if study.name not in shipped
        ]
    index = write_studies_index(catalogue, results_dir, "Studies", defaults.program, defaults.root, budget, reduced)
    console.print(f"wrote {index}", highlight=False)


def print_verdicts(results: StudyResults, console: Console) -> None:
    """
    Say how the study's seeds trained (``outputs.training_summary``), each claim's verdict under each reading, and where
    its variants did not learn (``stats.untrained_note``).
    """
    study = results.study
    console.print(f"{study.name}: {training_summary(study)}", highlight=False, markup=False, soft_wrap=True)
    for reading, judged in results.verdicts.items():
        # (a claim's variants with fewer seeds than any interval needs: its verdict is too close to call, and why)
        found = [len(seeds) for (seeds_reading, _), seeds in results.seeds.items() if seeds_reading == reading]
        too_few = min(found, default=stats.MIN_SEEDS) < stats.MIN_SEEDS
        for result in judged:
            where = "" if len(results.verdicts) == 1 else f" [{reading}]"
            console.print(f"{study.name}{where}: {result.verdict}: {result.claim.text}", highlight=False, markup=False)
            if too_few and result.verdict == stats.TOO_CLOSE:
                console.print(
                    f"  {min(found)} seeds per variant: a verdict needs at least {stats.MIN_SEEDS}",
                    highlight=False,
                    markup=False,
                )
            if result.untrained:
                console.print(f"  not learned: {result.untrained}", highlight=False, markup=False)


def check_settings(studies: Sequence[StudySpec], pending: set[str], console: Console) -> list[str]:
    """
    Build the model of each distinct setting among the runs to run (``check_run``: the envs and the model, no
    training), so that a setting the loader cannot judge (a ``policy_kwargs`` key, an activation's name, an option's
    value) fails before any run starts, not in every run of it.

    :param studies: the studies
    :param pending: the cache keys of the runs to run
    :param console: where to say what is checked
    :return: the problems, each naming the study file, the variant (and reading) and the error
    """
    to_check: dict[tuple[str, str, str], tuple[StudySpec, StudyRun]] = {}
    for study in studies:
        for run in study.runs():
            if run.spec.key() in pending:
                to_check.setdefault((run.spec.algo, run.spec.env_id, run.spec.hyperparams_yaml), (study, run))
    problems = []
    with console.status(f"Checking {len(to_check)} settings (building each model once)"):
        for study, run in to_check.values():
            try:
                check_run(run.spec)
            except RunError as error:
                where = f"variant {run.variant!r}" + ("" if run.reading == STATED else f" under reading {run.reading!r}")
                problems.append(f"{study.path}: {where}: {error}")
    return problems
