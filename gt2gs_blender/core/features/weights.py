"""Where network weights come from: the resolution order of ``shared/README.md``, and the fallback.

Order: an explicit path (a file, or a folder to search first; CLI flag / add-on preference), the
folder named by ``$GT2GS_WEIGHTS_DIR``, torch's hub cache (``<hub>/checkpoints``, where torchvision
keeps ``vgg16-397923af.pth``), and a download of torchvision's VGG-16 only when the caller allows
it (``bpy.app.online_access`` in Blender). With ``preference="auto"`` the paper's VGG-16 wins
wherever it is found, then the normalised VGG-19; with neither, the result is a seeded random
VGG-19 marked ``fallback`` with a reason the caller must show (CLI, report, UI) - never silent.
A file the user named, or that sits in a folder the user named, and cannot be used is an
:class:`InputFileError`.
"""

from __future__ import annotations

import os
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from ..atomic import ZIP_MAGIC, read_head
from ..errors import GT2GSError, InputFileError
from .specs import FALLBACK_SEED, SPECS, VGG16_RELU3, VGG19_NORM_RELU3, FeatureSpec

ENV_VAR = "GT2GS_WEIGHTS_DIR"
VGG16_URL = f"https://download.pytorch.org/models/{VGG16_RELU3.weight_files[0]}"
PARTIAL_FILES = {
    "vgg16_to_relu2_2.pth": "holds VGG-16 only up to relu2_2, not enough for the paper's relu3_1-relu3_3",
}
PREFERENCES = ("auto", *SPECS)
_AUTO_ORDER = (VGG16_RELU3, VGG19_NORM_RELU3)


@dataclass(frozen=True)
class ResolvedWeights:
    """The network to build and its parameters; ``state_dict`` None means the random fallback."""

    spec: FeatureSpec
    state_dict: dict[str, torch.Tensor] | None
    weights_file: Path | None
    reason: str

    @property
    def fallback(self) -> bool:
        """True when no real weights were found (features come from a seeded random network)."""
        return self.state_dict is None

    @property
    def info(self) -> dict[str, Any]:
        """JSON-ready description for reports: spec, weights_file, fallback, reason."""
        return {
            "spec": self.spec.name,
            "weights_file": None if self.weights_file is None else str(self.weights_file),
            "fallback": self.fallback,
            "reason": self.reason,
        }


def hub_checkpoint_dir() -> Path:
    """torch's hub cache folder for checkpoints (honours ``$TORCH_HOME``)."""
    return Path(torch.hub.get_dir()) / "checkpoints"


def search_dirs(weights_path: str | os.PathLike | None = None) -> list[tuple[Path, str]]:
    """(folder, origin) pairs in resolution order; an explicit file is not a folder and is skipped."""
    explicit = _explicit(weights_path)
    dirs = [(explicit, "explicit path")] if explicit is not None and explicit.is_dir() else []
    env = os.environ.get(ENV_VAR)
    if env:
        if not Path(env).is_dir():
            raise InputFileError(env, f"${ENV_VAR} names a folder that does not exist")
        dirs.append((Path(env), f"${ENV_VAR}"))
    return [*dirs, (hub_checkpoint_dir(), "torch hub cache")]


def find_weight_file(names: Sequence[str], weights_path: str | os.PathLike | None = None) -> Path | None:
    """The first file called one of ``names`` in the search folders, in resolution order."""
    found = _first_file(names, search_dirs(weights_path))
    return None if found is None else found[0]


def _first_file(names: Sequence[str], dirs: Sequence[tuple[Path, str]]) -> tuple[Path, str] | None:
    """(path, origin) of the first existing ``folder/name``, folders first, then names."""
    for folder, origin in dirs:
        for name in names:
            if (folder / name).is_file():
                return folder / name, origin
    return None


def load_state_dict(path: str | os.PathLike) -> dict[str, torch.Tensor]:
    """A state dict of tensors from a ``.pth`` file; any problem is an :class:`InputFileError`.

    Zip-format files are memory-mapped so that only the tensors used are read (the full VGG-16
    file is 528 MB, of which the features to relu3_3 are 7 MB).
    """
    _require_torch_file(path)
    try:
        data = torch.load(path, map_location="cpu", weights_only=True, mmap=zipfile.is_zipfile(path))
    except Exception as exc:  # torch.load raises many types for truncated or foreign files
        first = (str(exc).strip().splitlines() or [""])[0].split(". ")[0]
        raise InputFileError(path, f"cannot read it as PyTorch weights ({type(exc).__name__}: {first})") from exc
    if not isinstance(data, dict) or not all(isinstance(v, torch.Tensor) for v in data.values()):
        raise InputFileError(path, "is not a state dict of tensors")
    return data


def _require_torch_file(path: str | os.PathLike) -> None:
    """Refuse a file that is neither of torch.save's formats (a zip archive, or a pickle: protocol byte 0x80) before
    torch reads it, whose errors for a foreign file say nothing about the file."""
    try:
        head = read_head(path, len(ZIP_MAGIC))
    except OSError as exc:
        raise InputFileError(path, f"cannot read the weights ({exc.strerror or exc})") from None
    if not head.startswith((ZIP_MAGIC, b"\x80")):
        raise InputFileError(path, f"is not a PyTorch weights file (.pth); it starts with {head!r}")


def resolve_weights(
    preference: str = "auto",
    weights_path: str | os.PathLike | None = None,
    *,
    allow_download: bool = False,
) -> ResolvedWeights:
    """The feature network's weights, in the documented order; see the module docstring.

    ``preference`` is ``auto`` or a spec name (``vgg16_relu3``, ``vgg19_norm_relu3``); a named spec
    that cannot be found is an error rather than a fallback.
    """
    if preference not in PREFERENCES:
        raise GT2GSError(f"unknown feature network {preference!r}; choose one of {', '.join(PREFERENCES)}")
    specs = _AUTO_ORDER if preference == "auto" else (SPECS[preference],)
    explicit = _explicit(weights_path)
    if explicit is not None and explicit.is_file():
        return _from_file(explicit, specs, "explicit path", [])
    dirs = search_dirs(explicit)
    notes = [
        f"{folder / name} {why}"
        for folder, _ in dirs
        for name, why in PARTIAL_FILES.items()
        if (folder / name).is_file()
    ]
    for spec in specs:
        found = _first_file(spec.weight_files, dirs)
        if found is not None:
            return _from_file(found[0], (spec,), found[1], notes)
        notes.append(f"no {' or '.join(spec.weight_files)} found")
    if allow_download and VGG16_RELU3 in specs:
        return _from_file(download_vgg16(allow_download), (VGG16_RELU3,), "download", notes)
    searched = ", ".join(f"{folder} ({origin})" for folder, origin in dirs)
    if preference != "auto":
        raise GT2GSError(f"{preference} weights not found ({'; '.join(notes)}; searched {searched})")
    return ResolvedWeights(
        VGG19_NORM_RELU3,
        None,
        None,
        (
            f"FALLBACK: randomly initialised VGG-19 (seed {FALLBACK_SEED}) - texture features are not ImageNet "
            f"features and results will be weaker; {'; '.join(notes)}; searched {searched}. Put "
            f"{VGG16_RELU3.weight_files[0]} in one of those folders or set ${ENV_VAR}."
        ),
    )


def download_vgg16(allow_download: bool) -> Path:
    """Download torchvision's VGG-16 into the hub cache (hash-checked) and return its path.

    Only on explicit request where network access is allowed; the file is downloaded, not
    loaded whole, so that :func:`load_state_dict` can map just the layers it needs.
    """
    if not allow_download:
        raise GT2GSError("downloading the VGG-16 weights needs explicit permission (allow_download)")
    path = hub_checkpoint_dir() / VGG16_RELU3.weight_files[0]
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        torch.hub.download_url_to_file(VGG16_URL, str(path), hash_prefix=path.stem.split("-")[-1])
    except Exception as exc:  # URLError, hash mismatch, disk errors: all mean "no weights from there"
        raise GT2GSError(f"could not download {VGG16_URL}: {exc}") from exc
    return path


def _explicit(weights_path: str | os.PathLike | None) -> Path | None:
    """The user's explicit path, which must exist."""
    if weights_path is None:
        return None
    path = Path(weights_path).expanduser()
    if not path.exists():
        raise InputFileError(path, "weights file or folder not found")
    return path


def _from_file(path: Path, specs: Sequence[FeatureSpec], origin: str, notes: list[str]) -> ResolvedWeights:
    """The first spec whose parameters ``path`` holds, else an InputFileError saying what it holds."""
    state_dict = load_state_dict(path)
    for spec in specs:
        expected = spec.parameter_shapes()
        if all(k in state_dict and tuple(state_dict[k].shape) == s for k, s in expected.items()):
            kept = {k: state_dict[k].clone() for k in expected}  # detach from the memory map
            reason = "; ".join([f"{spec.description}, from {path} ({origin})", *notes])
            return ResolvedWeights(spec, kept, path, reason)
    convs = sorted(
        int(k.split(".")[1])
        for k, v in state_dict.items()
        if k.startswith("features.") and k.endswith(".weight") and v.dim() == 4
    )
    needs = ", ".join(
        f"{s.name} needs conv layers {sorted({int(k.split('.')[1]) for k in s.parameter_shapes()})}" for s in specs
    )
    raise InputFileError(path, f"holds conv layers features.{convs} (too few, or other shapes); {needs}")
