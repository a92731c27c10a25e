"""
Where the runs train, with a progress display: a local pool of processes, or a Dask cluster (``--scheduler``,
``cluster``, imported only then). ``run_pending`` runs what is not cached and writes each finished run into the
cache; ``report_missing`` names the runs that are still not there.
"""

import multiprocessing
import queue
import signal
import threading
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from contextlib import AbstractContextManager, contextmanager
from pathlib import Path
from typing import Any, Protocol

from rich.console import Console
from rich.markup import escape
from rich.progress import (
    BarColumn,
    Progress,
    TaskID,
    TaskProgressColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

from sb3_classic.harness.common import RunSpec, code_versions
from sb3_classic.harness.lockstep import lockstep_jobs
from sb3_classic.harness.runner import (
    ClusterError,
    RunError,
    RunResult,
    init_worker,
    run_in_worker,
    run_population_in_worker,
    store_failure,
    store_run,
)

#: Seconds between two readings of the runs' progress reports: the bars move as the runs train (the rate of rich's
#: display), and not only when a run ends
POLL_SECONDS = 0.1


class ProgressSource(Protocol):
    """A ``multiprocessing.Queue`` or a ``queue.Queue``."""

    def get_nowait(self) -> tuple[str, int]:
        """:return: the next report; :raise queue.Empty: if there is none"""


class Runs(Protocol):
    """Where the runs train: the local process pool (``PoolRuns``) or a Dask cluster (``cluster.DaskRuns``)."""

    @property
    def progress(self) -> ProgressSource:
        """The runs' progress reports, ``(run name, env steps)``."""

    def submit(self, spec: RunSpec) -> "Future[RunResult]":
        """:return: the future of ``spec``'s ``RunResult``"""

    def submit_population(self, specs: Sequence[RunSpec]) -> "Future[list[RunResult | RunError]]":
        """:return: the future of the results of the lockstep runs ``specs`` of one setting, trained together"""

    def cancel(self) -> None:
        """Cancel the runs not started, and stop those running where it can."""


class PoolRuns:
    """
    Runs in a local pool of processes (spawned: each run gets a fresh interpreter).

    :param pool: the pool, whose processes report progress to ``progress`` (``init_worker``)
    :param progress: their queue
    """

    def __init__(self, pool: ProcessPoolExecutor, progress: ProgressSource):
        self.pool = pool
        self.progress = progress

    def submit(self, spec: RunSpec) -> "Future[RunResult]":
        """:return: the future of ``spec``'s ``RunResult``"""
        # The versions now, the command's (cached from its start): a worker started after an edit of the package's
        # sources refuses the run before training it, instead of store_run refusing its result after
        return self.pool.submit(run_in_worker, spec, code_versions(spec.algo))

    def submit_population(self, specs: Sequence[RunSpec]) -> "Future[list[RunResult | RunError]]":
        """:return: the future of the results of the lockstep runs ``specs`` of one setting, trained in one process"""
        return self.pool.submit(run_population_in_worker, specs, code_versions(specs[0].algo))

    def cancel(self) -> None:
        """Cancel the runs not started, and stop those running (the finished ones are cached already)."""
        # Without stopping them, the pool's exit would wait for the running runs to end (minutes): a Ctrl-C reaches
        # the workers no more (init_worker). Python 3.14 has ProcessPoolExecutor.terminate_workers; before, the
        # processes are only in _processes, which shutdown() empties
        terminate = getattr(self.pool, "terminate_workers", None)
        if terminate is not None:
            terminate()
            return
        processes = list((getattr(self.pool, "_processes", None) or {}).values())
        self.pool.shutdown(wait=False, cancel_futures=True)
        for process in processes:
            process.terminate()


@contextmanager
def local_runs(workers: int) -> Iterator[PoolRuns]:
    """:param workers: the number of processes"""
    context = multiprocessing.get_context("spawn")
    progress_queue = context.Queue()
    with ProcessPoolExecutor(workers, mp_context=context, initializer=init_worker, initargs=(progress_queue,)) as pool:
        yield PoolRuns(pool, progress_queue)


def open_runs(workers: int, scheduler: str | None, console: Console) -> AbstractContextManager[Runs]:
    """
    :param workers: the processes of the local pool
    :param scheduler: a Dask scheduler's address (``tcp://HOST:PORT``), or None for the local pool
    :param console: where to say what the cluster is
    :return: where the runs train, as a context
    :raise ClusterError: if Dask is not installed, or the cluster cannot run the runs
    """
    if scheduler is None:
        return local_runs(workers)
    try:
        # Dask is optional, and imported only here
        from sb3_classic.harness import cluster
    except ModuleNotFoundError as error:
        if error.name not in ("dask", "distributed"):
            raise
        message = f"--scheduler {scheduler}: Dask is not installed ({error}): pip install 'sb3_classic[zoo,dask]'"
        raise ClusterError(message) from error
    return cluster.connect(scheduler, console)


def run_pending(
    specs: Sequence[RunSpec], workers: int, cache_dir: Path, console: Console, scheduler: str | None = None
) -> list[RunSpec]:
    """
    Run ``specs`` in a pool of ``workers`` processes, or on the Dask cluster of ``scheduler``, showing the progress of
    each and of all. Every run comes back as a ``RunResult``, which this process writes into the cache.

    :param specs: the runs
    :param workers: the processes of the local pool (without ``scheduler``)
    :param cache_dir: the cache root
    :param console: where to show the progress
    :param scheduler: a Dask scheduler's address (``tcp://HOST:PORT``), or None for the local pool
    :return: the runs that failed (their errors are printed, and they are not cached)
    :raise ClusterError: if the cluster of ``scheduler`` cannot run the runs (nothing was run)
    """
    if not specs:
        return []
    failed = []
    # The bars are in env steps, or for a run with an episode budget in its share of its step cap (ProgressCallback): a
    # percentage of the budget, not a count of steps
    columns = (TextColumn("{task.description}"), BarColumn(), TaskProgressColumn(), TimeElapsedColumn(), TimeRemainingColumn())
    with open_runs(workers, scheduler, console) as runs, Progress(*columns, console=console) as progress:
        # Over every run's env steps (or share of its episode budget): it moves as the runs train, and its time remaining
        # is rich's estimate from that speed. Until the first run starts training, the workers build the models
        description = f"{len(specs)} runs"
        overall = progress.add_task(
            f"{description} (starting: building the models)", total=sum(spec.n_timesteps for spec in specs)
        )
        # A run trained alone is a job of its own; the lockstep runs of a setting one job, a population
        futures: dict[Future[Any], tuple[RunSpec, ...]] = {
            (runs.submit(job[0]) if len(job) == 1 and not job[0].lockstep else runs.submit_population(job)): job
            for job in lockstep_jobs(specs)
        }
        by_name = {spec.name: spec for spec in specs}
        tasks: dict[str, TaskID] = {}
        steps = dict.fromkeys(by_name, 0)
        finished: set[str] = set()

        def show(name: str, num_timesteps: int) -> None:
            if not tasks and not finished:
                progress.update(overall, description=description)
            # A run started again (its Dask worker died) goes back: the overall bar with it
            completed = min(num_timesteps, by_name[name].n_timesteps)
            progress.advance(overall, completed - steps[name])
            steps[name] = completed
            if name in finished:
                progress.remove_task(tasks.pop(name))
            elif name not in tasks:
                tasks[name] = progress.add_task(escape(name), total=by_name[name].n_timesteps, completed=completed)
            else:
                progress.update(tasks[name], completed=completed)

        pending = set(futures)
        try:
            while pending:
                done, pending = wait(pending, timeout=POLL_SECONDS, return_when=FIRST_COMPLETED)
                while True:
                    try:
                        name, num_timesteps = runs.progress.get_nowait()
                    except queue.Empty:
                        break
                    if name in by_name and name not in finished:
                        show(name, num_timesteps)
                for future in done:
                    job = futures[future]
                    for member, spec in enumerate(job):
                        finished.add(spec.name)
                        if spec.name in tasks:
                            show(spec.name, spec.n_timesteps)
                        else:
                            progress.advance(overall, spec.n_timesteps - steps[spec.name])
                        result = _job_result(future, member, alone=len(job) == 1 and not spec.lockstep)
                        message = _store(spec, result, cache_dir)
                        if message is None:
                            progress.console.print(f"done: {spec.name}", markup=False, highlight=False)
                        else:
                            failed.append(spec)
                            failure = f"[red]failed: {escape(spec.name)}: {message}[/red]"
                            progress.console.print(failure, markup=True, highlight=False)
        except KeyboardInterrupt:
            runs.cancel()
            raise
    return failed


def run_missing_runs(
    n_runs: int,
    pending: Sequence[RunSpec],
    workers: int,
    cache_dir: Path,
    console: Console,
    scheduler: str | None = None,
) -> int | None:
    """
    ``run_pending`` for a command line: say what is cached and where the rest runs, and turn an interruption or a
    cluster error into a message and an exit status.

    :param n_runs: how many runs the command has, cached or not
    :param pending: those not cached yet
    :param workers: processes of the local pool
    :param cache_dir: the cache
    :param console: where to print
    :param scheduler: a Dask scheduler's address, or None for the local pool
    :return: None when the runs are done, else the exit status to stop with (130 interrupted by Ctrl-C, 143 by SIGTERM
        (``timeout``, a cluster job's time limit), 2 cluster error)
    """
    where = f"the Dask cluster at {scheduler}" if scheduler else f"{workers} worker{'s' if workers != 1 else ''}"
    # Runs of the same settings (a variant under two readings, two study files) share one cache entry: each is run once
    by_key: dict[str, RunSpec] = {}
    for spec in pending:
        by_key.setdefault(spec.key(), spec)
    distinct = list(by_key.values())
    shared = f" ({len(pending) - len(distinct)} of them the same runs as others)" if len(distinct) < len(pending) else ""
    console.print(f"{n_runs} runs: {n_runs - len(pending)} cached, {len(distinct)} to run on {where}{shared}")
    pending = distinct
    try:
        with _sigterm_as_interrupt() as terminated:
            run_pending(pending, workers, cache_dir, console, scheduler)
    except KeyboardInterrupt:
        how = "Terminated (SIGTERM)" if terminated.is_set() else "Interrupted"
        console.print(f"{how}: the finished runs are cached; run the same command again to resume.")
        return 143 if terminated.is_set() else 130
    except ClusterError as error:
        console.print(f"[red]{escape(str(error))}[/red]", highlight=False)
        return 2
    return None


@contextmanager
def _sigterm_as_interrupt() -> Iterator[threading.Event]:
    """
    SIGTERM (``timeout``, a batch scheduler's time limit) stops the runs as Ctrl-C does: the pool is cancelled, the
    finished runs stay cached, and the command says so (its default action killed the process without a word, and
    left the pool's semaphores behind). In the main thread only, where Python runs signal handlers.

    :return: an event set if SIGTERM came
    """
    terminated = threading.Event()
    if threading.current_thread() is not threading.main_thread():
        yield terminated
        return

    def interrupt(signum: int, frame: object) -> None:
        terminated.set()
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, interrupt)
    try:
        yield terminated
    finally:
        signal.signal(signal.SIGTERM, previous)


def _job_result(future: "Future[Any]", member: int, alone: bool) -> Callable[[], RunResult]:
    """
    :param future: a job's: a run's ``RunResult``, or the results of a population's runs (``submit_population``)
    :param member: the run's place in the job
    :param alone: whether the job is a run trained alone
    :return: a function that returns the run's result or raises its error
    """

    def result() -> RunResult:
        outcome = future.result()
        if alone:
            return outcome
        member_outcome = outcome[member]
        if isinstance(member_outcome, RunError):
            raise member_outcome
        assert isinstance(member_outcome, RunResult)
        return member_outcome

    return result


def _store(spec: RunSpec, result: Callable[[], RunResult], cache_dir: Path) -> str | None:
    """
    Write the finished run into the cache.

    :param spec: the run
    :param result: returns its result, or raises why it has none
    :param cache_dir: the cache root
    :return: None, or why the run failed (its error; where its log was kept)
    """
    try:
        store_run(spec, cache_dir, result())
    except RunError as error:
        return f"{escape(str(error))} (its log: {escape(str(store_failure(spec, cache_dir, error.log)))})"
    except Exception as error:
        # Raised in the worker, or by Dask (KilledWorker: its workers died; CancelledError: the cluster went away),
        # or by store_run (other versions)
        if "Cancelled" in type(error).__name__:
            return escape(
                f"{type(error).__name__}: the Dask cluster dropped it (its scheduler or this client's connection went "
                "away); the finished runs are cached: run the same command again to run the rest"
            )
        return escape(f"{type(error).__name__}: {error}")
    return None


def report_missing(missing: Sequence[RunSpec], console: Console, ran: bool = True) -> int:
    """
    Whatever happened to them (errors, dead workers), the runs not in the cache are named, never left out quietly.

    :param missing: the runs of the command not in the cache
    :param console: where to name them
    :param ran: whether the command ran its missing runs (False: a report from the cache alone, which runs nothing)
    :return: the command's exit status: 1 if any is missing
    """
    if not missing:
        return 0
    names = ", ".join(spec.name for spec in missing)
    what = "failed" if ran else "not run yet (this command runs nothing: run it without --report-only)"
    console.print(f"[red]{len(missing)} runs {what}, not in the cache: {escape(names)}[/red]", highlight=False, soft_wrap=True)
    return 1
