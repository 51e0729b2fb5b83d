"""The compiled CPU kernel's cache: one build per content, wherever the sources live.

A build folder is named by a hash of what decides the binary: the sources' bytes, the compiler's
``--version``, the flags, torch's version and the Python ABI. The sources are copied into that folder
and compiled from there, so the same sources in the installed extension and in a source tree share
one build (torch's own cache is keyed by the source path and would compile each copy). A finished
build leaves a marker; later loads import the library directly, without ninja or the compiler.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import logging
import os
import subprocess
import sys
import sysconfig
from pathlib import Path
from types import ModuleType

import torch

log = logging.getLogger(__name__)
NAME = "gt2gs_raster_cpu"
CSRC = Path(__file__).with_name("csrc")
SOURCE_NAMES = ("raster_cpu.cpp", "project_cpu.cpp")
LDFLAGS = ("-fopenmp",)
DONE = "build.done"
"""Written (atomically) after a build succeeded: its presence means the library is complete."""
LIB_EXT = ".pyd" if os.name == "nt" else ".so"


def vector_flags() -> list[str]:
    """Compiler flags for the kernel's 8-lane vectors: AVX2 where torch reports the CPU has it (else
    the compiler splits them into pairs of SSE/NEON registers, slower but correct)."""
    return ["-mavx2"] if torch.backends.cpu.get_cpu_capability() in ("AVX2", "AVX512") else []


def cflags() -> list[str]:
    """The kernel's compiler flags."""
    return ["-O3", "-fopenmp", "-ffp-contract=off", *vector_flags()]


def kernel_sources(csrc: Path = CSRC) -> list[Path]:
    """The kernel's C++ sources in the folder ``csrc``."""
    return [Path(csrc) / name for name in SOURCE_NAMES]


def compiler() -> str:
    """The C++ compiler torch's loader will run (``$CXX``, else c++)."""
    from torch.utils.cpp_extension import get_cxx_compiler

    return get_cxx_compiler()


@functools.lru_cache(maxsize=8)
def compiler_identity(command: str) -> str:
    """First line of ``command --version``, or why it could not run (then the build fails with a reason)."""
    try:
        result = subprocess.run([command, "--version"], capture_output=True, text=True, timeout=60, check=True)
    except (OSError, subprocess.SubprocessError) as exc:
        return f"{command}: unusable ({type(exc).__name__})"
    return result.stdout.strip().partition("\n")[0]


def build_inputs() -> dict[str, str]:
    """Everything besides the sources that decides the binary, by name."""
    return {
        "compiler": compiler_identity(compiler()),
        "torch": torch.__version__,
        "python": f"{sys.implementation.cache_tag} {sysconfig.get_config_var('EXT_SUFFIX')}",
        "cflags": " ".join(cflags()),
        "ldflags": " ".join(LDFLAGS),
    }


def build_key(sources: list[Path]) -> str:
    """16 hex digits of SHA-256 over the build inputs and the sources' names and bytes (not their paths)."""
    digest = hashlib.sha256()
    for name, value in sorted(build_inputs().items()):
        digest.update(f"{name}={value}\0".encode())
    for path in sources:
        digest.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()[:16]


def cache_base() -> Path:
    """The per-user folder of kernel builds: ``GT2GS_BUILD_DIR``, else ~/.cache/gt2gs_blender."""
    return Path(os.environ.get("GT2GS_BUILD_DIR") or Path.home() / ".cache" / "gt2gs_blender")


def build_dir(csrc: Path = CSRC) -> Path:
    """The build folder of the kernel whose sources are in ``csrc`` (same bytes, same folder)."""
    return cache_base() / f"raster_cpu-{build_key(kernel_sources(csrc))}"


def is_built(csrc: Path = CSRC) -> bool:
    """Whether the kernel of ``csrc`` is already compiled here (so loading it takes no compile)."""
    return (build_dir(csrc) / DONE).is_file()


def load(csrc: Path = CSRC) -> ModuleType:
    """The kernel built from ``csrc``: imported from its cache folder, compiled there first if needed."""
    sources = kernel_sources(csrc)
    directory = cache_base() / f"raster_cpu-{build_key(sources)}"
    return import_built(directory) or build(stage_sources(sources, directory), directory)


def import_built(directory: Path) -> ModuleType | None:
    """The library a finished build left in ``directory``, imported; None when there is none."""
    library = directory / f"{NAME}{LIB_EXT}"
    if not (directory / DONE).is_file() or not library.is_file():
        return None
    spec = importlib.util.spec_from_file_location(NAME, library)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def stage_sources(sources: list[Path], directory: Path) -> list[Path]:
    """Copies of ``sources`` in ``directory``/src, written once (the folder's key covers their bytes)."""
    staged = directory / "src"
    staged.mkdir(parents=True, exist_ok=True)
    for path in sources:
        if not (staged / path.name).is_file():
            write_atomically(staged / path.name, path.read_bytes())
    return [staged / path.name for path in sources]


def build(sources: list[Path], directory: Path) -> ModuleType:
    """Compile ``sources`` in ``directory`` with torch's loader (ninja), then mark the build done."""
    from torch.utils import cpp_extension

    log.info("compiling the CPU rasterizer kernel in %s (once per kernel version)", directory)
    module = cpp_extension.load(
        name=NAME,
        sources=[str(p) for p in sources],
        build_directory=str(directory),
        extra_cflags=cflags(),
        extra_ldflags=list(LDFLAGS),
        verbose=False,  # a copy: torch appends its own flags to the list
    )
    inputs = "".join(f"{name}: {value}\n" for name, value in build_inputs().items())
    write_atomically(directory / DONE, inputs.encode())
    return module


def write_atomically(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file and a rename (readers never see half a file)."""
    temporary = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    temporary.write_bytes(data)
    os.replace(temporary, path)
