from sb3_classic.sarsa.nstep_sarsa import NStepSARSA
from sb3_classic.sarsa.policies import CnnPolicy, MlpPolicy, MultiInputPolicy

__all__ = ["CnnPolicy", "MlpPolicy", "MultiInputPolicy", "NStepSARSA"]
