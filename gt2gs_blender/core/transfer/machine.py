"""The settings of the machine a transfer runs on (device, threads, rasterizer, feature network, weights, bank
cache): the part of ``config.TransferConfig`` Blender keeps in the add-on preferences, shared by every run."""

from __future__ import annotations

from dataclasses import dataclass
from typing import get_args

from .setting import IN_PREFERENCES, Device, FeatureNetwork, Rasterizer, setting


@dataclass(frozen=True)
class MachineSettings:
    """The machine part of a transfer's settings (``TransferConfig`` derives from it)."""

    mixed_precision: bool = setting(
        True,
        "Mixed Precision",
        "Run the feature network in float16 on a CUDA GPU, bfloat16 on a CPU with bfloat16 instructions (faster)",
        "machine",
        blender=IN_PREFERENCES,
    )
    features: FeatureNetwork = setting(
        "auto",
        "Feature Network",
        "Which feature network to use (auto: the best one found)",
        "machine",
        blender=IN_PREFERENCES,
        choices=get_args(FeatureNetwork),
    )
    weights_path: str | None = setting(
        None,
        "Weights",
        "VGG weights file or folder (default: $GT2GS_WEIGHTS_DIR, then torch's cache)",
        "machine",
        flag="--weights",
        blender=IN_PREFERENCES,
    )
    device: Device = setting(
        "auto",
        "Device",
        "Where the run computes: auto = CUDA when available",
        "machine",
        blender=IN_PREFERENCES,
        choices=get_args(Device),
    )
    threads: int = setting(
        0,
        "CPU Threads",
        "CPU threads for the run (0 = one per physical core); fewer keeps Blender responsive",
        "machine",
        min=0,
        soft_max=64,
        blender=IN_PREFERENCES,
    )
    backend: Rasterizer = setting(
        "auto",
        "Rasterizer",
        "Rasterizer backend (auto = the fastest available)",
        "machine",
        blender=IN_PREFERENCES,
        choices=get_args(Rasterizer),
    )
    cache_dir: str | None = setting(
        None,
        "Bank Cache Folder",
        "Where texture banks are cached (default: $GT2GS_CACHE_DIR, else ~/.cache/gt2gs_blender/banks)",
        "machine",
        blender=IN_PREFERENCES,
    )
