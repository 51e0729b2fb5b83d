"""bench/recognise_measure.py, the structure-only distance of the recognition benchmark, against oracles that
do not depend on it: a texture's own picture, rotated and rescaled copies, images with no structure, and
background pixels that must not count. Texture statistics use a coarser grid of variants than the benchmark
(fewer rotations, for speed); the method is the same."""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

import recognise_measure as measure

TEXTURES = ROOT.parent / "shared" / "data" / "textures"
NAMES = ("brick_wall", "honeycomb", "woven_straw", "green_cells", "toy_bricks")
SCALES = measure.SCALES
ROTATIONS = (0.0, 45.0, 90.0, 135.0)

pytestmark = pytest.mark.skipif(
    not measure.VGG_WEIGHTS.is_file() or not TEXTURES.is_dir(), reason="needs ../shared (textures, VGG-16 weights)"
)


def load(name: str) -> np.ndarray:
    path = next(TEXTURES.glob(f"{name}.*"))
    return cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2RGB)


@pytest.fixture(scope="module")
def stats() -> list[measure.TextureStats]:
    return [measure.texture_stats(load(n), n, SCALES, ROTATIONS) for n in NAMES]


def picture(name: str, height: float, angle: float, size: int = 160) -> np.ndarray:
    """The texture itself as an RGB image (independent of the measure's grey pipeline: colour kept)."""
    image = load(name).astype(np.float32) / 255.0
    return np.stack([measure.texture_variant(image[..., c], height, angle, size) for c in range(3)], axis=-1)


def ranks(image: np.ndarray, stats: list[measure.TextureStats], name: str, alpha=None) -> dict[str, int]:
    d = measure.distances(measure.view_stats(image, alpha), stats)
    return {m: measure.rank_of(d[m], name) for m in ("gram", "gabor")}


def margin(scores: dict[str, float]) -> float:
    """Relative gap between the best and the second best distance."""
    best, second = sorted(scores.values())[:2]
    return (second - best) / max(best, 1e-12)


@pytest.mark.parametrize("name", ["brick_wall", "honeycomb", "woven_straw"])
def test_a_texture_ranks_itself_first(stats, name):
    assert ranks(picture(name, 128, 0.0), stats, name) == {"gram": 1, "gabor": 1}


@pytest.mark.parametrize(("name", "height", "angle"), [("brick_wall", 100, 30.0), ("green_cells", 180, 70.0)])
def test_a_rotated_rescaled_copy_still_ranks_its_texture_first(stats, name, height, angle):
    assert ranks(picture(name, height, angle), stats, name) == {"gram": 1, "gabor": 1}


def test_no_structure_has_no_clear_winner(stats):
    own = measure.distances(measure.view_stats(picture("brick_wall", 128, 0.0)), stats)
    flat = measure.distances(measure.view_stats(np.full((160, 160, 3), 0.6, np.float32)), stats)
    noise = np.random.default_rng(0).random((160, 160, 3)).astype(np.float32)
    noisy = measure.distances(measure.view_stats(noise), stats)
    for m in ("gram", "gabor"):
        assert margin(flat[m]) < 0.5 * margin(own[m]), m
        assert margin(noisy[m]) < 0.5 * margin(own[m]), m
        # and both are far from the structured texture the real picture matches
        assert min(flat[m].values()) > 1.25 * own[m]["brick_wall"], m
        assert min(noisy[m].values()) > 1.25 * own[m]["brick_wall"], m


def test_the_mask_excludes_the_background(stats):
    image = picture("honeycomb", 128, 20.0, 192)
    yy, xx = np.mgrid[:192, :192]
    alpha = ((yy - 96) ** 2 + (xx - 96) ** 2 < 80**2).astype(np.float32)
    other = picture("brick_wall", 64, 0.0, 192)
    on_white = np.where(alpha[..., None] > 0, image, 1.0)
    on_bricks = np.where(alpha[..., None] > 0, image, other)
    a = measure.distances(measure.view_stats(on_white, alpha), stats)
    b = measure.distances(measure.view_stats(on_bricks, alpha), stats)
    for m in ("gram", "gabor"):
        assert a[m] == pytest.approx(b[m], rel=1e-5), m
    assert ranks(on_white, stats, "honeycomb", alpha) == {"gram": 1, "gabor": 1}


def test_image_to_image_distance_is_zero_for_the_same_image_and_grows_when_the_texture_turns():
    still = measure.view_stats(picture("brick_wall", 96, 0.0))
    same = measure.pair_distance(still, measure.view_stats(picture("brick_wall", 96, 0.0)))
    slightly = measure.pair_distance(still, measure.view_stats(picture("brick_wall", 96, 10.0)))
    turned = measure.pair_distance(still, measure.view_stats(picture("brick_wall", 96, 60.0)))
    other = measure.pair_distance(still, measure.view_stats(picture("honeycomb", 96, 0.0)))
    assert same["windows"] == turned["windows"] == still.n_windows > 0
    for m in ("gram", "gabor"):
        assert same[m] == 0.0, m
        assert 0.0 < slightly[m] < turned[m], m
        assert turned[m] > 0.5 * other[m], m  # a turned texture is about as far as another texture
    yy, xx = np.mgrid[:160, :160]
    disc = ((yy - 80) ** 2 + (xx - 80) ** 2 < 60**2).astype(np.float32)
    partial = measure.pair_distance(still, measure.view_stats(picture("brick_wall", 96, 0.0), disc))
    assert 0 < partial["windows"] < still.n_windows  # only the windows both images cover


def test_margin_of_is_the_share_the_distances_must_move_and_agrees_with_rank_of():
    """Analytic: ten distances 1..10, the texture at 2.5 sits inside the top 3 by (3 - 2.5) / 3 (the third of the
    others is 3); at 3.5 outside by 0.5 / 3. On random distances the sign agrees with ``rank_of`` at every
    threshold, and the texture's own distance moved by just under the margin's share of the threshold's keeps it
    inside, by just over moves it out."""
    scores = {f"t{k}": float(k) for k in (1, 2, 3, 4, 5, 6, 7, 8, 9, 10)}
    assert measure.margin_of({**scores, "me": 2.5}, "me", 3) == pytest.approx(1 / 6)
    assert measure.margin_of({**scores, "me": 3.5}, "me", 3) == pytest.approx(-1 / 6)
    rng = np.random.default_rng(0)
    for _ in range(200):
        values = {f"t{k}": float(v) for k, v in enumerate(rng.uniform(0.1, 1.0, 10))}
        name = "t0"
        for top in (1, 3, 5):
            edge = measure.margin_of(values, name, top)
            assert (edge >= 0) == (measure.rank_of(values, name) <= top)
            if edge > 0:
                for factor, inside in ((1 + 0.99 * edge / (1 - edge), True), (1 + 1.01 * edge / (1 - edge), False)):
                    moved = {**values, name: values[name] * factor}
                    assert (measure.rank_of(moved, name) <= top) == inside
