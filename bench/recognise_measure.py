"""Structure-only distance between a render of a textured object and a texture, for bench/recognise.py.

Nothing here is used by the transfer (and gt2gs_blender never imports it): the statistics come from features
the optimisation never sees, so a result cannot be tuned to them by accident.

Both measures see grey images only, over the object's pixels only (an eroded alpha mask):

1. ``prepare``: luminance; the shading removed (minus a mask-normalised Gaussian blur of width
   ``SHADING_SIGMA``) and the contrast divided out locally (by the mask-normalised local RMS, with a floor
   so a flat image stays flat). Background pixels become 0. Textures go through the same function.
2. The render is cut into ``WINDOW`` px windows (stride ``STRIDE``) that lie on the object (at least
   ``MIN_COVER`` of their pixels in the mask); every window is compared with every variant of a texture
   (``SCALES`` on-screen heights spanning 8x, and for the Gram ``ROTATIONS`` angles), the window keeps its
   best variant, and the distance is the mean over windows.
3. Gram: VGG-16 (ImageNet weights to relu2_2, the shared file) relu1_2 and relu2_2 Gram matrices of the
   grey image replicated to RGB, masked sums per window; distance ``|Ga - Gb| / (|Ga| + |Gb|)`` (Frobenius)
   averaged over the two layers.
4. Gabor: energies of a complex Gabor bank (``WAVELENGTHS`` x ``N_ORIENT`` orientations over 180 degrees)
   averaged over the window, normalised to sum 1 (contrast-free), and each filter's response sparsity (noise
   has the Rayleigh value pi/4, edges and cells less); compared by Hellinger distance plus the energy-weighted
   sparsity difference, at the best cyclic shift of the orientation axis (rotation-aware without rotating
   the texture).
5. Image to image (``pair_distance``): two renders of the same view (a result and the scene it started from),
   window by window over the windows both lie on the object; the same Gram and Gabor window distances, with
   no search over scales, rotations or orientation shifts, so a texture turned or rescaled on screen counts.
   Identical images are 0.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from gt2gs_blender.core.features.extractor import build_layers
from gt2gs_blender.core.features.specs import IMAGENET_MEAN, IMAGENET_STD, FeatureSpec
from gt2gs_blender.core.transfer import tone

SHARED = ROOT.parent / "shared"
VGG_WEIGHTS = SHARED / "weights" / "vgg16_to_relu2_2.pth"
CACHE = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "gt2gs_blender" / "bench" / "recognise"

LUMA = np.asarray(tone.LUMA, np.float32)
SHADING_SIGMA = 12.0
CONTRAST_SIGMA = 12.0
CONTRAST_FLOOR = 0.02
"""Grey levels: local RMS below this is treated as this (a flat image stays flat, noise of 1 % stays small)."""
MASK_ALPHA = 0.5
MASK_ERODE = 3
WINDOW = 48
STRIDE = 16
MIN_COVER = 0.85
SCALES = tuple(round(48 * 2 ** (k * 0.6)) for k in range(6))
"""On-screen texture heights (px at 256 px renders): 48 ... 384, 8x."""
ROTATIONS = tuple(22.5 * k for k in range(8))
TEXTURE_PATCH = 128
"""Side of the texture patch each variant's statistics come from."""
WAVELENGTHS = (4.0, 5.66, 8.0, 11.3, 16.0, 22.6)
N_ORIENT = 8
SPARSITY_WEIGHT = 1.0
VGG16_RELU2 = FeatureSpec(
    name="vgg16_relu2",
    layers=(64, 64, "M", 128, 128),
    taps=("relu1_2", "relu2_2"),
    preprocessing="imagenet",
    padding="zeros",
    weight_files=("vgg16_to_relu2_2.pth",),
    description="torchvision ImageNet VGG-16 to relu2_2 (the recognition benchmark's Gram features)",
)
PARAMS = {
    "shading": SHADING_SIGMA,
    "contrast": CONTRAST_SIGMA,
    "floor": CONTRAST_FLOOR,
    "window": WINDOW,
    "scales": SCALES,
    "rotations": ROTATIONS,
    "patch": TEXTURE_PATCH,
    "wavelengths": WAVELENGTHS,
    "orient": N_ORIENT,
    "sparsity": SPARSITY_WEIGHT,
    "version": 2,
}


# ---------------------------------------------------------------------------------------------------
# Grey, masked, normalised
# ---------------------------------------------------------------------------------------------------
def to_float(image: np.ndarray) -> np.ndarray:
    """(H,W[,3|4]) uint8 or float in [0,1] -> float32 (H,W,3) or (H,W)."""
    image = np.asarray(image)
    out = image.astype(np.float32) / 255.0 if image.dtype == np.uint8 else image.astype(np.float32)
    return out[..., :3] if out.ndim == 3 else out


def grey(image: np.ndarray) -> np.ndarray:
    """Luminance of an RGB image (a grey image passes)."""
    image = to_float(image)
    return image @ LUMA if image.ndim == 3 else image


def object_mask(alpha: np.ndarray, erode: int = MASK_ERODE) -> np.ndarray:
    """The object's pixels: alpha above MASK_ALPHA, eroded by ``erode`` px (bool)."""
    mask = (np.asarray(alpha, np.float32) > MASK_ALPHA).astype(np.uint8)
    if erode > 0:
        mask = cv2.erode(mask, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * erode + 1, 2 * erode + 1)))
    return mask.astype(bool)


def _masked_blur(values: np.ndarray, mask: np.ndarray, sigma: float) -> np.ndarray:
    weight = cv2.GaussianBlur(mask, (0, 0), sigma, borderType=cv2.BORDER_REFLECT)
    return cv2.GaussianBlur(values * mask, (0, 0), sigma, borderType=cv2.BORDER_REFLECT) / np.maximum(weight, 1e-6)


def prepare(image: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
    """Grey structure of ``image`` over ``mask`` (None = all): shading removed, local contrast divided out;
    0 outside the mask. Colour, brightness, contrast and the background do not matter."""
    g = grey(image)
    m = np.ones(g.shape, np.float32) if mask is None else np.asarray(mask, np.float32)
    high = (g - _masked_blur(g, m, SHADING_SIGMA)) * m
    rms = np.sqrt(_masked_blur(high * high, m, CONTRAST_SIGMA))
    return (high / np.maximum(rms, CONTRAST_FLOOR) * m).astype(np.float32)


def windows(mask: np.ndarray, size: int = WINDOW, stride: int = STRIDE, min_cover: float = MIN_COVER) -> list:
    """(y, x) of the ``size`` windows (top-left, every ``stride`` px) with at least ``min_cover`` in ``mask``."""
    h, w = mask.shape
    integral = cv2.integral(mask.astype(np.uint8))
    out = []
    for y in range(0, h - size + 1, stride):
        for x in range(0, w - size + 1, stride):
            count = integral[y + size, x + size] - integral[y, x + size] - integral[y + size, x] + integral[y, x]
            if count >= min_cover * size * size:
                out.append((y, x))
    return out


# ---------------------------------------------------------------------------------------------------
# Texture variants
# ---------------------------------------------------------------------------------------------------
def texture_variant(texture: np.ndarray, height: float, angle_deg: float, size: int = TEXTURE_PATCH) -> np.ndarray:
    """A ``size`` px grey patch of ``texture`` shown ``height`` px tall, rotated ``angle_deg``, centred
    (mirror-tiled where the scaled texture is smaller than the patch, so no seam edges)."""
    g = grey(texture)
    scale = height / g.shape[0]
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    linear = scale * np.array([[c, s], [-s, c]])
    centre_in = np.array([(g.shape[1] - 1) / 2.0, (g.shape[0] - 1) / 2.0])
    centre_out = np.array([(size - 1) / 2.0, (size - 1) / 2.0])
    matrix = np.hstack([linear, (centre_out - linear @ centre_in)[:, None]])
    if scale < 1.0:  # downscale with antialiasing first, then warp at (about) unit scale
        small = cv2.resize(g, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
        linear = np.array([[c, s], [-s, c]]) * (small.shape[0] / g.shape[0] / scale)
        centre_in = np.array([(small.shape[1] - 1) / 2.0, (small.shape[0] - 1) / 2.0])
        matrix = np.hstack([linear, (centre_out - linear @ centre_in)[:, None]])
        g = small
    return cv2.warpAffine(g, matrix, (size, size), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT_101)


# ---------------------------------------------------------------------------------------------------
# Features
# ---------------------------------------------------------------------------------------------------
_VGG: torch.nn.Sequential | None = None


def vgg() -> torch.nn.Sequential:
    global _VGG
    if _VGG is None:
        layers = build_layers(VGG16_RELU2)
        state = torch.load(VGG_WEIGHTS, map_location="cpu", weights_only=True)
        layers.load_state_dict({k.removeprefix("features."): v for k, v in state.items()})
        _VGG = layers.eval()
    return _VGG


@torch.no_grad()
def vgg_maps(prepared: np.ndarray) -> list[torch.Tensor]:
    """relu1_2 (64, H, W) and relu2_2 (128, H/2, W/2) of a prepared grey image shown as 0.5 + 0.2 x."""
    x = torch.from_numpy(np.clip(0.5 + 0.2 * prepared, 0.0, 1.0)).float()[None, None].expand(1, 3, -1, -1)
    mean = torch.tensor(IMAGENET_MEAN).view(1, 3, 1, 1)
    std = torch.tensor(IMAGENET_STD).view(1, 3, 1, 1)
    x = (x - mean) / std
    taps = {VGG16_RELU2.relu_indices[t]: t for t in VGG16_RELU2.taps}
    out = []
    for index, layer in enumerate(vgg()):
        x = layer(x)
        if index in taps:
            out.append(x[0])
    return out


def grams(maps: list[torch.Tensor], mask: np.ndarray, boxes: Sequence[tuple[int, int]], size: int) -> list[np.ndarray]:
    """Per layer (B, C, C) masked Gram matrices of the windows ``boxes`` (image px, top-left) of side ``size``."""
    out = []
    for tensor in maps:
        fmap = tensor.numpy()  # numpy slices: torch copies these windows ~100x slower here
        stride = mask.shape[0] // fmap.shape[1]
        m = cv2.resize(mask.astype(np.float32), (fmap.shape[2], fmap.shape[1]), interpolation=cv2.INTER_AREA)
        n = size // stride
        f = np.stack([fmap[:, y // stride : y // stride + n, x // stride : x // stride + n] for y, x in boxes])
        w = np.stack([m[y // stride : y // stride + n, x // stride : x // stride + n] for y, x in boxes])
        f = f.reshape(len(boxes), fmap.shape[0], -1)
        w = w.reshape(len(boxes), 1, -1)
        g = np.matmul(f * w, f.transpose(0, 2, 1)) / np.maximum(w.sum(2), 1.0)[:, :, None]
        out.append(g.astype(np.float32))
    return out


_KERNELS: list[tuple[np.ndarray, np.ndarray]] | None = None


def gabor_kernels() -> list[tuple[np.ndarray, np.ndarray]]:
    """(even, odd) zero-mean Gabor kernels, wavelength-major then orientation (0 ... 180 degrees)."""
    global _KERNELS
    if _KERNELS is None:
        _KERNELS = []
        for lam in WAVELENGTHS:
            sigma = 0.56 * lam
            k = math.ceil(3 * sigma) * 2 + 1
            for o in range(N_ORIENT):
                theta = math.pi * o / N_ORIENT
                pair = []
                for psi in (0.0, math.pi / 2):
                    kern = cv2.getGaborKernel((k, k), sigma, theta, lam, 1.0, psi, ktype=cv2.CV_32F)
                    kern -= kern.mean()
                    pair.append(kern / np.abs(kern).sum())
                _KERNELS.append((pair[0], pair[1]))
    return _KERNELS


def gabor_energy(prepared: np.ndarray) -> np.ndarray:
    """(F*O, H, W) Gabor energies of a prepared image."""
    out = []
    for even, odd in gabor_kernels():
        e = cv2.filter2D(prepared, cv2.CV_32F, even, borderType=cv2.BORDER_CONSTANT)
        o = cv2.filter2D(prepared, cv2.CV_32F, odd, borderType=cv2.BORDER_CONSTANT)
        out.append(e * e + o * o)
    return np.stack(out)


def gabor_descriptors(energy: np.ndarray, mask: np.ndarray, boxes: Sequence[tuple[int, int]], size: int) -> np.ndarray:
    """(B, 2, F, O) per window, masked: the energy distribution over filters (sum 1) and each filter's
    sparsity mean(|r|)^2 / mean(|r|^2) (pi/4 for noise, lower where the response sits on edges)."""
    m = mask.astype(np.float32)
    amplitude = np.sqrt(energy)
    out = []
    for y, x in boxes:
        w = m[y : y + size, x : x + size]
        n = max(float(w.sum()), 1.0)
        e = (energy[:, y : y + size, x : x + size] * w).sum((1, 2)) / n
        a = (amplitude[:, y : y + size, x : x + size] * w).sum((1, 2)) / n
        out.append(np.stack([e / max(float(e.sum()), 1e-12), a * a / np.maximum(e, 1e-12)]))
    return np.stack(out).reshape(len(boxes), 2, len(WAVELENGTHS), N_ORIENT)


# ---------------------------------------------------------------------------------------------------
# Texture statistics (cached) and distances
# ---------------------------------------------------------------------------------------------------
@dataclass
class TextureStats:
    name: str
    grams: list[np.ndarray]
    """Per layer (V, C, C): one per (scale, rotation), scale-major."""
    gabor: np.ndarray
    """(S, 2, F, O): one per scale, unrotated (rotation is a cyclic shift of O)."""


def texture_stats(
    texture: np.ndarray, name: str = "", scales: Sequence[float] = SCALES, rotations: Sequence[float] = ROTATIONS
) -> TextureStats:
    """Statistics of every variant of ``texture`` (``scales`` x ``rotations``, the first rotation 0): the
    centre window of each variant patch."""
    inner = TEXTURE_PATCH - 2 * 8  # leave out the patch border (zero padding of the filters)
    box = [((TEXTURE_PATCH - inner) // 2, (TEXTURE_PATCH - inner) // 2)]
    full = np.ones((TEXTURE_PATCH, TEXTURE_PATCH), bool)
    layer_grams: list[list[np.ndarray]] = [[], []]
    gabor = []
    for height in scales:
        for angle in rotations:
            p = prepare(texture_variant(texture, height, angle))
            for k, g in enumerate(grams(vgg_maps(p), full, box, inner)):
                layer_grams[k].append(g[0])
            if angle == 0.0:
                gabor.append(gabor_descriptors(gabor_energy(p), full, box, inner)[0])
    return TextureStats(name, [np.stack(g) for g in layer_grams], np.stack(gabor))


def cached_texture_stats(path: str | os.PathLike) -> TextureStats:
    """:func:`texture_stats` of an image file, cached by its content and the measure's parameters."""
    data = Path(path).read_bytes()
    key = hashlib.sha1(data + json.dumps(PARAMS, sort_keys=True).encode()).hexdigest()[:16]
    file = CACHE / f"{Path(path).stem}-{key}.npz"
    name = Path(path).stem
    if file.is_file():
        z = np.load(file)
        return TextureStats(name, [z["gram0"], z["gram1"]], z["gabor"])
    image = cv2.cvtColor(cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    stats = texture_stats(image, name)
    CACHE.mkdir(parents=True, exist_ok=True)
    tmp = file.with_suffix(".tmp.npz")
    np.savez(tmp, gram0=stats.grams[0], gram1=stats.grams[1], gabor=stats.gabor)
    tmp.replace(file)
    return stats


def gram_distance(window_grams: list[np.ndarray], texture: TextureStats) -> np.ndarray:
    """(B,) per window: min over the texture's variants of the mean over layers of the normalised Frobenius
    distance."""
    total = 0.0
    for gw, gt in zip(window_grams, texture.grams, strict=True):
        a, b = gw.reshape(len(gw), -1), gt.reshape(len(gt), -1)
        na, nb = np.linalg.norm(a, axis=1), np.linalg.norm(b, axis=1)
        sq = np.maximum(na[:, None] ** 2 + nb[None] ** 2 - 2 * a @ b.T, 0.0)
        total = total + np.sqrt(sq) / np.maximum(na[:, None] + nb[None], 1e-12)
    return (total / len(window_grams)).min(axis=1)


def _gabor_pair(p: np.ndarray, s: np.ndarray, tp: np.ndarray, ts: np.ndarray) -> np.ndarray:
    """(B,) Hellinger distance of the energy distributions ``p``/``tp`` plus the energy-weighted mean
    difference of the sparsities ``s``/``ts`` ((B|1, F, O) each)."""
    hellinger = np.sqrt(0.5 * ((np.sqrt(p) - np.sqrt(tp)) ** 2).sum((1, 2)))
    sparsity = (0.5 * (p + tp) * np.abs(s - ts)).sum((1, 2))
    return hellinger + SPARSITY_WEIGHT * sparsity


def gabor_distance(window_desc: np.ndarray, texture: TextureStats) -> np.ndarray:
    """(B,) per window: min over scales and cyclic orientation shifts of :func:`_gabor_pair`."""
    p, s = window_desc[:, 0], window_desc[:, 1]  # (B, F, O)
    best = np.full(len(p), np.inf)
    for t in texture.gabor:  # (2, F, O)
        for shift in range(N_ORIENT):
            tp, ts = np.roll(t[0], shift, axis=1)[None], np.roll(t[1], shift, axis=1)[None]
            best = np.minimum(best, _gabor_pair(p, s, tp, ts))
    return best


@dataclass
class ViewStats:
    grams: list[np.ndarray]
    gabor: np.ndarray
    n_windows: int
    boxes: list[tuple[int, int]]
    """(y, x) of each window, in the order of ``grams`` and ``gabor``."""


def view_stats(image: np.ndarray, alpha: np.ndarray | None = None) -> ViewStats:
    """Window statistics of a render (alpha: its coverage; None = the whole image is the object)."""
    mask = np.ones(image.shape[:2], bool) if alpha is None else object_mask(alpha)
    boxes = windows(mask)
    if not boxes:
        raise ValueError(f"no {WINDOW} px window lies on the object ({int(mask.sum())} object pixels)")
    p = prepare(image, mask)
    inner = mask.astype(np.uint8)
    return ViewStats(
        grams(vgg_maps(p), inner, boxes, WINDOW),
        gabor_descriptors(gabor_energy(p), mask, boxes, WINDOW),
        len(boxes),
        boxes,
    )


def pair_distance(a: ViewStats, b: ViewStats) -> dict[str, float]:
    """Structure distance between two renders of the same view: {"gram", "gabor"}, the mean over the windows
    both lie on (the same box in each) of the window distances, no variant search (a turned or rescaled
    texture counts); {"windows"}: how many (0: none in common, distances NaN). Identical images give 0."""
    index = {box: k for k, box in enumerate(b.boxes)}
    pairs = [(k, index[box]) for k, box in enumerate(a.boxes) if box in index]
    if not pairs:
        return {"gram": math.nan, "gabor": math.nan, "windows": 0}
    ia, ib = (np.array(v) for v in zip(*pairs, strict=True))
    gram = 0.0
    for ga, gb in zip(a.grams, b.grams, strict=True):
        x, y = ga[ia].reshape(len(ia), -1), gb[ib].reshape(len(ib), -1)
        norms = np.linalg.norm(x, axis=1) + np.linalg.norm(y, axis=1)
        gram = gram + np.linalg.norm(x - y, axis=1) / np.maximum(norms, 1e-12)
    gabor = _gabor_pair(a.gabor[ia, 0], a.gabor[ia, 1], b.gabor[ib, 0], b.gabor[ib, 1])
    return {"gram": float(np.mean(gram / len(a.grams))), "gabor": float(gabor.mean()), "windows": len(pairs)}


def distances(view: ViewStats, textures: Sequence[TextureStats]) -> dict[str, dict[str, float]]:
    """{"gram": {texture: d}, "gabor": {texture: d}}: mean over the view's windows."""
    return {
        "gram": {t.name: float(gram_distance(view.grams, t).mean()) for t in textures},
        "gabor": {t.name: float(gabor_distance(view.gabor, t).mean()) for t in textures},
    }


def rank_of(scores: dict[str, float], name: str) -> int:
    """1-based position of ``name`` among ``scores`` sorted by increasing distance."""
    return 1 + sum(v < scores[name] for k, v in scores.items() if k != name)


def margin_of(scores: dict[str, float], name: str, top: int) -> float:
    """How far ``name`` stands inside (> 0) or outside (< 0) the first ``top`` of ``scores``: the ``top``-th
    smallest distance among the others less its own, over that distance. ``rank_of <= top`` exactly when it is
    >= 0; its own distance moving by less than this share of the threshold's (the others held) keeps it there."""
    others = sorted(v for k, v in scores.items() if k != name)
    if len(others) < top:
        return float("inf")
    edge = others[top - 1]
    return (edge - scores[name]) / edge if edge > 0 else float("-inf") if scores[name] > edge else 0.0
