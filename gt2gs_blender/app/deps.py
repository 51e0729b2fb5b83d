"""The engine's Python dependencies inside Blender: what is installed where, and the pip command that
installs the pinned versions into the extension's own folder (torch is too big to ship in the zip).

Blender's Python never imports these packages: the worker process gets the folder on its
``PYTHONPATH``. Versions are read from package metadata, so nothing heavy is imported to check them.
"""

from __future__ import annotations

import importlib.metadata
import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass

PINS: dict[str, str] = {
    "torch": "2.13.0",
    "numpy": "1.26.4",
    "opencv-contrib-python-headless": "4.11.0.86",
    "ninja": "1.13.0",
    "numba": "0.68.1",
}
"""The runtime packages of requirements.txt with their pinned versions (a test keeps the two equal)."""
MODULES: dict[str, str] = {"torch": "torch", "numpy": "numpy", "opencv-contrib-python-headless": "cv2"}
"""Distribution -> module the engine imports (ninja only speeds up the C++ build, numba runs the fast rasterizer
where no C++ compiler is: neither is required)."""
TORCH_INDEX = {
    "CPU": "https://download.pytorch.org/whl/cpu",
    "CUDA": "https://download.pytorch.org/whl/cu128",
}
"""Where pip finds torch builds: the CPU-only wheels (small) or the CUDA 12.8 ones."""


@dataclass(frozen=True)
class Dependency:
    """One required package: its import name, the version found (None = missing) and the pinned one."""

    distribution: str
    module: str
    version: str | None
    pinned: str

    @property
    def ok(self) -> bool:
        """Whether the package is installed at all."""
        return self.version is not None

    @property
    def matches_pin(self) -> bool:
        """Whether the installed version is the tested one (a local build tag such as ``+cpu`` aside)."""
        return self.version is not None and self.version.split("+")[0] == self.pinned


def search_path(deps_dir: str | os.PathLike | None) -> list[str]:
    """Where the worker looks for packages: the deps folder first, then this Python's own path."""
    return ([os.fspath(deps_dir)] if deps_dir else []) + [p for p in sys.path if p]


def dependency_status(deps_dir: str | os.PathLike | None = None) -> list[Dependency]:
    """The installed version of each required package, as the worker (deps folder first) will see it."""
    path = search_path(deps_dir)
    status = []
    for dist, module in MODULES.items():
        found = next(iter(importlib.metadata.distributions(name=dist, path=path)), None)
        status.append(Dependency(dist, module, None if found is None else found.version, PINS[dist]))
    return status


def install_command(
    python: str, target: str | os.PathLike, build: str = "CPU", pins: dict[str, str] | None = None
) -> list[str]:
    """The pip command installing the pinned packages into ``target`` (torch from the chosen build's index)."""
    if build not in TORCH_INDEX:
        raise ValueError(f"build must be one of {', '.join(TORCH_INDEX)}, got {build!r}")
    requirements = [f"{name}=={version}" for name, version in (pins or PINS).items()]
    return [
        python,
        "-m",
        "pip",
        "install",
        "--upgrade",
        "--no-input",
        "--disable-pip-version-check",
        "--only-binary",
        ":all:",
        "--target",
        os.fspath(target),
        "--extra-index-url",
        TORCH_INDEX[build],
        *requirements,
    ]


def worker_pythonpath(
    package_parent: str | os.PathLike, deps_dir: str | os.PathLike | None, inherited: str | None = None
) -> str:
    """PYTHONPATH for the worker: the deps folder, the folder holding the package, then what was set."""
    parts: Sequence[str | os.PathLike | None] = (deps_dir, package_parent, inherited)
    return os.pathsep.join(os.fspath(p) for p in parts if p)
