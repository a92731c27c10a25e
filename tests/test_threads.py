"""
PyTorch's threads: the package's entry points that train use one on the CPU unless the user chose a number; a model's
own ``learn()`` leaves them to the user's script, as SB3's algorithms do.
"""

from typing import Any

import pytest
import torch as th
from stable_baselines3.common.callbacks import BaseCallback

import sb3_classic.common.threads as threads_module
from sb3_classic import REINFORCE, NStepSARSA
from sb3_classic.reinforce.lockstep import REINFORCEPopulation
from sb3_classic.sarsa.lockstep import NStepSARSAPopulation

POPULATIONS: list[tuple[Any, Any]] = [(NStepSARSA, NStepSARSAPopulation), (REINFORCE, REINFORCEPopulation)]


class Threads(BaseCallback):
    """Records PyTorch's number of threads at every env step."""

    def __init__(self) -> None:
        super().__init__()
        self.counts: set[int] = set()

    def _on_step(self) -> bool:
        self.counts.add(th.get_num_threads())
        return True


@pytest.fixture
def two_threads_unchosen(monkeypatch: pytest.MonkeyPatch) -> Any:
    """Two threads, as PyTorch's default on a 2-core machine, and no choice of the user's."""
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    monkeypatch.delenv("MKL_NUM_THREADS", raising=False)
    monkeypatch.setattr(threads_module, "_STARTING_THREADS", 2)
    before = th.get_num_threads()
    th.set_num_threads(2)
    yield
    th.set_num_threads(before)


@pytest.mark.parametrize(("model_class", "population_class"), POPULATIONS)
def test_a_population_trains_with_one_thread_unless_chosen(
    model_class: Any, population_class: Any, two_threads_unchosen: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Under load, a population with PyTorch's default threads was slower than its members trained one after another
    def members() -> list[Any]:
        return [model_class("MlpPolicy", "CartPole-v1", seed=seed, device="cpu") for seed in (0, 1)]

    callbacks = [Threads(), Threads()]
    population_class(members()).learn(300, callback=callbacks)
    assert [callback.counts for callback in callbacks] == [{1}, {1}]
    assert th.get_num_threads() == 2, "the count before learn() is restored"
    # Chosen by the user: torch.set_num_threads after the import, or the environment
    th.set_num_threads(3)
    callbacks = [Threads(), Threads()]
    population_class(members()).learn(300, callback=callbacks)
    assert [callback.counts for callback in callbacks] == [{3}, {3}]
    th.set_num_threads(2)
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    callbacks = [Threads(), Threads()]
    population_class(members()).learn(300, callback=callbacks)
    assert [callback.counts for callback in callbacks] == [{2}, {2}]


@pytest.mark.parametrize("model_class", [NStepSARSA, REINFORCE])
def test_a_models_learn_leaves_the_threads_to_the_user(model_class: Any, two_threads_unchosen: None) -> None:
    callback = Threads()
    model_class("MlpPolicy", "CartPole-v1", seed=0, device="cpu").learn(300, callback=callback)
    assert callback.counts == {2}
