"""REINFORCE with baseline and episodic semi-gradient n-step SARSA as Stable-Baselines3 algorithms."""

# PyTorch's thread count at import: a later change is the user's choice, which the package's entry points keep
import sb3_classic.common.threads

# Registers the book's example envs with Gymnasium (sb3_classic/ShortCorridor-v0, RandomWalk19-v0, MountainCarNoLimit-v0)
import sb3_classic.envs  # noqa: F401
from sb3_classic.common.obgd import ObGD
from sb3_classic.common.tile_coding import TileCoding
from sb3_classic.reinforce import REINFORCE
from sb3_classic.sarsa import NStepSARSA

__version__ = "0.1.0"

__all__ = ["REINFORCE", "NStepSARSA", "ObGD", "TileCoding", "__version__"]
