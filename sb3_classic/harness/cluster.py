"""
The runs on a Dask cluster: ``--scheduler tcp://HOST:PORT`` of ``python -m sb3_classic.studies`` (and of the
repository's ``python -m benchmarks.run``).

Imported only with ``--scheduler`` (Dask is the optional ``dask`` extra). Each run trains on a worker in a
temporary folder and comes back to the client as the contents of its files (``RunResult``); the client writes the
cache, so the workers need no shared filesystem, and no checkout of the repository: a run is a ``RunSpec`` (its
hyperparameters travel in it) trained by this package's ``runner``. Workers must run the client's versions of the
libraries, of ``sb3_classic``'s algorithms and of this harness (``sb3_classic/harness/``): they are checked before
anything is submitted, and again by each run.
"""

import hashlib
import platform
import queue
from collections.abc import Iterator, Sequence
from concurrent.futures import Future
from contextlib import contextmanager
from pathlib import Path

from distributed import Client, get_worker
from rich.console import Console

from sb3_classic.harness.common import RunSpec, code_versions
from sb3_classic.harness.runner import ClusterError, RunError, RunResult, execute_population, execute_run

#: The topic of the workers' progress events (``[run name, env steps, worker address]``), which the client subscribes to
PROGRESS_TOPIC = "sb3-classic-benchmark-progress"
#: Seconds to wait for the scheduler to answer
CONNECT_TIMEOUT_S = 20
_VERSIONS_FIX = "install the client's versions there (the same release or commit of sb3_classic) and restart the worker"
#: What a worker needs (the client too, with the dask extra)
_WORKER_INSTALL = "pip install 'sb3_classic[zoo,dask]' (the client's version; from a checkout: pip install -e '.[zoo,dask]')"


def harness_digest() -> str:
    """
    :return: a digest of the harness's sources (``sb3_classic/harness/*.py``): how a run is built, evaluated and
        recorded. The study runner (``sb3_classic/studies``) runs on the client only, and is not part of it.
    """
    folder = Path(__file__).resolve().parent
    digest = hashlib.sha256()
    for source in sorted(folder.glob("*.py")):
        digest.update(source.name.encode())
        digest.update(source.read_bytes())
    return digest.hexdigest()[:12]


def worker_versions() -> dict[str, str]:
    """
    :return: what a run's result depends on besides its settings, in this process: the libraries and
        ``sb3_classic`` (``code_versions``) and the harness (``harness_digest``)
    """
    return {**code_versions("reinforce"), "sb3_classic harness": harness_digest()}


def version_differences(expected: dict[str, str], found: dict[str, str]) -> list[str]:
    """
    :param expected: the client's versions (``worker_versions``)
    :param found: a worker's
    :return: one ``"name: X on the client, Y on the worker"`` per difference
    """
    return [
        f"{name}: {version} on the client, {found.get(name, 'missing')} on the worker"
        for name, version in expected.items()
        if found.get(name) != version
    ]


class WorkerProgress:
    """
    Where a run on a Dask worker reports its progress: events of ``PROGRESS_TOPIC``, pushed to the subscribed client
    through the scheduler.
    """

    def put(self, obj: tuple[str, int]) -> None:
        """:param obj: the run's name and its env steps so far (sent with the worker's address)"""
        worker = get_worker()
        worker.log_event(PROGRESS_TOPIC, [*obj, worker.address])


def run_on_worker(spec: RunSpec, expected: dict[str, str]) -> RunResult:
    """
    The task of one run on a Dask worker: ``execute_run`` after checking the worker's versions.

    :param spec: the run
    :param expected: the client's ``worker_versions()``
    :return: the run's summary and files
    :raise ClusterError: if the worker's versions differ from the client's (the run is not trained)
    """
    return execute_run(spec, WorkerProgress(), _checked_worker(expected))


def run_population_on_worker(specs: Sequence[RunSpec], expected: dict[str, str]) -> list[RunResult | RunError]:
    """
    The task of a population (the lockstep runs of one setting) on a Dask worker: ``execute_population`` after
    checking the worker's versions.

    :param specs: the runs
    :param expected: the client's ``worker_versions()``
    :return: each run's result or error
    :raise ClusterError: if the worker's versions differ from the client's (nothing is trained)
    """
    return execute_population(specs, WorkerProgress(), _checked_worker(expected))


def _checked_worker(expected: dict[str, str]) -> str:
    """
    :param expected: the client's ``worker_versions()``
    :return: this worker's name for messages, once its versions are the client's
    :raise ClusterError: if they differ
    """
    worker = get_worker()
    host = f"{platform.node()} (Dask worker {worker.address})"
    differences = version_differences(expected, worker_versions())
    if differences:
        raise ClusterError(f"{host} has other versions than the client ({'; '.join(differences)}): {_VERSIONS_FIX}")
    return host


class DaskRuns:
    """
    Runs on a Dask cluster, through its ``concurrent.futures`` interface.

    :param client: the connected client
    :param expected: the versions every worker must have (the client's ``worker_versions()``)
    """

    def __init__(self, client: Client, expected: dict[str, str]):
        self.expected = expected
        #: The progress events of the runs, ``(run name, env steps)``
        self.progress: queue.Queue[tuple[str, int]] = queue.Queue()
        # Called in the client's event-loop thread with (timestamp, [name, steps]); a queue.Queue is thread-safe
        client.subscribe_topic(PROGRESS_TOPIC, lambda event: self.progress.put((event[1][0], event[1][1])))
        # pure=False: a run submitted twice (the command run twice at once) is two tasks, not one shared result
        self.executor = client.get_executor(pure=False)

    def submit(self, spec: RunSpec) -> "Future[RunResult]":
        """:return: the future of ``spec`` run on a worker"""
        return self.executor.submit(run_on_worker, spec, self.expected)

    def submit_population(self, specs: Sequence[RunSpec]) -> "Future[list[RunResult | RunError]]":
        """:return: the future of the lockstep runs ``specs`` of one setting, trained together on one worker"""
        return self.executor.submit(run_population_on_worker, specs, self.expected)

    def cancel(self) -> None:
        """Cancel the runs not finished (a run being trained finishes on its worker, unused)."""
        self.executor.shutdown(wait=False)


@contextmanager
def connect(address: str, console: Console) -> Iterator[DaskRuns]:
    """
    Connect to the scheduler at ``address``, wait for a worker if there is none, and check the workers' versions.

    :param address: the scheduler, ``tcp://HOST:PORT``
    :param console: where to say what the cluster is
    :return: the runs' submitter, valid until the context exits (which closes the client)
    :raise ClusterError: if no scheduler answers, or a worker cannot run the harness or has other versions
    """
    try:
        client = Client(address, timeout=CONNECT_TIMEOUT_S, set_as_default=False)
    except (OSError, ValueError, TypeError) as error:
        raise ClusterError(
            f"--scheduler {address}: no Dask scheduler answered ({error}): start one with `dask scheduler` and give "
            "the address it prints, e.g. tcp://10.0.0.1:8786"
        ) from error
    try:
        if not client.nthreads():
            command = f"python -m dask worker {address} --nthreads 1"
            console.print(
                f"Waiting for a worker: start some with `{command}` where sb3_classic is installed ({_WORKER_INSTALL})",
                highlight=False,
            )
            client.wait_for_workers(1)
        expected = worker_versions()
        check_workers(client, expected, address)
        threads = client.nthreads()
        console.print(f"Dask cluster at {address}: {len(threads)} workers, {sum(threads.values())} threads (runs in parallel)")
        yield DaskRuns(client, expected)
    finally:
        client.close()


def check_workers(client: Client, expected: dict[str, str], address: str) -> None:
    """
    :param client: a connected client
    :param expected: the client's ``worker_versions()``
    :param address: its scheduler's, for messages
    :raise ClusterError: naming each worker that cannot run the harness or whose versions differ, and the fix
    """
    replies = client.run(worker_versions, on_error="return")
    problems = []
    for worker, reply in sorted(replies.items()):
        if isinstance(reply, BaseException):
            problems.append(f"worker {worker} cannot run the harness ({reply!r}): install it there: {_WORKER_INSTALL}")
        elif differences := version_differences(expected, reply):
            problems.append(f"worker {worker}: {'; '.join(differences)}")
    if problems:
        raise ClusterError(
            f"--scheduler {address}: workers refused (a run trained there would not be the run its "
            "cache key names):\n  " + "\n  ".join(problems) + f"\nFix: {_VERSIONS_FIX}, or stop it."
        )
