"""The original scene as the views see it: content renders and the Gaussians no view shows
(skipped by the optimisation), cached in-process for re-runs on the same scene and views."""

from __future__ import annotations

import hashlib
from collections.abc import Sequence

import numpy as np
import torch

from ..cameras.camera import Camera
from ..render import render
from ..scene.gaussians import GaussianScene
from .config import TransferConfig
from .skips import used_sh_degree
from .views import ViewSet, render_views

_CONTENT_CACHE: dict[str, tuple[ViewSet, torch.Tensor | None]] = {}
"""The last run's content renders and hidden set, by :func:`content_key` (one entry: a re-run with
another texture, angle or schedule on the same scene and views reuses them)."""


def clear_caches() -> None:
    """Forget the in-process content cache (the disk bank cache stays)."""
    _CONTENT_CACHE.clear()


def content_degree(scene: GaussianScene, config: TransferConfig) -> int:
    """SH degree the original is rendered at: the highest band in use with ``skip_sh``, else all."""
    return used_sh_degree(scene) if config.skip_sh else scene.sh_degree


def content_key(
    scene: GaussianScene, cameras: Sequence[Camera], background: torch.Tensor, config: TransferConfig
) -> str:
    """sha256 of the scene's tensors, the cameras and every setting the content renders depend on."""
    digest = hashlib.sha256(
        repr(
            (
                config.backend,
                config.skip_sh,
                config.skip_hidden,
                config.hidden_threshold,
                background.tolist(),
                str(scene.device),
                str(scene.dtype),
            )
        ).encode()
    )
    for name, tensor in scene.tensors().items():
        digest.update(name.encode() + repr(tuple(tensor.shape)).encode())
        digest.update(tensor.detach().cpu().contiguous().numpy().tobytes())
    for cam in cameras:
        digest.update(
            repr(
                (np.asarray(cam.world_to_cam).tolist(), cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height)
            ).encode()
        )
    return digest.hexdigest()


def content_and_hidden(
    original: GaussianScene, cameras: Sequence[Camera], background: torch.Tensor, config: TransferConfig
) -> tuple[ViewSet, torch.Tensor | None]:
    """The original's renders from the cameras and its hidden Gaussians (None when not skipped or
    none), from the in-process cache when ``reuse_content`` and the same scene and views ran last."""
    key = content_key(original, cameras, background, config) if config.reuse_content else None
    if key is not None and key in _CONTENT_CACHE:
        return _CONTENT_CACHE[key]
    content = render_views(original, cameras, background, config.backend, content_degree(original, config))
    hidden = (
        hidden_gaussians(original, cameras, config.hidden_threshold, config.backend) if config.skip_hidden else None
    )
    if key is not None:
        _CONTENT_CACHE.clear()
        _CONTENT_CACHE[key] = (content, hidden)
    return content, hidden


HIDDEN_CAMERAS_PER_CALL = 4
"""Cameras rendered together when measuring each Gaussian's contribution."""


@torch.enable_grad()
def contributions(scene: GaussianScene, cameras: Sequence[Camera], backend: str = "auto") -> torch.Tensor:
    """Per Gaussian (N,), its blending weight T*alpha summed over every pixel of every camera, in
    pixels: the gradient of the summed render of a zero colour probe, so exactly what compositing
    gives it (0 for a Gaussian culled, too faint or behind opaque ones everywhere; gradients on even
    inside a caller's ``no_grad``, such as the preview's)."""
    probe = torch.zeros(len(scene), 1, dtype=scene.dtype, device=scene.device, requires_grad=True)
    geometry = scene.detach()
    start = 0
    while start < len(cameras):
        size = (cameras[start].width, cameras[start].height)
        end = start + 1
        while (
            end < len(cameras)
            and end - start < HIDDEN_CAMERAS_PER_CALL
            and (cameras[end].width, cameras[end].height) == size
        ):
            end += 1
        out = render(geometry, cameras[start:end], colors=probe, render_depth=False, backend=backend)
        out.colors.sum().backward()
        start = end
    return probe.grad[:, 0].detach() if probe.grad is not None else torch.zeros(len(scene), device=scene.device)


def hidden_gaussians(
    scene: GaussianScene, cameras: Sequence[Camera], threshold: float, backend: str = "auto"
) -> torch.Tensor | None:
    """Bool (N,): the Gaussians whose summed contribution to the views is at most ``threshold``
    pixels (no view can show a change of theirs), or None when there are none (nothing to skip)."""
    hidden = contributions(scene, cameras, backend) <= threshold
    return hidden if bool(hidden.any()) and not bool(hidden.all()) else None
