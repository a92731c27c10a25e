from sb3_classic.reinforce.lockstep import REINFORCEPopulation
from sb3_classic.reinforce.policies import CnnPolicy, MlpPolicy, MultiInputPolicy
from sb3_classic.reinforce.reinforce import REINFORCE

__all__ = ["REINFORCE", "CnnPolicy", "MlpPolicy", "MultiInputPolicy", "REINFORCEPopulation"]
