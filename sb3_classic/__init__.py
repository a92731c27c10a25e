"""REINFORCE with baseline and episodic semi-gradient n-step SARSA as Stable-Baselines3 algorithms."""

from sb3_classic.reinforce import REINFORCE
from sb3_classic.sarsa import NStepSARSA

__version__ = "0.1.0"

__all__ = ["REINFORCE", "NStepSARSA", "__version__"]
