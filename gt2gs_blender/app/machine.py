"""What a run would use on this machine: feature weights, rasterizer (and why), C++ compiler, numba, CUDA, kernel cache.

``python -m gt2gs_blender.app.machine [--weights PATH] [--features F] [--backend B] [--device D] [--download]``
prints it as one JSON object on stdout, with ``packages``: each required package imported here (its version,
or why it does not load; then the object is ``{"error": ..., "packages": ...}``). Blender runs it with the
worker's Python (torch never loads into Blender) to fill its preferences and to know whether CUDA is there;
``--download`` first fetches
torchvision's VGG-16 weights into torch's hub cache. Nothing is compiled here: the kernel's state is read
from its cache.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from typing import Any

from ..core.errors import GT2GSError
from .deps import import_check

RASTERIZERS = {
    "cpu": "compiled CPU kernel",
    "numba": "CPU kernel through numba",
    "torch": "portable torch",
    "gsplat": "gsplat CUDA",
}
"""What the preferences call each rasterizer backend."""


def compiler_found() -> str | None:
    """The C++ compiler's ``--version`` line, None when there is no usable compiler."""
    from ..core.render import kernel_cache

    command = kernel_cache.compiler()
    if shutil.which(command) is None:
        return None
    identity = kernel_cache.compiler_identity(command)
    return None if "unusable" in identity else identity


def numba_found() -> str | None:
    """numba's version when it is installed (read from its metadata, nothing imported), else None."""
    import importlib.metadata

    try:
        return importlib.metadata.version("numba")
    except importlib.metadata.PackageNotFoundError:
        return None


def rasterizer(backend: str, cuda: bool, compiler: str | None, built: bool, numba: str | None = None,
               numba_compiled: bool = False) -> tuple[str, str]:  # fmt: skip
    """(backend, note: why) a run with ``backend`` would use, as ``core.render.resolve_backend`` picks it,
    without building the kernel; ``numba``: its version, None when it is not installed."""
    from ..core.render import gsplat_backend

    if cuda and backend != "torch":
        if gsplat_backend.available():
            return "gsplat", "CUDA kernels"
        return "torch", "on the GPU (install gsplat for the faster CUDA rasterizer)"
    if backend == "torch":
        return "torch", "chosen in the preferences"
    if backend != "numba":
        if built:
            return "cpu", "built"
        if compiler is not None:
            return "cpu", "compiled at the first run (about a minute, once)"
    why = "chosen in the preferences" if backend == "numba" else "no C++ compiler found"
    if numba is not None:
        when = "compiled" if numba_compiled else "compiled at the first run (about a minute, once)"
        return "numba", f"{why}; the same kernel through numba {numba}, {when}"
    return "torch", f"{why} and numba is not installed, so the portable (slower) rasterizer runs"


def machine_info(
    weights_path: str | None = None, features: str = "auto", backend: str = "auto", device: str = "auto"
) -> dict[str, Any]:
    """A JSON-ready description of what a run with these machine settings would use."""
    import torch

    from ..core.device import resolve_device
    from ..core.features.extractor import precision_note
    from ..core.features.weights import VGG16_URL, resolve_weights, search_dirs
    from ..core.render import kernel_cache, numba_backend

    cuda = torch.cuda.is_available()
    info: dict[str, Any] = {
        "torch": torch.__version__,
        "cuda": cuda,
        "cuda_device": torch.cuda.get_device_name(0) if cuda else None,
        "threads": torch.get_num_threads(),
        "download_url": VGG16_URL,
    }
    try:
        info["device"] = str(resolve_device(device))
    except GT2GSError as exc:
        info["device"], info["device_error"] = "cpu", str(exc)
    try:
        info["weights"] = resolve_weights(features, weights_path).info
        info["weights_folders"] = [str(folder) for folder, _ in search_dirs(weights_path)]
    except GT2GSError as exc:
        info["weights"] = {"spec": None, "weights_file": None, "fallback": True, "reason": str(exc), "error": True}
        info["weights_folders"] = []
    info["precision"], info["precision_note"] = precision_note(info["device"])
    compiler = compiler_found()
    built = kernel_cache.is_built()
    numba = numba_found()
    numba_compiled = numba is not None and numba_backend.is_compiled()
    name, note = rasterizer(backend, info["device"] == "cuda", compiler, built, numba, numba_compiled)
    info.update(
        compiler=compiler,
        numba=numba,
        numba_compiled=numba_compiled,
        kernel_cache=str(kernel_cache.cache_base()),
        kernel_built=built,
        rasterizer=name,
        rasterizer_label=RASTERIZERS[name],
        rasterizer_note=note,
    )
    return info


def _problem(module: str, error: str) -> str:
    """What is wrong with a required package, in a few words."""
    if error == f"ModuleNotFoundError: No module named '{module}'":
        return f"{module} is not installed"
    return f"{module} does not load: {error}"


def main(argv: list[str] | None = None) -> int:
    """Print the machine description as JSON (after downloading the weights when asked); 1 on an error."""
    parser = argparse.ArgumentParser(prog="python -m gt2gs_blender.app.machine", description=__doc__)
    parser.add_argument("--weights", default=None)
    parser.add_argument("--features", default="auto")
    parser.add_argument("--backend", default="auto")
    parser.add_argument("--device", default="auto")
    parser.add_argument("--download", action="store_true", help="download torchvision's VGG-16 weights first")
    args = parser.parse_args(argv)
    packages = import_check()
    broken = [_problem(module, found["error"]) for module, found in packages.items() if found["error"]]
    if broken:
        advice = " (Install Dependencies installs them for this Python)"
        print(json.dumps({"error": "; ".join(broken) + advice, "packages": packages}))
        return 1
    try:
        if args.download:
            from ..core.features.weights import download_vgg16

            download_vgg16(True)
        info = machine_info(args.weights, args.features, args.backend, args.device)
    except GT2GSError as exc:
        print(json.dumps({"error": str(exc), "packages": packages}))
        return 1
    print(json.dumps(info | {"packages": packages}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
