"""
Tile coding (Sutton & Barto §9.5.4) as a Stable-Baselines3 features extractor, and the pure functions it is made of.

The tilings are those of Sutton's ``tiles3.py``, the software of the footnote to the book's Example 10.1 (Mountain
Car). Each observation dimension d is first clipped to its range and scaled to tile widths:

    f_d = tiles_per_dim_d · (clip(x_d, low_d, high_d) − origin_d) / (high_d − low_d),

with ``origin = low`` by default (``origin="zero"``: 0, the book's footnote). Then, as ``tiles3.tiles(None,
n_tilings, f)`` computes it, tiling t (0 ≤ t < n_tilings) puts the observation in the tile of integer coordinates

    q_d = ⌊f_d · n_tilings⌋,    c_{t,d} = ⌊(q_d + t·(2d + 1)) / n_tilings⌋,

that is, tiling t is displaced from tiling 0 by t·(1, 3, 5, …)/n_tilings of a tile width: the book's asymmetric
offsets by the first odd integers (§9.5.4, p. 219–220, after Miller and Glanz 1996). These coordinates are
``tile_coordinates``. ``tile_indices`` turns them into one index per tiling:

- without hashing (``hash_size=None``), the exact dense index: tiling t owns the ``tiles_per_tiling`` indices from
  t·tiles_per_tiling, and the tile is found there in C order of its coordinates counted from the tiling's first tile
  that meets the range. With ``origin="low"`` each tiling meets ``tiles_per_dim + 1`` tiles along each dimension (the
  displaced tilings need one more tile to cover the range), so there are n_tilings × Π(tiles_per_dim + 1) features;
- with ``hash_size``, a deterministic hash of (t, c_{t,0}, c_{t,1}, …) modulo ``hash_size``, like ``tiles3``'s
  ``hashcoords(coords, hash_size)`` (see ``hash_tiles`` for why not an ``IHT``).
"""

import math
import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

from sb3_classic.common.utils import check_choice, check_positive_int

#: ``origin`` choices: tile boundaries of tiling 0 at ``low`` (n_tilings × Π(tiles_per_dim + 1) dense features) or at
#: 0, as ``tiles3`` on floats tiles_per_dim·x/(high − low) places them (the book's footnote for Mountain Car)
ORIGINS = ("low", "zero")

# The hash of hash_tiles: FNV-1's multiply-xor step (32-bit FNV prime and offset basis) modulo the Mersenne prime
# 2^31 − 1, in int64 without overflow (every product is below 2^31 · 2^25).
HASH_MODULUS = 2**31 - 1
#: The most dense features (``hash_size=None``) a tile coder builds: 2^24, a 64 MiB float32 row; more needs hash_size
MAX_DENSE_FEATURES = 2**24
#: Above this many dense features (2^20), a tile coder warns: a forward pass over them takes milliseconds
SLOW_DENSE_FEATURES = 2**20
#: Space bounds of at least this magnitude are taken as unbounded, as infinite ones are: envs give ±3.4e38 (the float32
#: limit) for "no bound"
UNBOUNDED = 1e30
_HASH_MULTIPLIER = 16_777_619
_HASH_BASIS = 2_166_136_261 % HASH_MODULUS


def _as_floats(name: str, value: float | Sequence[float] | np.ndarray, n_dims: int) -> tuple[float, ...]:
    """
    :param name: the argument's name, for the error
    :param value: one number for every dimension, or one per dimension
    :param n_dims: number of observation dimensions
    :return: ``n_dims`` finite floats
    """
    try:
        values = (
            np.broadcast_to(np.asarray(value, dtype=np.float64), (n_dims,))
            if np.ndim(value) == 0
            else np.asarray(value, dtype=np.float64)
        )
    except (TypeError, ValueError):
        values = np.empty(0)
    if values.shape != (n_dims,):
        raise ValueError(
            f"{name}={value!r} must be a number or a sequence of {n_dims} numbers (one per observation dimension)"
        )
    if not np.all(np.isfinite(values)):
        raise ValueError(
            f"{name}={value!r} must be finite: the tiles cover [low, high]; pass finite {name} "
            "(e.g. the range the observations actually take)"
        )
    return tuple(float(v) for v in values)


def _check_grid(
    n_tilings: int,
    tiles_per_dim: int | Sequence[int],
    low: float | Sequence[float] | np.ndarray,
    high: float | Sequence[float] | np.ndarray,
    hash_size: int | None,
    origin: str,
    n_dims: int,
) -> tuple[tuple[int, ...], tuple[float, ...], tuple[float, ...]]:
    """
    Check the arguments of a tile coder.

    :return: ``tiles_per_dim``, ``low`` and ``high`` with one entry per dimension
    """
    check_positive_int("n_tilings", n_tilings, "Sutton & Barto §9.5.4 advise a power of 2 at least 4 × n_dims, e.g. 8")
    if isinstance(tiles_per_dim, int | np.integer):
        tiles = [tiles_per_dim] * n_dims
    else:
        tiles = list(tiles_per_dim) if isinstance(tiles_per_dim, Sequence | np.ndarray) else []
    if len(tiles) != n_dims or any(isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1 for n in tiles):
        raise ValueError(
            f"tiles_per_dim={tiles_per_dim!r} must be an integer >= 1 or a sequence of {n_dims} of them "
            "(the number of tiles across [low, high] in each dimension)"
        )
    lows, highs = _as_floats("low", low, n_dims), _as_floats("high", high, n_dims)
    if not all(lo < hi for lo, hi in zip(lows, highs, strict=True)):
        raise ValueError(f"low={lows} must be below high={highs} in every dimension")
    if hash_size is not None:
        check_positive_int("hash_size", hash_size, "Pass None for the dense features")
        if hash_size > HASH_MODULUS:
            raise ValueError(f"hash_size={hash_size} must be <= {HASH_MODULUS} (2^31 − 1, the modulus of the hash)")
    check_choice("origin", origin, ORIGINS)
    # Tiling t is displaced by t·(2d + 1)/n_tilings of a tile along dimension d: with a common factor g, only
    # n_tilings/g of the displacements differ modulo a tile, and the other tilings repeat them (tiles3 does the same)
    shared = [(d, factor) for d in range(n_dims) if (factor := math.gcd(2 * d + 1, n_tilings)) > 1]
    if shared:
        d, factor = shared[0]
        advised = 2 ** max(2, math.ceil(math.log2(4 * n_dims)))
        warnings.warn(
            f"TileCoding: n_tilings={n_tilings} shares the factor {factor} with dimension {d}'s offset {2 * d + 1} (tiling "
            f"t is displaced by t·(2d + 1)/n_tilings of a tile): along dimension {d} only {n_tilings // factor} of the "
            f"{n_tilings} tilings are distinct (dimensions {[dim for dim, _ in shared]}), which lowers the resolution "
            f"there. Sutton & Barto §9.5.4 advise a power of 2 at least 4 × n_dims, e.g. n_tilings={advised}",
            stacklevel=4,
        )
    if hash_size is not None and hash_size < n_tilings:
        warnings.warn(
            f"TileCoding: hash_size={hash_size} is below n_tilings={n_tilings}: every observation's {n_tilings} "
            f"tiles collide in {hash_size} features. Pass a hash_size well above the number "
            "of tiles visited (e.g. 4096, as the book's IHT for Mountain Car), or None for the dense features",
            stacklevel=4,
        )
    dense_size = n_tilings * math.prod(int(n) + 1 for n in tiles)
    if hash_size is None and dense_size > MAX_DENSE_FEATURES:
        raise ValueError(
            f"n_tilings={n_tilings} tilings of Π(tiles_per_dim + 1) tiles over {n_dims} dimensions are "
            f"{_approximately(dense_size)} dense features, more than {MAX_DENSE_FEATURES:,} (a float32 row of them "
            f"would take {_approximately(dense_size * 4, 2**30)} GiB, as would each action's weights): pass hash_size "
            "(e.g. 4096, as the book's IHT for Mountain Car) to hash the tiles to that many features, or fewer tiles_per_dim"
        )
    if hash_size is None and dense_size > SLOW_DENSE_FEATURES:
        warnings.warn(
            f"TileCoding: n_tilings={n_tilings} tilings of Π(tiles_per_dim + 1) tiles over {n_dims} dimensions are "
            f"{dense_size:,} dense features: every forward pass over them (predict; any gradient step through autograd, "
            f"e.g. of a network with hidden layers) reads {dense_size:,} weights per output (milliseconds on a CPU). "
            "Pass hash_size (e.g. 4096, as the book's IHT for Mountain Car) to hash the "
            "tiles to that many features, or fewer tiles_per_dim",
            stacklevel=4,
        )
    return tuple(int(n) for n in tiles), lows, highs


def _approximately(count: int, unit: int = 1) -> str:
    """
    :return: ``count / unit`` to 3 significant digits (``f"{count:.3g}"`` overflows past 1e308: 400 dimensions of 9
        tiles)
    """
    if len(str(count)) < 300:
        return f"{count / unit:.3g}"
    digits = len(str(count // unit))
    return f"{int(str(count // unit)[:3]) / 100:.2f}e+{digits - 1}"


def _shown(bound: np.ndarray) -> str:
    """:return: a space's bound for an error, its first values only if it has many"""
    values = bound.ravel().tolist()
    return str(values) if len(values) <= 8 else f"[{', '.join(map(str, values[:8]))}, ...] ({len(values)} values)"


def _nan_message(x: np.ndarray) -> str:
    """:return: the error of a batch of observations ``x`` (batch, n_dims) holding NaN, naming the first"""
    row, dim = np.argwhere(np.isnan(x))[0]
    return (
        f"TileCoding: observation {row} of the batch holds NaN (dimension {dim}), which is in no tile: tile coding "
        "needs numbers (±inf are clipped to the edge tiles). Check the env's observations"
    )


def _tracing() -> bool:
    """:return: whether ``torch.jit.trace``, ``torch.compile`` or ``torch.export`` traces the call (they do not see NumPy)"""
    return th.jit.is_tracing() or th.compiler.is_compiling()


def _coordinates(
    observations: th.Tensor,
    n_tilings: int,
    tiles_per_dim: th.Tensor,
    low: th.Tensor,
    high: th.Tensor,
    origin: th.Tensor,
    offsets: th.Tensor,
) -> th.Tensor:
    """
    The body of ``tile_coordinates``, on checked float64 tensors: ``offsets`` is t·(2d + 1), shape (n_tilings, n_dims).

    :raises ValueError: if an observation holds NaN
    """
    # (shape[0], not len(): torch.jit.trace records it as the batch size of each call, not a constant)
    x = th.clamp(observations.reshape(observations.shape[0], -1).to(th.float64), low, high)
    # (not while tracing or exporting, which record no data-dependent branch: the NaN check is an eager one; torch.compile
    # runs it at a graph break)
    if not (th.jit.is_tracing() or th.compiler.is_exporting()) and th.isnan(x).any():
        raise ValueError(_nan_message(x.cpu().numpy()))
    # Position in tile widths from the origin (§9.5.4: tiles of width (high − low) / tiles_per_dim)
    scaled = tiles_per_dim * (x - origin) / (high - low)
    # tiles3: q = ⌊f · n_tilings⌋, then tiling t's coordinate ⌊(q + t·(2d + 1)) / n_tilings⌋ (asymmetric offsets, §9.5.4)
    quantized = th.floor(scaled * n_tilings).to(th.int64)
    return th.div(quantized[:, None, :] + offsets, n_tilings, rounding_mode="floor")


class _Grid:
    """
    Checked tile-coder settings as tensors, computed once.

    :param n_tilings: number of tilings
    :param tiles_per_dim: tiles across the range in each dimension
    :param low: lower end of the range in each dimension
    :param high: upper end of the range in each dimension
    :param origin: one of ``ORIGINS``
    """

    def __init__(
        self, n_tilings: int, tiles_per_dim: tuple[int, ...], low: tuple[float, ...], high: tuple[float, ...], origin: str
    ) -> None:
        n_dims = len(tiles_per_dim)
        self.n_tilings = n_tilings
        self.tensors: dict[str, th.Tensor] = {
            "tiles_per_dim": th.tensor(tiles_per_dim, dtype=th.float64),
            "low": th.tensor(low, dtype=th.float64),
            "high": th.tensor(high, dtype=th.float64),
        }
        self.tensors["origin"] = self.tensors["low"].clone() if origin == "low" else th.zeros(n_dims, dtype=th.float64)
        # Tiling t is displaced by t·(1, 3, 5, …) / n_tilings of a tile width: the first odd integers (§9.5.4)
        self.tensors["offsets"] = th.arange(n_tilings, dtype=th.int64)[:, None] * (2 * th.arange(n_dims, dtype=th.int64) + 1)
        # The first and last tile of each tiling that the range meets (coordinates are monotone in x)
        first = self.coordinates(self.tensors["low"][None])[0]
        last = self.coordinates(self.tensors["high"][None])[0]
        # tiles_per_dim + 1 with origin "low" (the first of the two terms is never larger then), up to + 2 with "zero"
        sizes = th.maximum((last - first).amax(dim=0) + 1, th.tensor(tiles_per_dim, dtype=th.int64) + 1)
        self.sizes = tuple(int(n) for n in sizes)
        self.tiles_per_tiling = math.prod(self.sizes)
        self.tensors["first_tiles"] = first
        # C-order strides of a tile's coordinates within its tiling, and each tiling's first index
        self.tensors["strides"] = th.tensor([math.prod(self.sizes[d + 1 :]) for d in range(n_dims)], dtype=th.int64)
        self.tensors["tiling_starts"] = th.arange(n_tilings, dtype=th.int64) * self.tiles_per_tiling

    def coordinates(self, observations: th.Tensor) -> th.Tensor:
        t = self.tensors
        return _coordinates(observations, self.n_tilings, t["tiles_per_dim"], t["low"], t["high"], t["origin"], t["offsets"])


def _indices(
    coordinates: th.Tensor,
    first_tiles: th.Tensor,
    strides: th.Tensor,
    tiling_starts: th.Tensor,
    hash_size: int | None,
) -> th.Tensor:
    """The body of ``tile_indices``: tiles3 coordinates (batch, n_tilings, n_dims) to indices (batch, n_tilings)."""
    if hash_size is not None:
        return hash_tiles(coordinates, hash_size)
    return tiling_starts + ((coordinates - first_tiles) * strides).sum(dim=-1)


def hash_tiles(coordinates: th.Tensor, hash_size: int) -> th.Tensor:
    r"""
    Hash each tile :math:`(t, c_{t,0}, \dots, c_{t,D-1})` to an index in [0, ``hash_size``), as ``tiles3``'s
    ``hashcoords(coords, hash_size)`` does with Python's ``hash``, but vectorised and the same in every process: FNV-1's
    multiply-xor step over the tiling number and the coordinates, modulo :math:`2^{31} - 1`, then modulo ``hash_size``.

    Why not ``tiles3``'s index-hash table (``IHT``), which numbers tiles in the order they are first seen and so has
    no collisions until it is full: its indices depend on the order of the observations seen (features of the same
    state would differ between runs, and between a model and its copy), it would have to be saved with the model, and
    it grows one Python dict entry at a time. A fixed hash is stateless, batched and reproducible; the price is
    collisions from the start, about (tiles in use)² / (2 · ``hash_size``) of them, so pick ``hash_size`` well above
    the number of tiles visited, or use the dense features (``hash_size=None``) when they fit.

    :param coordinates: tile coordinates from ``tile_coordinates``, shape (batch, n_tilings, n_dims), int64
    :param hash_size: number of indices, at most 2^31 − 1
    :return: indices in [0, hash_size), shape (batch, n_tilings), int64
    """
    batch, n_tilings, _ = coordinates.shape
    tilings = th.arange(n_tilings, dtype=th.int64, device=coordinates.device).expand(batch, n_tilings)
    hashed = th.full((batch, n_tilings), _HASH_BASIS, dtype=th.int64, device=coordinates.device)
    for values in (tilings, *coordinates.unbind(dim=-1)):
        # h ← ((h xor v) · p) mod (2^31 − 1), with v reduced to [0, 2^31 − 1) first (coordinates can be negative)
        hashed = th.remainder(th.bitwise_xor(hashed, th.remainder(values, HASH_MODULUS)) * _HASH_MULTIPLIER, HASH_MODULUS)
    return th.remainder(hashed, hash_size)


def tile_coordinates(
    observations: th.Tensor | np.ndarray,
    n_tilings: int,
    tiles_per_dim: int | Sequence[int],
    low: float | Sequence[float] | np.ndarray,
    high: float | Sequence[float] | np.ndarray,
    origin: str = "low",
) -> th.Tensor:
    """
    The integer coordinates of the tile each tiling puts each observation in (Sutton & Barto §9.5.4), exactly as
    ``tiles3.tiles(None, n_tilings, f)`` returns them (less its leading tiling number) for the scaled observation
    f = tiles_per_dim · (clip(x, low, high) − origin) / (high − low). See the module's docstring.

    :param observations: a batch of observations, shape ``(batch, *obs_shape)``; flattened to ``(batch, n_dims)``
    :param n_tilings: number of tilings (the book advises a power of 2 at least 4 × n_dims)
    :param tiles_per_dim: tiles across [low, high] in each dimension (one int for all, or one per dimension)
    :param low: lower end of the range of each dimension (one number for all, or one per dimension); below is clipped
    :param high: upper end of the range of each dimension; above is clipped
    :param origin: ``"low"`` (tiling 0's boundaries from ``low``) or ``"zero"`` (from 0, as the book's footnote)
    :return: coordinates :math:`c_{t,d}`, shape (batch, n_tilings, n_dims), int64
    :raises ValueError: if an argument is out of its domain (the message names it), or an observation holds NaN
    """
    observations = th.as_tensor(observations)
    n_dims = int(np.prod(observations.shape[1:]))
    grid = _Grid(n_tilings, *_check_grid(n_tilings, tiles_per_dim, low, high, None, origin, n_dims), origin=origin)
    return grid.coordinates(observations.cpu()).to(observations.device)


def tile_indices(
    observations: th.Tensor | np.ndarray,
    n_tilings: int,
    tiles_per_dim: int | Sequence[int],
    low: float | Sequence[float] | np.ndarray,
    high: float | Sequence[float] | np.ndarray,
    hash_size: int | None = None,
    origin: str = "low",
) -> th.Tensor:
    """
    The index of the active tile of each tiling (Sutton & Barto §9.5.4): the positions of the n_tilings ones in the
    binary feature vector ``TileCoding`` returns, for linear methods that sum weights instead of multiplying by x.

    :param observations: a batch of observations, shape ``(batch, *obs_shape)``; flattened to ``(batch, n_dims)``
    :param n_tilings: number of tilings
    :param tiles_per_dim: tiles across [low, high] in each dimension (one int for all, or one per dimension)
    :param low: lower end of the range of each dimension; observations below are clipped
    :param high: upper end of the range of each dimension; observations above are clipped
    :param hash_size: ``None`` for the dense indices (tiling t owns [t·tiles_per_tiling, (t + 1)·tiles_per_tiling)),
        or the number of indices to hash the tiles to (``hash_tiles``)
    :param origin: ``"low"`` or ``"zero"``, see ``tile_coordinates``
    :return: indices, shape (batch, n_tilings), int64, in [0, n_tilings × Π(tiles_per_dim + 1)) (dense, origin
        ``"low"``) or [0, hash_size)
    :raises ValueError: if an argument is out of its domain (the message names it), or an observation holds NaN
    """
    observations = th.as_tensor(observations)
    n_dims = int(np.prod(observations.shape[1:]))
    grid = _Grid(n_tilings, *_check_grid(n_tilings, tiles_per_dim, low, high, hash_size, origin, n_dims), origin=origin)
    t = grid.tensors
    indices = _indices(grid.coordinates(observations.cpu()), t["first_tiles"], t["strides"], t["tiling_starts"], hash_size)
    return indices.to(observations.device)


class TileCoding(BaseFeaturesExtractor):
    r"""
    Tile coding (Sutton & Barto §9.5.4) of a Box observation: n_tilings grid tilings of the range [low, high], each
    displaced from the first by t·(1, 3, 5, …)/n_tilings of a tile width (the book's asymmetric offsets), giving a
    binary feature vector with one 1 per tiling: the features of the book's linear methods (§9.5, Figs 10.1–10.4).
    The tiles are those of Sutton's ``tiles3.py``; the module's docstring gives the exact formulas.

    - Dense (``hash_size=None``): ``features_dim`` = n_tilings × Π(tiles_per_dim + 1), exactly n_tilings ones per
      observation (one in each tiling's block).
    - Hashed: ``features_dim`` = ``hash_size``; feature i counts the tilings whose tile hashes to i, so the features
      still sum to n_tilings and a linear :math:`\hat q = \mathbf w^\top \mathbf x` is
      :math:`\sum_t w[\text{index}_t]`, as with ``tiles3`` (a rare collision of two tilings of one observation gives
      a 2).

    Observations outside [low, high] are clipped to it (they share the edge tiles). The computation is in float64
    (not on Apple's MPS device, which lacks it); the output is float32. The extractor has no parameters: with
    ``net_arch=[]`` the policy's output layer is linear in the tile features. Don't normalise the observations
    (``VecNormalize``) unless ``low``/``high`` are given in normalised units.

    For the book's Mountain Car (Example 10.1's footnote: ``tiles(iht, 8, [8*x/(0.5+1.2), 8*xdot/(0.07+0.07)], A)``):
    ``TileCoding(space, n_tilings=8, tiles_per_dim=8, low=(-1.2, -0.07), high=(0.5, 0.07))`` (the book's range of
    the position ends at the goal, 0.5, not at Gymnasium's bound 0.6). Add ``origin="zero"`` for the very tiles of the
    footnote; the action is the output layer's row instead of an extra tile coordinate.

    :param observation_space: a Box observation space (multi-dimensional ones are flattened)
    :param n_tilings: number of tilings (the book advises a power of 2 at least 4 × the number of dimensions)
    :param tiles_per_dim: tiles across [low, high] in each dimension: one int for all, or one per dimension (8: the
        book's 8 × 8 grid for Mountain Car)
    :param low: lower end of the range of each dimension (one number for all, or one per dimension); the space's
        ``low`` if None (which must then be bounded)
    :param high: upper end of the range of each dimension; the space's ``high`` if None
    :param hash_size: None for the exact dense features, or the number of features to hash the tiles to
        (``hash_tiles``: a fixed hash, not an index-hash table)
    :param origin: ``"low"`` (tiling 0's tile boundaries at ``low``, the default) or ``"zero"`` (at 0, as ``tiles3`` on
        tiles_per_dim·x/(high − low); then a tiling can meet tiles_per_dim + 2 tiles along a dimension)
    :raises TypeError: if the observation space is not a Box
    :raises ValueError: if the range is not given and the space's is unbounded (infinite, or at ±1e30 or beyond, such as
        the float32 limit some envs give for "no bound"), or another argument is out of its domain
    """

    tiles_per_dim: tuple[int, ...]
    low: tuple[float, ...]
    high: tuple[float, ...]

    def __init__(
        self,
        observation_space: spaces.Space,
        n_tilings: int = 8,
        tiles_per_dim: int | Sequence[int] = 8,
        low: float | Sequence[float] | np.ndarray | None = None,
        high: float | Sequence[float] | np.ndarray | None = None,
        hash_size: int | None = None,
        origin: str = "low",
    ) -> None:
        if not isinstance(observation_space, spaces.Box):
            raise TypeError(
                f"observation_space={observation_space!r} must be a gymnasium.spaces.Box: TileCoding codes continuous "
                "observations (use FlattenExtractor for Discrete ones)"
            )
        n_dims = int(np.prod(observation_space.shape))
        for name, given, bound in (("low", low, observation_space.low), ("high", high, observation_space.high)):
            if given is not None:
                continue
            # Gymnasium's flags: False for ±inf, and for an integer Box's, which it stores as its dtype's limits
            bounded = observation_space.bounded_below if name == "low" else observation_space.bounded_above
            largest = float(np.abs(bound.astype(np.float64)).max(initial=0.0))
            if not np.all(bounded):
                what = "infinite"
            elif largest >= UNBOUNDED:
                # ±3.4e38, the float32 limit: envs' "unbounded" (CartPole's velocities before Gymnasium 1.0); tiles that
                # wide put every observation in one
                what = f"at ±{largest:.3g}, envs' way of saying unbounded (every observation would fall in one tile)"
            else:
                continue
            raise ValueError(
                f"{name}=None takes the observation space's bounds, but they are {what} ({_shown(bound)}): pass a "
                f"finite {name} (one number, or one per dimension), the range the observations actually take"
            )
        low = observation_space.low.ravel().tolist() if low is None else low
        high = observation_space.high.ravel().tolist() if high is None else high
        tiles, lows, highs = _check_grid(n_tilings, tiles_per_dim, low, high, hash_size, origin, n_dims)
        grid = _Grid(n_tilings, tiles, lows, highs, origin)
        super().__init__(observation_space, hash_size if hash_size is not None else n_tilings * grid.tiles_per_tiling)
        self.n_tilings = n_tilings
        self.tiles_per_dim = tiles
        self.low, self.high = lows, highs
        self.hash_size = hash_size
        self.origin = origin
        self.tiles_per_tiling = grid.tiles_per_tiling
        # Derived from the arguments, so not saved in the state dict; buffers follow the policy's device
        for name, tensor in grid.tensors.items():
            self.register_buffer(f"_{name}", tensor, persistent=False)
        # The same, as NumPy arrays, made on first use by the CPU path of forward
        self._grid_names = tuple(grid.tensors)
        self._numpy_grid: dict[str, np.ndarray] | None = None

    def active_tiles(self, observations: th.Tensor) -> th.Tensor:
        """
        :param observations: a batch of observations, shape ``(batch, *obs_shape)``
        :return: the index of the active tile of each tiling, shape (batch, n_tilings), int64 (``tile_indices``)
        """

        def b(name: str) -> th.Tensor:
            return self.get_buffer(f"_{name}")

        coordinates = _coordinates(
            observations, self.n_tilings, b("tiles_per_dim"), b("low"), b("high"), b("origin"), b("offsets")
        )
        return _indices(coordinates, b("first_tiles"), b("strides"), b("tiling_starts"), self.hash_size)

    def forward(self, observations: th.Tensor) -> th.Tensor:
        """
        :param observations: a batch of observations, shape ``(batch, *obs_shape)``
        :return: the tile features x(s), shape (batch, features_dim), float32: binary, n_tilings ones per row; with
            ``hash_size``, the count of tilings hashed to each feature (collisions give 2 or more; each row sums to
            n_tilings)
        """
        if observations.device.type == "cpu" and self.hash_size is None and not _tracing():
            # (NumPy is invisible to torch.jit.trace and torch.export: a traced module would return the tracing input's
            # features for every input, so they get the PyTorch path, which gives the same features)
            return th.from_numpy(self._dense_features_numpy(observations.detach().numpy()))
        indices = self.active_tiles(observations)
        features = th.zeros(indices.shape[0], self.features_dim, dtype=th.float32, device=indices.device)
        ones = th.ones(indices.shape, dtype=th.float32, device=indices.device)
        # Hashed tiles may collide: count them, so that w·x = Σ_t w[index_t] as with tiles3
        return features.scatter_add_(1, indices, ones)

    def active_tiles_numpy(self, observations: np.ndarray) -> np.ndarray:
        """
        ``active_tiles`` for NumPy observations on the CPU: the same indices, and for ``hash_size=None`` the same float64
        arithmetic as ``_coordinates`` and ``_indices`` in NumPy, whose calls on a small batch cost a fraction of
        PyTorch's (the per-step loop codes one observation at every env step; with a linear q̂ over these features
        ``NStepSARSA`` sums and updates the active tiles' weights, as the book's ``tiles3`` code does).

        :param observations: a batch of observations, shape ``(batch, *obs_shape)``, any real dtype
        :return: the index of the active tile of each tiling, shape (batch, n_tilings), int64; with ``hash_size``,
            hashed indices, which may repeat within a row
        :raises ValueError: if an observation has a NaN
        """
        if self.hash_size is not None:
            return self.active_tiles(th.as_tensor(observations, dtype=th.float64)).numpy()
        if self._numpy_grid is None:
            grid = {name: self.get_buffer(f"_{name}").cpu().numpy() for name in self._grid_names}
            grid["width"] = grid["high"] - grid["low"]
            # c_{t,d} − first_{t,d} = ⌊(q_d + t(2d + 1) − n_tilings·first_{t,d}) / n_tilings⌋: integers, exact
            grid["offsets_from_first"] = grid["offsets"] - self.n_tilings * grid["first_tiles"]
            self._numpy_grid = grid
        grid = self._numpy_grid
        batch = len(observations)
        # np.clip's result, without its dispatch (each NumPy call on one observation costs more than its arithmetic)
        x = np.minimum(np.maximum(observations.reshape(batch, -1).astype(np.float64), grid["low"]), grid["high"])
        if np.isnan(x).any():  # (NaN survives the clip, and its tile index would be garbage)
            raise ValueError(_nan_message(x))
        # As _coordinates: f = tiles_per_dim·(x − origin)/(high − low), q = ⌊f·n_tilings⌋, c = ⌊(q + t(2d+1))/n_tilings⌋
        quantized = np.floor(grid["tiles_per_dim"] * (x - grid["origin"]) / grid["width"] * self.n_tilings).astype(np.int64)
        from_first = (quantized[:, None, :] + grid["offsets_from_first"]) // self.n_tilings
        # As _indices: the tiling's first index + Σ_d (c_{t,d} − first_{t,d}) · stride_d, in int64 (exact)
        indices: np.ndarray = grid["tiling_starts"] + from_first @ grid["strides"]
        return indices

    def _dense_features_numpy(self, observations: np.ndarray) -> np.ndarray:
        """
        ``forward`` for a batch on the CPU without hashing, from ``active_tiles_numpy``.

        :param observations: a batch of observations, shape ``(batch, *obs_shape)``
        :return: the binary tile features, shape (batch, features_dim), float32
        """
        indices = self.active_tiles_numpy(observations)
        features = np.zeros((len(indices), self.features_dim), dtype=np.float32)
        features[np.arange(len(indices))[:, None], indices] = 1.0
        return features

    def extra_repr(self) -> str:
        settings: dict[str, Any] = dict(
            n_tilings=self.n_tilings,
            tiles_per_dim=self.tiles_per_dim,
            low=self.low,
            high=self.high,
            hash_size=self.hash_size,
            origin=self.origin,
            features_dim=self.features_dim,
        )
        return ", ".join(f"{key}={value}" for key, value in settings.items())
