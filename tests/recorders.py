"""Callbacks that keep what the rollout loop sees at every step (for the tests of several files)."""

from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback


class RecordLocal(BaseCallback):
    """Keeps a variable of the rollout loop at every step (``self.locals[name]``)."""

    def __init__(self, name: str) -> None:
        super().__init__()
        self.name = name
        self.values: list[Any] = []

    def _on_step(self) -> bool:
        self.values.append(np.copy(self.locals[self.name]))
        return True


class RecordAttribute(RecordLocal):
    """Keeps an attribute of the model at every step."""

    def _on_step(self) -> bool:
        self.values.append(getattr(self.model, self.name))
        return True
