"""The engine's Python dependencies inside Blender: what is installed where, and the pip command that
installs the pinned versions into the extension's own folder (torch is too big to ship in the zip).

Blender's Python never imports these packages: the worker process gets the folder on its ``PYTHONPATH``.
``dependency_status`` reads versions from package metadata (nothing heavy is imported, so the preferences
can draw it); ``import_check`` imports each package, and runs in the worker's Python as part of the machine
check, since a package built for another Python has metadata but does not load.
"""

from __future__ import annotations

import importlib.metadata
import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass

PINS_BY_PYTHON: dict[tuple[int, int], dict[str, str]] = {
    (3, 11): {
        "torch": "2.13.0",
        "numpy": "1.26.4",
        "opencv-contrib-python-headless": "4.11.0.86",
        "ninja": "1.13.0",
        "numba": "0.68.1",
    },
    (3, 13): {
        "torch": "2.13.0",
        "numpy": "2.4.6",
        "opencv-contrib-python-headless": "4.11.0.86",
        "ninja": "1.13.0",
        "numba": "0.68.1",
    },
}
"""The runtime packages with their pinned versions for each Python a supported Blender runs (4.5 and 5.0:
3.11, requirements.txt's, which a test keeps equal; 5.1 and 5.2: 3.13, with numpy 2, as 1.26 has no wheel for
it and requirements-py313.txt's numpy)."""
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


def pinned_packages(version: tuple[int, int] | None = None) -> dict[str, str]:
    """The pinned packages for Python ``version`` (this one by default); ValueError for a Python with none."""
    version = version or sys.version_info[:2]
    if version not in PINS_BY_PYTHON:
        tested = ", ".join(f"{major}.{minor}" for major, minor in PINS_BY_PYTHON)
        raise ValueError(f"no tested packages for Python {version[0]}.{version[1]} (tested: {tested})")
    return PINS_BY_PYTHON[version]


def search_path(deps_dir: str | os.PathLike | None) -> list[str]:
    """Where the worker looks for packages: the deps folder first, then this Python's own path."""
    return ([os.fspath(deps_dir)] if deps_dir else []) + [p for p in sys.path if p]


def dependency_status(deps_dir: str | os.PathLike | None = None) -> list[Dependency]:
    """The installed version of each required package, as the worker (deps folder first) will see it."""
    path = search_path(deps_dir)
    pinned = PINS_BY_PYTHON.get(sys.version_info[:2], {})
    status = []
    for dist, module in MODULES.items():
        found = next(iter(importlib.metadata.distributions(name=dist, path=path)), None)
        status.append(Dependency(dist, module, None if found is None else found.version, pinned.get(dist, "none")))
    return status


def import_check() -> dict[str, dict[str, str | None]]:
    """Each required package imported in this Python: module -> its version, or why it does not load."""
    found: dict[str, dict[str, str | None]] = {}
    for module in MODULES.values():
        try:
            loaded = importlib.import_module(module)
        except Exception as exc:  # any failure to load is what the user must see (ImportError, OSError, ...)
            found[module] = {"version": None, "error": load_error(exc)}
        else:
            found[module] = {"version": str(getattr(loaded, "__version__", "?")), "error": None}
    return found


def load_error(exc: BaseException) -> str:
    """One line for a failed import: the innermost error it was raised from (a compiled part that does not
    load, as in a package built for another Python, rather than the advice printed around it), first line."""
    while (exc.__cause__ or exc.__context__) is not None:
        exc = exc.__cause__ or exc.__context__
    text = next((part.strip() for part in str(exc).splitlines() if part.strip()), "")
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def install_command(python: str, target: str | os.PathLike, build: str = "CPU") -> list[str]:
    """The pip command installing this Python's pinned packages into ``target`` (torch from the chosen build's
    index); ``python`` is this Python, as Blender runs it."""
    if build not in TORCH_INDEX:
        raise ValueError(f"build must be one of {', '.join(TORCH_INDEX)}, got {build!r}")
    requirements = [f"{name}=={version}" for name, version in pinned_packages().items()]
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
