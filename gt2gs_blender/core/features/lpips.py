"""LPIPS v0.1 with the AlexNet backbone: a port of the ``lpips`` package's metric, for the consistency
metrics (the package itself imports torchvision, which cannot load beside this torch build).

Same computation as ``lpips.LPIPS(net="alex", version="0.1")``: inputs in [-1, 1] through the scaling
layer, torchvision AlexNet ``features`` tapped after relu1..relu5, each tap unit-normalised over
channels (eps 1e-10), squared difference, the learned 1x1 linear head, spatial mean, sum over the
five layers. Only the AlexNet variant is supported: the VGG head exists in ``shared/weights`` but
the VGG-16 backbone it needs is there only up to relu2_2.
"""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path

import torch
from torch import nn

from ..errors import GT2GSError
from .weights import find_weight_file, load_state_dict

BACKBONE_FILES = ("alexnet_features.pth", "alexnet-owt-7be5be79.pth")
"""AlexNet conv1-conv5 extracted for LPIPS, or torchvision's full AlexNet file from the hub cache."""
HEAD_FILE = "lpips_v0.1_alex_lin.pth"
SHIFT = (-0.030, -0.088, -0.188)
SCALE = (0.458, 0.448, 0.450)
TAP_INDICES = (1, 4, 7, 9, 11)
CHANNELS = (64, 192, 384, 256, 256)
EPS = 1e-10


def alexnet_features() -> nn.Sequential:
    """torchvision AlexNet ``features`` up to relu5 (indices 0-11)."""
    return nn.Sequential(
        nn.Conv2d(3, 64, 11, stride=4, padding=2),
        nn.ReLU(),
        nn.MaxPool2d(3, 2),
        nn.Conv2d(64, 192, 5, padding=2),
        nn.ReLU(),
        nn.MaxPool2d(3, 2),
        nn.Conv2d(192, 384, 3, padding=1),
        nn.ReLU(),
        nn.Conv2d(384, 256, 3, padding=1),
        nn.ReLU(),
        nn.Conv2d(256, 256, 3, padding=1),
        nn.ReLU(),
    )


class LPIPS(nn.Module):
    """Perceptual distance (B,) between image batches (B,3,H,W) in [0, 1]; frozen, differentiable."""

    def __init__(self, backbone: dict[str, torch.Tensor], heads: dict[str, torch.Tensor]) -> None:
        super().__init__()
        self.features = alexnet_features()
        self.features.load_state_dict(
            {k.removeprefix("features."): v for k, v in backbone.items() if k.startswith("features.")}
        )
        self.heads = nn.ModuleList(nn.Conv2d(c, 1, 1, bias=False) for c in CHANNELS)
        for i, head in enumerate(self.heads):
            head.weight.data.copy_(heads[f"lin{i}.model.1.weight"])
        self.register_buffer("shift", torch.tensor(SHIFT).reshape(1, 3, 1, 1), persistent=False)
        self.register_buffer("scale", torch.tensor(SCALE).reshape(1, 3, 1, 1), persistent=False)
        self.requires_grad_(False)
        self.eval()

    def _taps(self, images: torch.Tensor) -> list[torch.Tensor]:
        """Unit-normalised relu1..relu5 activations of images in [0, 1]."""
        x = ((2.0 * images - 1.0) - self.shift) / self.scale
        taps = []
        for index, module in enumerate(self.features):
            x = module(x)
            if index in TAP_INDICES:
                taps.append(x / (x.pow(2).sum(dim=1, keepdim=True).sqrt() + EPS))
        return taps

    def forward(self, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        """LPIPS of each pair; both batches (B,3,H,W) in [0, 1]."""
        if x.shape != y.shape or x.dim() != 4 or x.shape[1] != 3:
            raise ValueError(f"LPIPS needs two (B,3,H,W) batches of one shape, got {tuple(x.shape)}, {tuple(y.shape)}")
        layers = zip(self._taps(x), self._taps(y), self.heads)
        return sum(head((a - b).pow(2)).mean(dim=(1, 2, 3)) for a, b, head in layers)


def load_lpips(weights_path: str | os.PathLike | None = None, device: torch.device | str = "cpu") -> LPIPS:
    """LPIPS-Alex from weight files found in the order of :mod:`.weights` (the heads may also come
    from an installed ``lpips`` package); a :class:`GT2GSError` names what is missing."""
    backbone = find_weight_file(BACKBONE_FILES, weights_path)
    head = find_weight_file((HEAD_FILE,), weights_path) or _lpips_package_head()
    if backbone is None or head is None:
        missing = [name for name, path in ((" or ".join(BACKBONE_FILES), backbone), (HEAD_FILE, head)) if path is None]
        raise GT2GSError(f"LPIPS weights not found: {', '.join(missing)} (set $GT2GS_WEIGHTS_DIR)")
    try:
        return LPIPS(load_state_dict(backbone), load_state_dict(head)).to(device)
    except (KeyError, RuntimeError) as exc:  # missing or mis-shaped tensors
        raise GT2GSError(f"LPIPS weights {backbone} + {head} do not fit LPIPS-Alex v0.1: {exc}") from exc


def _lpips_package_head() -> Path | None:
    """The AlexNet head shipped inside an installed ``lpips`` package, located without importing it."""
    spec = importlib.util.find_spec("lpips")
    if spec is None or spec.origin is None:
        return None
    path = Path(spec.origin).parent / "weights" / "v0.1" / "alex.pth"
    return path if path.is_file() else None
