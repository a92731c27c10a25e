"""
What both algorithms' policies share: acting in the env's own action values.

Gymnasium's ``Discrete(n, start=s)`` holds the actions s, …, s + n − 1 and ``MultiDiscrete(nvec, start=...)`` offsets
each dimension. The networks, the buffer and the losses work with indices 0, …, n − 1 (an index selects a logit or a
Q-value); everything that hands an action to an env or to the user adds the space's ``start``: the rollout loop,
``predict`` (and so SB3's ``evaluate_policy``, ``EvalCallback`` and the zoo's ``enjoy``) and ε-greedy draws. SB3's own
policies do not (they assume ``start=0``), hence this module.
"""

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.torch_layers import CombinedExtractor, FlattenExtractor, NatureCNN
from stable_baselines3.common.type_aliases import PyTorchObs
from stable_baselines3.dqn.policies import QNetwork
from torch import nn

from sb3_classic.common.masking import check_action_masks
from sb3_classic.common.tile_coding import TileCoding

#: Modules whose forward pass is the same in train and eval mode (``nn.Module.train``), by exact class: a subclass (a
#: NoisyNet layer subclassing ``nn.Linear``, say) may read ``self.training``. With torch's activations (but
#: ``MODE_DEPENDENT_ACTIVATIONS``), what SB3's and this package's networks are built of
MODE_INDEPENDENT_MODULES = (
    nn.Linear,
    nn.Conv2d,
    nn.LayerNorm,
    nn.Flatten,
    nn.Identity,
    nn.Sequential,
    nn.ModuleList,
    nn.ModuleDict,
    QNetwork,
    FlattenExtractor,
    NatureCNN,
    CombinedExtractor,
    TileCoding,
)

#: The classes of ``torch.nn.modules.activation`` that compute otherwise in train mode: RReLU draws its slopes at
#: random, MultiheadAttention has dropout
MODE_DEPENDENT_ACTIVATIONS = (nn.RReLU, nn.MultiheadAttention)


def mode_dependent(module: nn.Module) -> bool:
    """
    :param module: a network
    :return: whether its forward pass may differ between train and eval mode: some module in it is not one of
        ``MODE_INDEPENDENT_MODULES`` or torch's activations (dropout, batch norm, a user's layer or features extractor,
        which may read ``self.training``)
    """
    for submodule in module.modules():
        kind = type(submodule)
        activation = kind.__module__ == "torch.nn.modules.activation" and kind not in MODE_DEPENDENT_ACTIVATIONS
        if kind not in MODE_INDEPENDENT_MODULES and not activation:
            return True
    return False


def action_offset(action_space: spaces.Space) -> np.ndarray | None:
    """
    :param action_space: an action space
    :return: the env's action value of index 0 (``start`` of a ``Discrete`` or ``MultiDiscrete`` space, scalar or
        shape (n_dims,), int64), or None where there is no offset (a zero ``start``, or any other space)
    """
    if isinstance(action_space, (spaces.Discrete, spaces.MultiDiscrete)):
        start = np.asarray(action_space.start, dtype=np.int64)
        if start.any():
            return start
    return None


class EnvActionsMixin:
    """
    Makes a policy's ``predict`` return the env's action values: index + ``start`` for ``Discrete`` and
    ``MultiDiscrete`` spaces with an offset (see the module docstring); other spaces are unchanged.
    Put it before the SB3 policy class in the bases.
    """

    action_space: spaces.Space

    def predict(
        self,
        observation: np.ndarray | dict[str, np.ndarray],
        state: tuple[np.ndarray, ...] | None = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = False,
        action_masks: np.ndarray | None = None,
    ) -> tuple[np.ndarray, tuple[np.ndarray, ...] | None]:
        """
        SB3's ``BasePolicy.predict``, in the env's action values, with sb3-contrib's ``action_masks`` (as
        ``MaskableActorCriticPolicy.predict`` takes them).

        :param observation: the input observation (one, or a batch)
        :param state: unused (no recurrent policy)
        :param episode_start: unused (no recurrent policy)
        :param deterministic: whether to return the most likely action
        :param action_masks: the legal actions of each observation, shape (batch, mask_size) or (mask_size,) for one
            (see ``sb3_classic.common.masking``); None: every action is legal
        :return: the actions, as the env takes them, and the unchanged state
        """
        if action_masks is None:
            actions, state = BasePolicy.predict(self, observation, state, episode_start, deterministic)  # type: ignore[arg-type]
        else:
            actions = self._masked_predict(observation, deterministic, action_masks)
        offset = action_offset(self.action_space)
        if offset is not None:
            actions = actions + offset
        return actions, state

    def _masked_predict(
        self, observation: np.ndarray | dict[str, np.ndarray], deterministic: bool, action_masks: np.ndarray
    ) -> np.ndarray:
        """
        ``BasePolicy.predict`` with masks, as sb3-contrib's ``MaskableActorCriticPolicy.predict`` (whose ``_predict``
        takes them); here the policy's ``_predict_masked`` does.

        :return: the actions as indices, shape (batch, *action_shape), or action_shape for one observation
        """
        policy: BasePolicy = self  # type: ignore[assignment]
        policy.set_training_mode(False)
        obs_tensor, vectorized_env = policy.obs_to_tensor(observation)
        first = next(iter(obs_tensor.values())) if isinstance(obs_tensor, dict) else obs_tensor
        masks = check_action_masks(action_masks, len(first), self.action_space)
        with th.no_grad():
            actions_tensor = self._predict_masked(obs_tensor, deterministic, masks)
        assert self.action_space.shape is not None
        actions: np.ndarray = actions_tensor.cpu().numpy().reshape((-1, *self.action_space.shape))
        if not vectorized_env:
            actions = actions.squeeze(axis=0)
        return actions

    def _predict_masked(self, observation: PyTorchObs, deterministic: bool, action_masks: np.ndarray) -> th.Tensor:
        """
        :param observation: the observations, as tensors
        :param deterministic: whether to take the most likely actions
        :param action_masks: the legal actions of each, shape (batch, mask_size), boolean
        :return: the actions, as indices
        """
        raise NotImplementedError(f"{type(self).__name__} takes no action masks")
