"""Entropy Rate Superpixels: exact K, connectivity, determinism, depth steps, bad input."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest
from scipy import ndimage

from holescan.detect._ers import ers_superpixels
from holescan.errors import InputError

EIGHT = np.ones((3, 3), dtype=bool)


def _components(mask: npt.NDArray[np.bool_]) -> int:
    return int(ndimage.label(mask, structure=EIGHT)[1])


def _two_level(shape: str, noise: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A 48 x 64 grey image with two levels (60 and 200) split along ``shape``."""
    v, u = np.mgrid[0:48, 0:64]
    if shape == "vertical":
        high = u >= 25
    elif shape == "disc":
        high = np.hypot(u - 30, v - 22) < 12
    else:  # diagonal
        high = u + v >= 50
    level = np.where(high, 200.0, 60.0)
    rng = np.random.default_rng(seed)
    img = np.clip(level + rng.normal(0.0, noise, level.shape), 0, 255).astype(np.uint8)
    return img, high


@pytest.mark.parametrize("k", [1, 2, 5, 9, 20, 57])
def test_exactly_k_connected_regions(k: int) -> None:
    rng = np.random.default_rng(k)
    # smooth random terrain plus noise, like a rescaled depth image
    img = ndimage.gaussian_filter(rng.normal(128, 60, (40, 50)), 3) + rng.normal(0, 2, (40, 50))
    labels = ers_superpixels(np.clip(img, 0, 255).astype(np.uint8), k)
    assert labels.shape == (40, 50)
    assert labels.dtype == np.int32
    assert np.array_equal(np.unique(labels), np.arange(k))
    for label in range(k):
        assert _components(labels == label) == 1


def test_float_image_gives_k_connected_regions() -> None:
    rng = np.random.default_rng(7)
    img = rng.random((30, 30)) * 10.0
    labels = ers_superpixels(img, 12, sigma=1.0)
    assert np.array_equal(np.unique(labels), np.arange(12))
    assert all(_components(labels == label) == 1 for label in range(12))


def test_deterministic() -> None:
    rng = np.random.default_rng(3)
    img = rng.integers(0, 256, (32, 40)).astype(np.uint8)
    first = ers_superpixels(img, 10)
    for _ in range(2):
        assert np.array_equal(ers_superpixels(img.copy(), 10), first)


@pytest.mark.parametrize("shape", ["vertical", "disc", "diagonal"])
@pytest.mark.parametrize("noise", [0.0, 3.0])
def test_no_region_straddles_a_sharp_step(shape: str, noise: float) -> None:
    img, high = _two_level(shape, noise)
    for k in (2, 3, 4, 6, 9, 12, 20):
        labels = ers_superpixels(img, k)
        for label in range(k):
            side = high[labels == label]
            assert side.all() or not side.any(), f"K={k}: region {label} straddles the step"


@pytest.mark.parametrize("shape", ["vertical", "disc", "diagonal"])
def test_two_superpixels_are_the_two_levels(shape: str) -> None:
    img, high = _two_level(shape, 0.0)
    labels = ers_superpixels(img, 2)
    assert np.array_equal(labels == labels[high][0], high)


def test_tiny_images_with_known_partitions() -> None:
    # the only dissimilar edge is the one ERS leaves out
    assert ers_superpixels(np.array([[0, 0, 255]], np.uint8), 2).tolist() == [[0, 0, 1]]
    assert ers_superpixels(np.array([[0, 0], [0, 255]], np.uint8), 2).tolist() == [
        [0, 0],
        [0, 1],
    ]
    # K = number of pixels: nothing merges, labels in raster order
    assert ers_superpixels(np.zeros((2, 3)), 6).tolist() == [[0, 1, 2], [3, 4, 5]]
    assert ers_superpixels(np.zeros((1, 1)), 1).tolist() == [[0]]
    assert ers_superpixels(np.arange(12.0).reshape(3, 4), 1).max() == 0


def test_balancing_term_evens_out_sizes_on_a_flat_image() -> None:
    flat = np.zeros((20, 20), np.uint8)
    sizes_entropy_only = np.bincount(ers_superpixels(flat, 4, lam=0.0).ravel())
    sizes_balanced = np.bincount(ers_superpixels(flat, 4, lam=0.5).ravel())
    # entropy rate alone grows one cluster; the balancing term spreads the pixels
    assert sizes_entropy_only.max() >= 0.9 * flat.size
    assert sizes_balanced.min() >= 0.1 * flat.size


@pytest.mark.parametrize(
    ("image", "k", "kwargs", "match"),
    [
        (np.zeros((4, 4)), 0, {}, "between 1 and"),
        (np.zeros((4, 4)), 17, {}, "between 1 and"),
        (np.zeros((4, 4)), 2.0, {}, "integer"),
        (np.zeros((4, 4)), True, {}, "integer"),
        (np.zeros((4, 4, 3)), 2, {}, r"\(H, W\)"),
        (np.zeros((0, 4)), 1, {}, r"\(H, W\)"),
        (np.array([[0.0, np.nan]]), 1, {}, "NaN"),
        (np.array([["a", "b"]]), 1, {}, "real numbers"),
        (np.zeros((4, 4), bool), 2, {}, "real numbers"),
        (np.zeros((4, 4)), 2, {"sigma": 0.0}, "sigma"),
        (np.zeros((4, 4)), 2, {"lam": -1.0}, "lam"),
    ],
)
def test_bad_input_raises_input_error(
    image: np.ndarray, k: object, kwargs: dict[str, float], match: str
) -> None:
    with pytest.raises(InputError, match=match):
        ers_superpixels(image, k, **kwargs)  # type: ignore[arg-type]
