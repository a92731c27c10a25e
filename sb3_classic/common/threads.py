"""
PyTorch's intra-op threads for these algorithms' small networks: one on the CPU unless the user chose a number.

The networks are small (two layers of 64 to 256 units, a batch of one to a few hundred rows) and take a gradient step
every few env steps: PyTorch's threads cost more to wake than they save, and on a machine with other work running each
of those steps waits for a busy core (``benchmarks/results/threads.md`` has the measurement). The package's own entry
points that train (the zoo's commands, populations, the study runner, the benchmarks) use one thread; a model's
``learn()`` leaves the threads to the user's script, as SB3's algorithms do.
"""

import os
from collections.abc import Iterator
from contextlib import contextmanager

import torch as th
from stable_baselines3.common.utils import get_device

#: PyTorch's number of intra-op threads when the package was imported: another one later was the user's choice
_STARTING_THREADS = th.get_num_threads()


def threads_chosen() -> bool:
    """
    :return: whether the user chose PyTorch's number of threads: ``OMP_NUM_THREADS`` or ``MKL_NUM_THREADS`` in the
        environment, or a call of ``torch.set_num_threads`` since the package was imported
    """
    return "OMP_NUM_THREADS" in os.environ or "MKL_NUM_THREADS" in os.environ or th.get_num_threads() != _STARTING_THREADS


@contextmanager
def one_thread_unless_chosen(device: th.device | str) -> Iterator[bool]:
    """
    One PyTorch thread while the context lasts, on the CPU and unless the user chose a number (``threads_chosen``);
    the number before it afterwards.

    :param device: the device the networks train on (another than the CPU: nothing changes)
    :return: (as the context's value) whether it set one thread
    """
    if threads_chosen() or get_device(device).type != "cpu":
        yield False
        return
    threads = th.get_num_threads()
    th.set_num_threads(1)
    try:
        yield True
    finally:
        th.set_num_threads(threads)
