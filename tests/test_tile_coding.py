"""Tile coding (S&B §9.5.4) against a line-by-line port of Sutton's tiles3.py and slow pure-Python references."""

import math
import os
import re
import subprocess
import sys
import warnings
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from gymnasium import spaces

from sb3_classic import NStepSARSA, TileCoding
from sb3_classic.common.tile_coding import HASH_MODULUS, ORIGINS, hash_tiles, tile_coordinates, tile_indices

ROOT = Path(__file__).parents[1]


# --- Slow references ---------------------------------------------------------------------------------------------------


def tiles3(numtilings: int, floats: list[float]) -> list[list[int]]:
    """``tiles(None, numtilings, floats)`` of Sutton's tiles3.py: the coordinates [tiling, c_0, c_1, …] of each tiling."""
    qfloats = [math.floor(f * numtilings) for f in floats]
    tiles = []
    for tiling in range(numtilings):
        tiling_x2 = tiling * 2
        coords = [tiling]
        b = tiling
        for q in qfloats:
            coords.append((q + b) // numtilings)
            b += tiling_x2
        tiles.append(coords)
    return tiles


class IHT:
    """tiles3.py's index-hash table: tiles numbered in the order they are first seen."""

    def __init__(self) -> None:
        self.dictionary: dict[tuple[int, ...], int] = {}

    def getindex(self, coords: list[int]) -> int:
        return self.dictionary.setdefault(tuple(coords), len(self.dictionary))


def scaled(x: list[float], tiles_per_dim: list[int], low: list[float], high: list[float], origin: str) -> list[float]:
    """f_d = tiles_per_dim_d · (clip(x_d) − origin_d) / (high_d − low_d), one dimension at a time."""
    floats = []
    for d in range(len(x)):
        clipped = min(max(x[d], low[d]), high[d])
        floats.append(tiles_per_dim[d] * (clipped - (low[d] if origin == "low" else 0.0)) / (high[d] - low[d]))
    return floats


def reference_dense_indices(
    x: list[float], n_tilings: int, tiles_per_dim: list[int], low: list[float], high: list[float], origin: str
) -> tuple[list[int], int]:
    """
    Number the tiles of each tiling that meet [low, high] in C order of their coordinates, tiling after tiling.

    :return: the index of each tiling's active tile, and the number of features
    """
    first = tiles3(n_tilings, scaled(low, tiles_per_dim, low, high, origin))
    last = tiles3(n_tilings, scaled(high, tiles_per_dim, low, high, origin))
    sizes = [
        max(tiles_per_dim[d] + 1, *(last[t][d + 1] - first[t][d + 1] + 1 for t in range(n_tilings))) for d in range(len(x))
    ]
    per_tiling = math.prod(sizes)
    indices = []
    for t, coords in enumerate(tiles3(n_tilings, scaled(x, tiles_per_dim, low, high, origin))):
        index = 0
        for d in range(len(x)):
            position = coords[d + 1] - first[t][d + 1]
            assert 0 <= position < sizes[d]
            index = index * sizes[d] + position
        indices.append(t * per_tiling + index)
    return indices, n_tilings * per_tiling


def reference_hash(coords: list[int], hash_size: int) -> int:
    """FNV-1's step h ← ((h xor v) · 16777619) mod (2^31 − 1) over [tiling, c_0, …], then mod hash_size."""
    h = 2166136261 % (2**31 - 1)
    for value in coords:
        h = ((h ^ (value % (2**31 - 1))) * 16777619) % (2**31 - 1)
    return h % hash_size


def random_points(rng: np.random.Generator, low: np.ndarray, high: np.ndarray, n: int) -> np.ndarray:
    """Points in and around [low, high], the corners and the bounds, as float32 (what SB3 feeds the extractor)."""
    width = high - low
    inside = rng.uniform(low, high, size=(n, len(low)))
    around = rng.uniform(low - width, high + width, size=(n, len(low)))
    corners = np.array([low, high, low - 1.0, high + 1.0])
    edges = np.where(rng.random((n, len(low))) < 0.5, low, high)
    mixed = np.where(rng.random((n, len(low))) < 0.5, edges, inside)
    return np.concatenate([inside, around, corners, mixed]).astype(np.float32)


SETTINGS = [
    # n_tilings, tiles_per_dim, low, high
    (1, [5], [0.0], [1.0]),
    (4, [2, 2], [0.0, 0.0], [1.0, 1.0]),
    (8, [8, 8], [-1.2, -0.07], [0.5, 0.07]),  # the book's Mountain Car
    (8, [3, 4, 5], [-1.0, 0.0, 2.5], [1.0, 0.1, 7.0]),
    (16, [10, 1, 6, 4], [-2.4, -3.0, -0.21, -3.5], [2.4, 3.0, 0.21, 3.5]),
    (5, [7], [-3.3], [-1.1]),  # a non-power of 2 and a range away from 0
]


# --- Agreement with the references -------------------------------------------------------------------------------------


@pytest.mark.parametrize("origin", ["low", "zero"])
@pytest.mark.parametrize(("n_tilings", "tiles_per_dim", "low", "high"), SETTINGS)
def test_coordinates_and_indices_match_references(
    n_tilings: int, tiles_per_dim: list[int], low: list[float], high: list[float], origin: str
) -> None:
    points = random_points(np.random.default_rng(n_tilings), np.array(low), np.array(high), n=100)
    coordinates = tile_coordinates(points, n_tilings, tiles_per_dim, low, high, origin=origin)
    dense = tile_indices(points, n_tilings, tiles_per_dim, low, high, origin=origin)
    hashed = tile_indices(points, n_tilings, tiles_per_dim, low, high, hash_size=1000, origin=origin)
    assert coordinates.shape == (len(points), n_tilings, len(low))
    assert coordinates.dtype == th.int64
    assert dense.shape == hashed.shape == (len(points), n_tilings)
    assert dense.dtype == hashed.dtype == th.int64
    for i, point in enumerate(points.tolist()):
        expected = tiles3(n_tilings, scaled(point, tiles_per_dim, low, high, origin))
        assert coordinates[i].tolist() == [coords[1:] for coords in expected]
        expected_dense, _ = reference_dense_indices(point, n_tilings, tiles_per_dim, low, high, origin)
        assert dense[i].tolist() == expected_dense
        assert hashed[i].tolist() == [reference_hash(coords, 1000) for coords in expected]


@pytest.mark.parametrize(("n_tilings", "tiles_per_dim", "low", "high"), SETTINGS)
def test_features_are_binary_with_one_tile_per_tiling(
    n_tilings: int, tiles_per_dim: list[int], low: list[float], high: list[float]
) -> None:
    space = spaces.Box(np.array(low, dtype=np.float32), np.array(high, dtype=np.float32) + 1, dtype=np.float32)
    extractor = TileCoding(space, n_tilings=n_tilings, tiles_per_dim=tiles_per_dim, low=low, high=high)
    per_tiling = math.prod(n + 1 for n in tiles_per_dim)
    assert (
        extractor.features_dim
        == n_tilings * per_tiling
        == reference_dense_indices(low, n_tilings, tiles_per_dim, low, high, "low")[1]
    )
    points = th.as_tensor(random_points(np.random.default_rng(0), np.array(low), np.array(high), n=200))
    features = extractor(points)
    assert features.dtype == th.float32
    assert features.shape == (len(points), extractor.features_dim)
    assert set(features.unique().tolist()) == {0.0, 1.0}
    # One 1 in each tiling's block: n_tilings ones per observation
    blocks = features.reshape(len(points), n_tilings, per_tiling)
    assert th.equal(blocks.sum(dim=-1), th.ones(len(points), n_tilings))
    assert th.equal(features.nonzero()[:, 1].reshape(len(points), n_tilings), extractor.active_tiles(points))
    # Every dense feature is reachable: nothing in features_dim is wasted (a fine grid of the range, in float64 so that
    # it ends exactly at high, meets every tile: each is at least 1/n_tilings of a tile width wide, or is the point high)
    if len(low) <= 2:
        axes = [
            th.linspace(lo, hi, 4 * n * n_tilings + 1, dtype=th.float64)
            for lo, hi, n in zip(low, high, tiles_per_dim, strict=True)
        ]
        grid = th.cartesian_prod(*axes).reshape(-1, len(low))
        assert len(extractor.active_tiles(grid).unique()) == extractor.features_dim


def test_asymmetric_offsets_by_hand() -> None:
    # 4 tilings of one tile across [0, 1]² (tile width 1): tiling t is displaced by t·(1, 3)/4 of a tile, i.e. by
    # (0, 0), (1/4, 3/4), (2/4, 6/4 ≡ 2/4), (3/4, 9/4 ≡ 1/4): not along the diagonal as uniform offsets (t/4, t/4) are.
    # The point (0.3, 0.3): f = (0.3, 0.3), q = ⌊4f⌋ = (1, 1), c_t = (⌊(1 + t)/4⌋, ⌊(1 + 3t)/4⌋)
    coordinates = tile_coordinates(th.tensor([[0.3, 0.3]]), 4, 1, 0.0, 1.0)
    assert coordinates[0].tolist() == [[0, 0], [0, 1], [0, 1], [1, 2]]
    # Each tiling has 2 × 2 tiles; counted from its first tile, (0, 0), (0, 1), (0, 0), (1, 0): t·4 + 2·c_0 + c_1
    assert tile_indices(th.tensor([[0.3, 0.3]]), 4, 1, 0.0, 1.0).tolist() == [[0, 5, 8, 14]]

    # Where each tiling's tile changes along each axis in [0, 1): at 1 − (t·(2d + 1) mod 4)/4 (mod 1) tile widths
    sweep = th.linspace(0.0, 1.0, 401, dtype=th.float64)[:-1, None]
    for d, odd in enumerate((1, 3)):
        points = th.zeros(len(sweep), 2, dtype=th.float64)
        points[:, d] = sweep[:, 0]
        coords = tile_coordinates(points, 4, 1, 0.0, 1.0)[:, :, d]
        for t in range(4):
            changes = sweep[1:, 0][coords[1:, t] != coords[:-1, t]].tolist()
            expected = (1 - (t * odd % 4) / 4) % 1
            assert changes == ([expected] if expected > 0 else []), (d, t, changes)


def test_book_footnote_tiles() -> None:
    # tiles(iht, 8, [8*x/(0.5+1.2), 8*xdot/(0.07+0.07)], A) (the footnote to S&B Example 10.1): origin="zero" gives its
    # very tiles; with the IHT numbering them by first visit, its indices and the dense ones are one partition renumbered
    rng = np.random.default_rng(1)
    x = rng.uniform(-1.2, 0.5, 3000)
    xdot = rng.uniform(-0.07, 0.07, 3000)
    points = np.stack([x, xdot], axis=1)
    iht = IHT()
    book = [[iht.getindex(coords) for coords in tiles3(8, [8 * p / (0.5 + 1.2), 8 * v / (0.07 + 0.07)])] for p, v in points]
    ours = tile_indices(points, 8, 8, (-1.2, -0.07), (0.5, 0.07), origin="zero").tolist()
    book_to_ours: dict[int, int] = {}
    ours_to_book: dict[int, int] = {}
    for book_tiles, our_tiles in zip(book, ours, strict=True):
        for b, o in zip(book_tiles, our_tiles, strict=True):
            assert book_to_ours.setdefault(b, o) == o
            assert ours_to_book.setdefault(o, b) == b
    assert len(book_to_ours) > 500  # most of the 8 × 9 × 9 tiles were visited
    coords = tile_coordinates(points, 8, 8, (-1.2, -0.07), (0.5, 0.07), origin="zero")
    expected = [[c[1:] for c in tiles3(8, [8 * p / (0.5 + 1.2), 8 * v / (0.07 + 0.07)])] for p, v in points]
    assert coords.tolist() == expected
    # Its range meets 9 × 9 tiles of each tiling, as with origin="low"
    assert (
        TileCoding(
            gym.make("MountainCar-v0").observation_space, low=(-1.2, -0.07), high=(0.5, 0.07), origin="zero"
        ).features_dim
        == 648
    )


def test_out_of_range_observations_are_clipped() -> None:
    low, high = np.array([-1.0, 0.0]), np.array([1.0, 2.0])
    extractor = TileCoding(spaces.Box(-np.inf, np.inf, (2,)), n_tilings=4, tiles_per_dim=3, low=low, high=high)
    outside = th.tensor([[-5.0, 1.0], [3.0, -1.0], [0.5, 9.0], [1e30, -1e30]])
    clipped = th.tensor([[-1.0, 1.0], [1.0, 0.0], [0.5, 2.0], [1.0, 0.0]])
    assert th.equal(extractor(outside), extractor(clipped))


def test_multidimensional_box_is_flattened() -> None:
    space = spaces.Box(0.0, 1.0, (2, 3), dtype=np.float32)
    extractor = TileCoding(space, n_tilings=2, tiles_per_dim=[1, 2, 3, 1, 2, 3])
    points = th.rand(5, 2, 3)
    assert th.equal(extractor.active_tiles(points), tile_indices(points.reshape(5, 6), 2, [1, 2, 3, 1, 2, 3], 0.0, 1.0))
    assert extractor.features_dim == 2 * (2 * 3 * 4) ** 2


# --- Hashing -----------------------------------------------------------------------------------------------------------


@pytest.mark.filterwarnings("ignore:TileCoding. hash_size=.* is below n_tilings")
@pytest.mark.parametrize("hash_size", [1, 7, 4096, HASH_MODULUS])
def test_hashed_features(hash_size: int) -> None:
    space = spaces.Box(np.array([-1.2, -0.07], dtype=np.float32), np.array([0.6, 0.07], dtype=np.float32))
    extractor = TileCoding(space, n_tilings=8, tiles_per_dim=8, hash_size=hash_size)
    assert extractor.features_dim == hash_size
    points = th.as_tensor(random_points(np.random.default_rng(2), space.low, space.high, n=100))
    indices = extractor.active_tiles(points)
    assert int(indices.min()) >= 0
    assert int(indices.max()) < hash_size
    if hash_size <= 4096:
        features = extractor(points)
        # Colliding tilings count twice: the features sum to n_tilings and w·x = Σ_t w[index_t]
        assert th.equal(features.sum(dim=1), th.full((len(points),), 8.0))
        weights = th.randn(hash_size, dtype=th.float64)
        th.testing.assert_close(features.double() @ weights, weights[indices].sum(dim=1))


def test_hash_spreads_the_book_tiles() -> None:
    # All 8 × 9 × 9 tiles of the book's Mountain Car into 4096 indices (the footnote's IHT size): about as many
    # distinct indices as a uniform random map gives, 4096·(1 − (1 − 1/4096)^648) ≈ 598
    coordinates = th.cartesian_prod(th.arange(9), th.arange(9))[:, None, :].expand(81, 8, 2)  # (tile, tiling, dim)
    indices = hash_tiles(coordinates, 4096)
    assert indices.shape == (81, 8)
    assert len(indices.unique()) >= 580


HASH_SCRIPT = """
import torch as th
from sb3_classic.common.tile_coding import tile_indices
th.manual_seed({seed})
points = th.tensor([[-1.2, -0.07], [0.5, 0.07], [-0.5, 0.0], [0.123, -0.0456], [7.0, -3.0]])
print(tile_indices(points, 8, 8, (-1.2, -0.07), (0.5, 0.07), hash_size=4096).tolist())
"""

# Pinned: a change of the hash changes the features of saved models
GOLDEN_HASHED = [
    [1754, 3332, 2695, 579, 4039, 1520, 3771, 2864],
    [3516, 998, 2676, 561, 4057, 696, 2008, 2883],
    [1941, 1541, 1261, 2810, 3420, 2148, 3761, 3745],
    [1801, 1682, 651, 1339, 1583, 358, 2046, 3492],
    [2644, 126, 1804, 3785, 833, 3920, 2880, 3755],
]


def test_hash_is_deterministic_across_processes() -> None:
    points = th.tensor([[-1.2, -0.07], [0.5, 0.07], [-0.5, 0.0], [0.123, -0.0456], [7.0, -3.0]])
    here = tile_indices(points, 8, 8, (-1.2, -0.07), (0.5, 0.07), hash_size=4096).tolist()
    assert here == GOLDEN_HASHED
    # Another process, with another str hash seed (Python's hash, which tiles3 uses, changes with it) and torch seed
    env = {**os.environ, "PYTHONHASHSEED": "12345"}
    script = HASH_SCRIPT.format(seed=12345)
    result = subprocess.run([sys.executable, "-c", script], cwd=ROOT, env=env, capture_output=True, text=True, check=True)
    assert result.stdout.strip() == str(GOLDEN_HASHED)


# --- Arguments ---------------------------------------------------------------------------------------------------------

BOX = spaces.Box(np.array([-1.0, 0.0], dtype=np.float32), np.array([1.0, 5.0], dtype=np.float32))


@pytest.mark.parametrize(
    ("space", "kwargs", "match"),
    [
        (BOX, dict(n_tilings=0), "n_tilings=0"),
        (BOX, dict(n_tilings=2.5), "n_tilings=2.5"),
        (BOX, dict(tiles_per_dim=0), "tiles_per_dim=0"),
        (BOX, dict(tiles_per_dim=[4, 4, 4]), r"tiles_per_dim=\[4, 4, 4\].*2"),
        (BOX, dict(tiles_per_dim=[4, 2.5]), r"tiles_per_dim=\[4, 2.5\]"),
        (BOX, dict(low=[0.0, 0.0, 0.0]), "low=.*2 numbers"),
        (BOX, dict(high=(1.0, "a")), "high="),
        (BOX, dict(low=(1.0, 0.0)), "low=.* below high="),
        (BOX, dict(high=np.inf), "high=inf must be finite"),
        (BOX, dict(hash_size=0), "hash_size=0"),
        (BOX, dict(hash_size=2**31), "hash_size=2147483648"),
        (BOX, dict(origin="centre"), "origin='centre'"),
        (spaces.Box(-np.inf, np.inf, (2,)), {}, r"low=None .* infinite .* pass a finite low"),
        (spaces.Box(-np.inf, np.inf, (2,)), dict(low=(0.0, 0.0)), r"high=None .* infinite .* pass a finite high"),
        # A float count: "'float' object is not iterable" before
        (BOX, dict(tiles_per_dim=8.0), r"tiles_per_dim=8.0 must be an integer >= 1"),
        # 8 × 9^8 = 344M dense features (a 1.3 GiB row); at 12 dimensions the allocation failed deep in torch, at 20
        # the tile indices overflowed int64 into negative ones, silently
        (spaces.Box(0.0, 1.0, (8,)), {}, r"3.44e\+08 dense features, more than 16,777,216 .* pass hash_size"),
        (spaces.Box(0.0, 1.0, (20,)), {}, r"dense features, more than 16,777,216 .* pass hash_size"),
        # 400 dimensions (a flattened image): an OverflowError formatting the count (int too large to convert to float)
        (spaces.Box(0.0, 1.0, (400,)), {}, r"3.98e\+382 dense features, more than 16,777,216 .* pass hash_size"),
        # Bounds at the float32 limit (envs' "unbounded"): every observation fell in one tile, silently
        (spaces.Box(-3.4e38, 3.4e38, (2,)), {}, r"low=None .* at ±3.4e\+38, envs' way of saying unbounded .* pass a finite"),
        (spaces.Box(-1.0, 1e30, (2,)), dict(low=-1.0), r"high=None .* at ±1e\+30"),
        # An integer Box without bounds: Gymnasium stores its dtype's limits (±2.1e9), marked unbounded
        (spaces.Box(-np.inf, np.inf, (2,), np.int32), {}, r"low=None .* they are infinite"),
        # The row's size in GiB below 1 was "0 GiB" (an integer division)
        (spaces.Box(0.0, 1.0, (4,)), dict(tiles_per_dim=63), r"1.34e\+08 dense features, .* would take 0.5 GiB"),
    ],
)
def test_bad_arguments_raise_naming_them(space: spaces.Space, kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        TileCoding(space, **kwargs)


def test_numpy_counts_and_hashed_large_spaces_are_accepted() -> None:
    # Space bounds short of "unbounded", or wide bounds replaced by the range given
    assert TileCoding(spaces.Box(-1e29, 1e29, (2,))).high == pytest.approx((1e29, 1e29))
    assert TileCoding(spaces.Box(-3.4e38, 3.4e38, (2,)), low=-1.0, high=1.0).high == (1.0, 1.0)
    numpy_count: Any = np.int64(8)
    assert TileCoding(BOX, tiles_per_dim=numpy_count).features_dim == TileCoding(BOX, tiles_per_dim=8).features_dim
    coder = TileCoding(spaces.Box(0.0, 1.0, (20,)), hash_size=4096)
    indices = coder.active_tiles(th.rand(5, 20))
    assert indices.shape == (5, 8)
    assert int(indices.min()) >= 0
    assert int(indices.max()) < 4096


def test_many_dense_features_warn_naming_hash_size() -> None:
    # Acrobot-v1's 6 dimensions with the defaults: 8 × 9^6 = 4,251,528 features, which trained for minutes without output
    with pytest.warns(UserWarning, match=r"4,251,528 dense features: .* Pass hash_size"):
        TileCoding(spaces.Box(0.0, 1.0, (6,)))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        TileCoding(spaces.Box(0.0, 1.0, (6,)), hash_size=4096)
        TileCoding(spaces.Box(0.0, 1.0, (4,)))  # 8 × 9^4 = 52,488


@pytest.mark.parametrize("hash_size", [None, 4096])
def test_a_nan_observation_is_named(hash_size: int | None) -> None:
    # Dense: int64 garbage indices (8070450532247928836), then an IndexError deep inside; hashed: ordinary-looking ones
    coder = TileCoding(BOX, hash_size=hash_size)
    observations = th.tensor([[0.5, 0.5], [0.2, float("nan")]])
    with pytest.raises(ValueError, match=r"observation 1 of the batch holds NaN \(dimension 1\)"):
        coder(observations)
    with pytest.raises(ValueError, match="holds NaN"):
        tile_indices(observations, 8, 8, 0.0, 1.0, hash_size=hash_size)
    # ±inf are clipped to the edge tiles, as before
    assert coder(th.tensor([[float("inf"), -float("inf")]])).sum() == 8


def test_non_box_space_raises() -> None:
    with pytest.raises(TypeError, match="observation_space=Discrete"):
        TileCoding(spaces.Discrete(3))


# --- With an algorithm ------------------------------------------------------------------------------------------------


def test_nstep_sarsa_on_mountain_car_with_tile_coding(tmp_path: Path) -> None:
    # The documented usage (docs/modules/tile_coding.md): q̂(s, ·, w) linear in the 648 tile features of the book's Mountain Car
    model = NStepSARSA(
        "MlpPolicy",
        "sb3_classic/MountainCarNoLimit-v0",
        policy_kwargs=dict(
            features_extractor_class=TileCoding,
            features_extractor_kwargs=dict(n_tilings=8, tiles_per_dim=8, low=(-1.2, -0.07), high=(0.5, 0.07)),
            net_arch=[],
        ),
        seed=0,
    )
    assert model.policy.q_net.features_extractor.features_dim == 648
    (linear,) = (layer for layer in model.policy.q_net.q_net if isinstance(layer, th.nn.Linear))
    assert linear.in_features == 648
    assert linear.out_features == 3
    model.learn(200)
    observations = np.array([[-0.5, 0.0], [0.3, 0.05]], dtype=np.float32)
    actions, _ = model.predict(observations, deterministic=True)
    model.save(tmp_path / "sarsa")
    loaded = NStepSARSA.load(tmp_path / "sarsa")
    np.testing.assert_array_equal(loaded.predict(observations, deterministic=True)[0], actions)


def test_docs_tile_coding_example_runs() -> None:
    page = (ROOT / "docs" / "modules" / "tile_coding.md").read_text()
    (example,) = re.findall(r"## Example\n.*?```python\n(.*?)```", page, flags=re.DOTALL)
    namespace: dict[str, object] = {}
    exec(compile(example, "docs/modules/tile_coding.md", "exec"), namespace)
    model = namespace["model"]
    assert isinstance(model, NStepSARSA)
    assert isinstance(model.policy.q_net.features_extractor, TileCoding)
    assert model.policy.q_net.features_extractor.features_dim == 648


@pytest.mark.parametrize("origin", ORIGINS)
def test_cpu_features_equal_the_tile_indices(origin: str) -> None:
    """``forward`` on the CPU (NumPy) puts its ones exactly at ``active_tiles`` (PyTorch), bounds and outside included."""
    space = spaces.Box(np.array([-1.2, -0.07, 0.0], np.float32), np.array([0.5, 0.07, 3.0], np.float32), dtype=np.float32)
    coder = TileCoding(space, n_tilings=8, tiles_per_dim=(8, 6, 3), origin=origin)
    rng = np.random.default_rng(0)
    points = rng.uniform(space.low - 0.2, space.high + 0.2, size=(500, 3))
    points = np.concatenate([points, space.low[None], space.high[None]]).astype(np.float32)
    features = coder(th.as_tensor(points))
    assert features.dtype == th.float32
    expected = th.zeros_like(features).scatter_(1, coder.active_tiles(th.as_tensor(points)), 1.0)
    assert th.equal(features, expected)


def test_tilings_that_coincide_and_too_small_hashes_warn() -> None:
    """
    n_tilings = 3 on two dimensions displaces the tilings by t·3/3 of a tile along the second: whole tiles, so all
    three coincide there (counted below); hash_size < n_tilings collides every observation's tiles. Both warn.
    """
    velocities = np.stack([np.zeros(2000), np.linspace(0.0, 5.0, 2000)], axis=1).astype(np.float32)
    with pytest.warns(UserWarning, match=r"n_tilings=3 shares the factor 3 with dimension 1's offset 3.* 1 of the 3"):
        three = TileCoding(BOX, n_tilings=3)
    cells = {tuple(row) for row in three.active_tiles_numpy(velocities).tolist()}
    single = {row[0] for row in three.active_tiles_numpy(velocities).tolist()}
    assert len(cells) == len(single), "the three tilings cut the velocity axis at the same places"
    with pytest.warns(UserWarning, match=r"n_tilings=6 .* 2 of the 6 tilings are distinct"):
        TileCoding(BOX, n_tilings=6)
    with pytest.warns(
        UserWarning, match=r"hash_size=4 is below n_tilings=8: every observation's 8 tiles collide in 4 features"
    ):
        TileCoding(BOX, hash_size=4)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        eight = TileCoding(BOX, n_tilings=8)  # powers of 2: odd offsets never share a factor with them
        TileCoding(spaces.Box(0.0, 1.0, (1,)), n_tilings=5)  # one dimension: offset 1
        TileCoding(BOX, hash_size=8)
    assert len({tuple(row) for row in eight.active_tiles_numpy(velocities).tolist()}) > 4 * len(single)


@pytest.mark.parametrize("hash_size", [None, 512])
def test_exported_policy_acts_as_predict(hash_size: int | None) -> None:
    """
    SB3's export recipes (``torch.jit.trace``, ``torch.export``) on a tile-coded policy: its features must be traced, not
    baked in (the CPU's NumPy features were: the traced module gave the tracing input's actions for every input), and
    the batch size must stay free (it was recorded from ``len``).
    """
    tiles = dict(n_tilings=8, tiles_per_dim=8, low=(-1.2, -0.07), high=(0.5, 0.07), hash_size=hash_size)
    kwargs = dict(features_extractor_class=TileCoding, features_extractor_kwargs=tiles, net_arch=[])
    model = NStepSARSA("MlpPolicy", "MountainCar-v0", policy_kwargs=kwargs, seed=0, device="cpu")
    layer = model.policy.q_net.q_net[0]
    assert isinstance(layer, th.nn.Linear)
    with th.no_grad():
        layer.weight.normal_(generator=th.Generator().manual_seed(0))
    observations = th.as_tensor(np.random.default_rng(0).uniform((-1.2, -0.07), (0.6, 0.07), (100, 2)), dtype=th.float32)
    greedy = model.predict(observations.numpy(), deterministic=True)[0]
    assert len(set(greedy.tolist())) == 3  # (the weights make every action greedy somewhere)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no TracerWarning: nothing in the trace is a constant of the tracing input
        warnings.filterwarnings("ignore", r"`torch\.jit\.trace", DeprecationWarning)  # (torch 2.13 deprecates it)
        traced = th.jit.trace(model.policy.eval(), observations[:1])
    np.testing.assert_array_equal(traced(observations).numpy(), greedy)
    exported = th.export.export(model.policy.q_net, (observations[:3],), dynamic_shapes=({0: th.export.Dim("batch")},))
    np.testing.assert_array_equal(exported.module()(observations).argmax(dim=1).numpy(), greedy)


def test_compiled_policy_still_refuses_nan() -> None:
    """``torch.compile`` for speed (not an export) keeps the NaN check, at a graph break (it gave an index error)."""
    tiles = dict(n_tilings=8, tiles_per_dim=8, low=(-1.2, -0.07), high=(0.5, 0.07))
    kwargs = dict(features_extractor_class=TileCoding, features_extractor_kwargs=tiles, net_arch=[])
    model = NStepSARSA("MlpPolicy", "MountainCar-v0", policy_kwargs=kwargs, seed=0, device="cpu")
    compiled = th.compile(model.policy.q_net, backend="eager")
    observations = th.tensor([[0.1, 0.01], [-0.5, 0.0]])
    assert th.equal(compiled(observations), model.policy.q_net(observations))
    with pytest.raises(ValueError, match="observation 1 of the batch holds NaN"):
        compiled(th.tensor([[0.1, 0.01], [float("nan"), 0.0]]))
