"""
Schedules driven by a count (completed episodes or gradient updates) rather than by SB3's training progress.

SB3 schedules (``FloatSchedule``, ``LinearSchedule``) map the remaining progress of the current ``learn()`` call
to a value. The seed report decays the learning rate and ε per *episode*, which is training state: these classes
are pure functions of a count that the algorithm keeps (and saves), so ``save``/``load`` and ``learn()`` called
again continue them where they stopped. Like SB3's, they are classes (picklable with ``weights_only=True``).
"""

from collections.abc import Sequence


class StepDecay:
    """
    Learning-rate multiplier that drops by ``factor`` every ``every`` counts (PyTorch's ``StepLR``), or at each of
    the ``milestones`` (``MultiStepLR``). The algorithm multiplies its learning-rate schedule by this.

    :param factor: multiplicative decay applied at each step (1.0: no decay)
    :param every: decay every ``every`` counts
    :param milestones: decay when the count reaches each of these (instead of ``every``)
    """

    def __init__(self, factor: float = 1.0, every: int | None = None, milestones: Sequence[int] | None = None) -> None:
        self.factor = factor
        self.every = every
        self.milestones = sorted(milestones) if milestones is not None else None

    def n_decays(self, count: int) -> int:
        """
        :param count: completed episodes or updates
        :return: how many decays have happened by ``count``
        """
        if self.every is not None:
            return count // self.every
        if self.milestones is not None:
            return sum(count >= milestone for milestone in self.milestones)
        return 0

    def __call__(self, count: int) -> float:
        return self.factor ** self.n_decays(count)

    def __repr__(self) -> str:
        return f"StepDecay(factor={self.factor}, every={self.every}, milestones={self.milestones})"


class ExponentialDecay:
    """
    ε ← max(ε_final, ε · k) once per completed episode, as in the seed report: ε(count) = max(end, start · k^count).

    :param start: value at count 0
    :param end: floor the value never goes below
    :param decay_rate: the factor k applied per count, in (0, 1]
    """

    def __init__(self, start: float, end: float, decay_rate: float) -> None:
        self.start = start
        self.end = end
        self.decay_rate = decay_rate

    def __call__(self, count: int) -> float:
        return max(self.end, self.start * self.decay_rate**count)

    def __repr__(self) -> str:
        return f"ExponentialDecay(start={self.start}, end={self.end}, decay_rate={self.decay_rate})"
