from sb3_classic.sarsa.lockstep import NStepSARSAPopulation
from sb3_classic.sarsa.nstep_sarsa import NStepSARSA
from sb3_classic.sarsa.policies import CnnPolicy, LinearPolicy, MlpPolicy, MultiInputPolicy

__all__ = ["CnnPolicy", "LinearPolicy", "MlpPolicy", "MultiInputPolicy", "NStepSARSA", "NStepSARSAPopulation"]
