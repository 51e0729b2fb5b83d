"""The engine as a Python library: read and write scenes (every splat format), make or load cameras, render,
re-texture.

    from gt2gs_blender.core.api import read_scene, write_splats, auto_views, load_views, render, preset, transfer
    from gt2gs_blender.core.api import preview  # the picture a run will start from, before running it

Everything here is defined in the engine's packages; this module only gathers the public names
(importing it loads torch).
"""

from .cameras.camera import Camera
from .cameras.files import load_views
from .cameras.generate import auto_views
from .errors import GT2GSError
from .progress import Cancelled, Progress
from .render import render
from .scene.files import FORMATS, read_scene, read_splats, write_splats
from .scene.gaussians import GaussianScene
from .scene.parts import Parts, find_parts, find_parts_in
from .scene.ply import read_ply
from .scene.ply_write import write_ply
from .transfer.config import TransferConfig
from .transfer.orientation_preview import Preview, preview
from .transfer.pipeline import TransferResult, transfer
from .transfer.presets import PRESETS, preset

__all__ = [
    "FORMATS",
    "PRESETS",
    "Camera",
    "Cancelled",
    "GT2GSError",
    "GaussianScene",
    "Parts",
    "Preview",
    "Progress",
    "TransferConfig",
    "TransferResult",
    "auto_views",
    "find_parts",
    "find_parts_in",
    "load_views",
    "preset",
    "preview",
    "read_ply",
    "read_scene",
    "read_splats",
    "render",
    "transfer",
    "write_ply",
    "write_splats",
]
