"""Shared pytest fixtures: where ../shared is, and a deterministic torch set-up."""

from __future__ import annotations

import os
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # as gt2gs_blender.core sets it: before torch loads

import pytest

try:
    import torch
except ModuleNotFoundError:  # the Blender edge's tests also run on bpy's newer Python, which has no torch here
    torch = None

SHARED = Path(__file__).resolve().parents[1].parent / "shared"


@pytest.fixture(autouse=True)
def _seeded() -> None:
    if torch is not None:
        torch.manual_seed(0)


@pytest.fixture
def shared() -> Path:
    """The ../shared folder beside the project; tests that need it skip with the reason when absent."""
    if not SHARED.is_dir():
        pytest.skip(f"shared data folder not found at {SHARED}")
    return SHARED


@pytest.fixture(scope="session")
def donut_files(tmp_path_factory) -> dict:
    """The shared donut in every splat format (see ``splat_tools.donut_in_every_format``), made once."""
    from .splat_tools import donut_in_every_format

    return donut_in_every_format(tmp_path_factory.mktemp("formats"))
