"""One texture-transfer job, as the command line and the Blender worker both run it.

Inputs are read and checked before any work starts (scene, texture, region, views that see the
scene); the result PLY and the report are written atomically and only on success, so a failed or
cancelled job leaves nothing behind. The front ends differ only in where progress goes and in what
they print or send afterwards.
"""

from __future__ import annotations

import contextlib
import json
import os
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path

import cv2
import numpy as np
import torch

from ..core.atomic import ZIP_MAGIC, atomic_write, read_head
from ..core.cameras.camera import Camera
from ..core.cameras.cut import cut_to_scene
from ..core.cameras.generate import auto_views
from ..core.errors import InputFileError
from ..core.progress import ProgressCallback
from ..core.render import render
from ..core.scene.files import write_splats
from ..core.scene.gaussians import GaussianScene
from ..core.transfer.config import TransferConfig
from ..core.transfer.pipeline import TransferResult, transfer
from ..core.transfer.region import region_problem
from ..core.transfer.texture import load_texture
from ..core.transfer.visibility import require_visible
from .images import write_png

STRIP_VIEWS = 4
STRIP_SIZE = 256


def load_npy(path: Path, what: str) -> np.ndarray:
    """A user's .npy file as an array; an empty, truncated or malformed one (or a pickle, or a .npz) is one line
    naming it. The file is mapped before it is copied, so a header that declares more than the file holds is
    refused rather than allocated."""
    head = b""
    with contextlib.suppress(OSError):  # a file that cannot be opened: np.load says why, below
        head = read_head(path, len(NPY_MAGIC))
    if head and not head.startswith((NPY_MAGIC[: len(head)], ZIP_MAGIC)):  # a .npz is a zip: named below
        raise InputFileError(path, f"{what} is not a .npy file (it starts with {head!r})")
    try:
        array = np.load(path, mmap_mode="r", allow_pickle=False)
    except EOFError:
        raise InputFileError(path, f"cannot read {what}: the file is empty or ends early (.npy expected)") from None
    except (OSError, ValueError, SyntaxError) as exc:
        raise InputFileError(path, f"cannot read {what} as a .npy array ({' '.join(str(exc).split())})") from None
    if not isinstance(array, np.ndarray):
        array.close()
        raise InputFileError(path, f"{what} must be one .npy array, not a .npz archive of several")
    return np.array(array)


NPY_MAGIC = b"\x93NUMPY"
"""How every .npy file starts (numpy reads anything else as a pickle, and its error says so)."""


def load_region(path: Path, n: int) -> np.ndarray:
    """A region file: a .npy of Gaussian indices, or of n booleans (True = restyle)."""
    region = load_npy(path, "the region")
    if region.dtype != np.bool_ and (not np.issubdtype(region.dtype, np.integer) or region.ndim != 1):
        raise InputFileError(
            path, f"the region must be a 1-D array of indices or booleans, got {region.dtype} {region.shape}"
        )
    problem = region_problem(region, n)
    if problem is not None:
        raise InputFileError(path, f"the region {problem}")
    return region


def read_texture(path: Path) -> np.ndarray:
    """The texture as (H,W,3) float32 in [0,1]: an image file, or pixels saved as .npy (Blender's images)."""
    if path.suffix.lower() != ".npy":
        return load_texture(path)
    image = load_npy(path, "the texture pixels")
    if image.ndim != 3 or image.shape[2] < 3 or not np.isfinite(image).all():
        raise InputFileError(path, f"texture pixels must be a finite (H, W, 3) array, got {image.shape}")
    return np.clip(image[..., :3], 0.0, 1.0).astype(np.float32)


def run_transfer(
    scene: GaussianScene,
    texture: np.ndarray,
    views: Sequence[Camera] | int | None,
    config: TransferConfig,
    output: Path,
    *,
    report: Path | None = None,
    region: np.ndarray | None = None,
    progress: ProgressCallback | None = None,
    cancel: Callable[[], bool] | None = None,
    scene_name: str | os.PathLike = "the scene",
    views_name: str | None = None,
) -> TransferResult:
    """Check that the views see the scene, re-texture it, write the result in the format ``output``'s name
    says (any writable splat format; what it drops is a warning) and the report.

    ``scene_name`` and ``views_name`` are what an error calls the scene and the views (None: automatic).
    """
    require_visible(scene, views, config, scene_name, views_name, region)
    result = transfer(scene, texture, views, config, region=region, progress=progress, cancel=cancel)
    for note in write_splats(output, result.scene):
        warnings.warn(f"{output}: {note}", stacklevel=2)
    if report is not None:
        atomic_write(report, json.dumps(result.report, indent=1, default=str))
    return result


def summary(report: dict) -> str:
    """A few lines: time per stage, the feature network (and a loud note on the fallback), the metrics."""
    stages = ", ".join(f"{k} {v:.1f}s" for k, v in report["stage_seconds"].items())
    lines = [
        f"done in {report['seconds']:.1f}s ({stages}); {report['n_gaussians']:,} Gaussians, "
        f"{report['n_views']} views at {report['image_size'][0]}x{report['image_size'][1]}"
    ]
    weights = report["weights"]
    lines.append(("WARNING, fallback features: " if weights["fallback"] else "features: ") + weights["reason"])
    metrics = report.get("metrics")
    if metrics:
        lines.append("metrics: " + ", ".join(f"{k} {v:.4f}" for k, v in metrics.items() if v is not None))
    return "\n".join(lines)


def strip_cameras(
    original: GaussianScene, views: Sequence[Camera] | int | None, up: str, kind: str = "orbit"
) -> list[Camera]:
    """The before/after strip's views, longest side ``STRIP_SIZE``: four of the run's own cameras, spread over them,
    when it was given cameras (a capture seen as it was taken); else automatic views of the run's ``kind`` (a ring,
    or the front arc) about the ``up`` axis cut to the object and enlarged to fill its cells (a wide donut shows
    larger)."""
    if views is None or isinstance(views, int):
        ring = auto_views(
            original, STRIP_VIEWS, width=STRIP_SIZE, height=STRIP_SIZE, kind=kind, elevation_deg=30.0, up=up
        )
        picked = cut_to_scene(ring, original)
    else:
        cameras = list(views)
        picked = [cameras[i * len(cameras) // STRIP_VIEWS] for i in range(min(STRIP_VIEWS, len(cameras)))]
    return [c.scaled(STRIP_SIZE / max(c.width, c.height)) for c in picked]


@torch.no_grad()
def write_before_after(
    path: Path,
    original: GaussianScene,
    stylised: GaussianScene,
    texture: np.ndarray,
    views: Sequence[Camera] | int | None = None,
    up: str = "+z",
    kind: str = "orbit",
) -> None:
    """A PNG: the texture, then the original (top) and stylised (bottom) scene from the strip's views."""
    cams = strip_cameras(original, views, up, kind)
    tiles = [torch.cat([_strip_cell(s, cam) for cam in cams], dim=1) for s in (original, stylised)]
    swatch = torch.from_numpy(cv2.resize(texture, (STRIP_SIZE, STRIP_SIZE), interpolation=cv2.INTER_AREA))
    white = torch.ones_like(swatch)
    image = torch.cat([torch.cat([swatch, tiles[0]], 1), torch.cat([white, tiles[1]], 1)], 0)
    write_png(path, (image.numpy() * 255 + 0.5).astype(np.uint8))


def _strip_cell(scene: GaussianScene, camera: Camera) -> torch.Tensor:
    """(STRIP_SIZE, STRIP_SIZE, 3) on the CPU: ``scene`` from ``camera`` (longest side ``STRIP_SIZE``) centred on
    white, so views of any shape (a capture's 4:3, a ring cut to a tall guitar) line up in the strip."""
    image = render(scene, [camera], background=(1.0, 1.0, 1.0)).colors[0].clamp(0, 1).cpu()
    cell = torch.ones(STRIP_SIZE, STRIP_SIZE, 3, dtype=image.dtype)
    top, left = (STRIP_SIZE - camera.height) // 2, (STRIP_SIZE - camera.width) // 2
    cell[top : top + camera.height, left : left + camera.width] = image
    return cell
