"""The paper's evaluation metrics, measured on a run's own views (paper Tab. 1 and the cost table); the content
measures on every other view (``MEASURE_STRIDE``) at one size, ``MEASURE_SIDE``, whatever size the run worked at.

- ``ssim``: the paper's content preservation, SSIM of each stylised render vs the original render over the
  whole frame, mean over views (a small object on a plain backdrop scores high whatever happens to it).
- ``object_ssim``: content a user can trust, SSIM of the luminance (``tone.luma``) over the windows centred on
  the pixels the original covers (the object's pixels; for a capture that fills the view, the frame): whether the
  scene's edges, light and dark are still there, whatever colour the texture gave them (the texture's colour is what
  a run is for); ``object_ssim_blurred`` the same after blurring both renders to the object's scale (``OBJECT_BLUR``):
  whether the object's parts, light and dark still lie where they did once the texture's own detail is set aside.
  ``bench/recognise.py``'s content is the same measure on held-out views. Neither enters the optimisation.
- ``st_*`` / ``lt_*``: multi-view consistency, short range (view i vs i+1) and long range (i vs i+7):
  render i is warped into view j by rendered depth and the known poses (exact for our scenes, where
  peers estimate optical flow), then compared with render j over valid pixels only (covered in
  both views, not occluded, inside the source) by RMSE and LPIPS-Alex, averaged over pairs.
- ``texture_match``: mean cosine distance of each rendered feature cell the object covers to its
  nearest texture-bank feature (lower = closer to the texture; background cells are left out).
- ``preview_ssim``: whether the preview predicted the run: SSIM of the luminance of the result's render and
  the preview of the first view (``orientation_preview.preview``), over the pixels the result covers
  (1 = the picture the artist approved; the original scene's detail or grain in its place lowers it).
- render FPS and peak memory.
Images are channels-last (V,H,W,3) in [0, 1], as the rasterizer renders them.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

import numpy as np
import torch
import torch.nn.functional as F

from ..cameras.camera import Camera
from ..cameras.warp import MIN_ALPHA, expected_depth, warp_image
from ..features.extractor import FeatureExtractor
from ..features.lpips import LPIPS
from ..features.window import selected_features
from ..render import render
from ..scene.gaussians import GaussianScene
from ..train.ssim import WINDOW, gaussian_window, ssim_map
from .losses import cosine_distance, nearest_features
from .texture_bank import covered_cells
from .tone import luma

SHORT_RANGE = 1
LONG_RANGE = 7
COVERED = 0.5
"""Pixels the result covers at least this much count in ``preview_ssim``."""
MEASURE_SIDE = 512
"""Longest side of the views the content measures (``ssim``, ``object_ssim``, ``object_ssim_blurred``) judge a result
at, whatever size the run worked at: about the size an object takes in a Blender viewport, and one size for every
run, so two runs' numbers compare."""
MEASURE_STRIDE = 2
"""The content measures read every this-many-th of a run's views (half of a 16-view ring, evenly around it): the
renders at ``MEASURE_SIDE`` are most of the measure's cost (2.5 s of a donut result's 3.8 s with all 16)."""
OBJECT_BLUR = 1.0 / 20.0
"""``object_ssim_blurred``'s Gaussian sigma, as a share of the object's size in the view (the square root of
the pixels it covers): about 5 px for the donut at 256 px, wider than a texture's grain, narrower than a part."""
BLOCK_BYTES = 64 * 2**20
"""Largest similarity block texture_match builds at once."""


@torch.no_grad()
def content_metrics(
    stylised: torch.Tensor, original: torch.Tensor, covered: torch.Tensor | None = None
) -> dict[str, float | None]:
    """``{ssim}`` (the paper's, over the colour channels) of stylised renders (V,H,W,3) against the original's, and
    ``object_ssim`` / ``object_ssim_blurred`` (:func:`object_ssim`) over the ``covered`` (V,H,W) pixels of the
    original when given."""
    out: dict[str, float | None] = {"ssim": _mean([float(ssim_map(a, b).mean()) for a, b in zip(stylised, original)])}
    if covered is not None:
        out["object_ssim"] = object_ssim(stylised, original, covered)
        out["object_ssim_blurred"] = object_ssim(stylised, original, covered, blurred=True)
    return out


@torch.no_grad()
def object_ssim(
    stylised: torch.Tensor, original: torch.Tensor, covered: torch.Tensor, *, blurred: bool = False
) -> float | None:
    """Mean over views of the luminance SSIM of stylised and original renders (V, H, W, 3) over the windows centred
    on the ``covered`` (V, H, W) pixels, each view's pair first blurred to the object's scale when ``blurred``; None
    when no view covers a window."""
    scores = []
    for image, reference, mask in zip(luminance(stylised), luminance(original), covered):
        if blurred and bool(mask.any()):
            sigma = OBJECT_BLUR * float(mask.sum()) ** 0.5
            image, reference = gaussian_blur(torch.stack([image, reference]), sigma)
        score = masked_ssim(image, reference, mask)
        if score is not None:
            scores.append(score)
    return _mean(scores)


def luminance(images: torch.Tensor) -> torch.Tensor:
    """The luminance (..., H, W, 1) of (..., H, W, 3) images as one channel: what content is judged on."""
    return luma(images)[..., None]


def gaussian_blur(images: torch.Tensor, sigma: float) -> torch.Tensor:
    """(..., H, W, C) blurred by a Gaussian of ``sigma`` pixels (kernel 2 ceil(3 sigma) + 1, mirrored edges, as
    OpenCV), as a product of spectra: the object's-scale sigma grows with the views' size, and a direct
    convolution's cost with it (2 s of a donut run's finish at 512 px)."""
    radius = min(int(np.ceil(3.0 * sigma)), min(images.shape[-3:-1]) - 1)
    if sigma <= 0.0 or radius < 1:
        return images
    height, width = images.shape[-3:-1]
    x = images.reshape(-1, height, width, images.shape[-1]).permute(0, 3, 1, 2)
    x = F.pad(x, (radius, radius, radius, radius), mode="reflect")
    rows, cols = x.shape[-2:]
    window = gaussian_window(2 * radius + 1, sigma, dtype=torch.float64, device=x.device)
    # a circular convolution of the padded image: exact on the centre, where the window never wraps
    data = torch.fft.rfft2(x)
    kernel = torch.fft.fft(_centred(window, rows))[:, None] * torch.fft.rfft(_centred(window, cols))[None, :]
    y = torch.fft.irfft2(data * kernel.to(data.dtype), s=(rows, cols))
    y = y[..., radius : radius + height, radius : radius + width]
    return y.permute(0, 2, 3, 1).reshape(images.shape)


def _centred(window: torch.Tensor, size: int) -> torch.Tensor:
    """``window`` (2r+1,) in a ring of ``size`` with its centre at index 0 (the kernel of a circular convolution)."""
    ring = torch.zeros(size, dtype=window.dtype, device=window.device)
    ring[: len(window)] = window
    return torch.roll(ring, -(len(window) // 2))


@torch.no_grad()
def preview_ssim(
    result: GaussianScene, preview: np.ndarray, camera: Camera, background: torch.Tensor, backend: str = "auto"
) -> float | None:
    """SSIM of the luminance of ``result`` rendered from ``camera`` and ``preview`` (H, W, 3 uint8 of that
    view at the camera's size) over the pixels the result covers; None when it covers none."""
    out = render(result.detach(), [camera], background=background, backend=backend)
    shown = torch.from_numpy(np.ascontiguousarray(preview)).to(out.colors) / 255.0
    return masked_ssim(luminance(out.colors[0].clamp(0.0, 1.0)), luminance(shown), out.alphas[0] > COVERED)


@torch.no_grad()
def masked_ssim(image: torch.Tensor, reference: torch.Tensor, covered: torch.Tensor) -> float | None:
    """Mean SSIM of two (H, W, C) images over the windows centred on ``covered`` (H, W) pixels: an object's
    likeness without the background around it; None when no window is centred on a covered pixel."""
    per_window = ssim_map(image, reference)[0].mean(0)  # (H-10, W-10): the windows inside the image
    half = WINDOW // 2
    inside = covered[half:-half, half:-half].to(per_window.device)
    return float(per_window[inside].mean()) if bool(inside.any()) else None


@torch.no_grad()
def consistency(
    images: torch.Tensor,
    depths: torch.Tensor,
    alphas: torch.Tensor,
    cameras: Sequence[Camera],
    pairs_offset: int,
    *,
    lpips: LPIPS | None = None,
    min_alpha: float = MIN_ALPHA,
) -> dict[str, float | None]:
    """Warped-render error over the pairs (i, i + ``pairs_offset``): ``{rmse, lpips}``, None without pairs.

    ``depths`` are the rasterizer's sum T*alpha*z (divided by alpha here). RMSE is over valid pixels and
    channels of each pair; a pair without a valid pixel is left out. LPIPS sees both images with invalid
    pixels set to 0 in both, so masked areas add zero distance and dilute the mean by the invalid fraction
    (as in the peers' masked LPIPS); ``lpips`` None skips it.
    """
    z = expected_depth(depths, alphas, min_alpha)
    rmses, lpipses = [], []
    for i in range(len(cameras) - pairs_offset):
        j = i + pairs_offset
        warp = warp_image(
            images[i], z[i], cameras[i], cameras[j], z[j], src_alpha=alphas[i], dst_alpha=alphas[j], min_alpha=min_alpha
        )
        if not warp.valid.any():
            continue
        target = torch.where(warp.valid[..., None], images[j], torch.zeros_like(images[j]))
        rmses.append(float((warp.image - target)[warp.valid].pow(2).mean().sqrt()))
        if lpips is not None:
            lpipses.append(float(lpips(*(x.permute(2, 0, 1)[None] for x in (warp.image, target)))))
    return {"rmse": _mean(rmses), "lpips": _mean(lpipses)}


def _mean(values: list[float]) -> float | None:
    """Arithmetic mean, None for no values."""
    return sum(values) / len(values) if values else None


@torch.no_grad()
def texture_match(features: torch.Tensor, bank_features: torch.Tensor, block_bytes: int = BLOCK_BYTES) -> float:
    """Mean over rendered features (N,C) of the cosine distance to the nearest bank feature (M,C).

    The same nearest-feature search as the NNFM loss, in blocks of at most ``block_bytes``.
    """
    if features.dim() != 2 or bank_features.dim() != 2 or features.shape[1] != bank_features.shape[1]:
        shapes = f"{tuple(features.shape)}, {tuple(bank_features.shape)}"
        raise ValueError(f"texture_match needs (N,C) and (M,C) features, got {shapes}")
    nearest = nearest_features(features, bank_features, chunk_bytes=block_bytes)
    return float(cosine_distance(features, bank_features[nearest].to(features)).mean())


def peak_memory_mib(device: torch.device | str = "cpu") -> dict[str, float | None]:
    """Process RSS high-water mark and, on CUDA, torch's peak allocated memory, in MiB."""
    try:
        import resource  # POSIX only; Blender's worker may run on Windows
    except ImportError:
        rss_mib = None
    else:
        rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # KiB on Linux, bytes on macOS
        rss_mib = rss / 2**20 if sys.platform == "darwin" else rss / 2**10
    device = torch.device(device)
    cuda = torch.cuda.max_memory_allocated(device) / 2**20 if device.type == "cuda" else None
    return {"rss_peak_mib": rss_mib, "cuda_peak_mib": cuda}


@torch.no_grad()
def evaluate(
    stylised: torch.Tensor,
    depths: torch.Tensor,
    alphas: torch.Tensor,
    cameras: Sequence[Camera],
    content: tuple[torch.Tensor, torch.Tensor, torch.Tensor | None],
    *,
    lpips: LPIPS | None = None,
    extractor: FeatureExtractor | None = None,
    bank_features: torch.Tensor | None = None,
) -> dict[str, float | None]:
    """``{st_rmse, st_lpips, lt_rmse, lt_lpips, texture_match}`` of stylised renders (V,H,W,3) and the content
    measures (:func:`content_metrics`) of ``content``: (stylised, original, covered or None) renders, which may be
    other views or another size than the stylised ones (a run's are every other view at ``MEASURE_SIDE``).

    ``depths``/``alphas`` are the stylised renders' raw depth and alpha; texture_match needs the
    feature ``extractor`` and the texture bank's features (M,C), else it is None.
    """
    out = content_metrics(*content)
    for prefix, offset in (("st", SHORT_RANGE), ("lt", LONG_RANGE)):
        scores = consistency(stylised, depths, alphas, cameras, offset, lpips=lpips)
        out[f"{prefix}_rmse"], out[f"{prefix}_lpips"] = scores["rmse"], scores["lpips"]
    out["texture_match"] = None
    if extractor is not None and bank_features is not None:
        # a view at a time (VGG memory); only the cells the object covers: the background takes no texture
        features = torch.cat([covered_features(extractor, image, alpha) for image, alpha in zip(stylised, alphas)])
        out["texture_match"] = texture_match(features, bank_features)
    return out


def covered_features(extractor: FeatureExtractor, image: torch.Tensor, alpha: torch.Tensor) -> torch.Tensor:
    """The feature vectors (n, C) of the covered cells (:func:`covered_cells` of ``alpha``) of one (H,W,3) image,
    the network run on the crop they need only."""
    return selected_features(extractor, image.permute(2, 0, 1)[None], lambda hw: covered_cells(alpha, hw))
