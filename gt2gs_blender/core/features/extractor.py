"""VGG feature extractor: one network type, parameterised by a :class:`FeatureSpec`.

The paper matches rendered and texture features of torchvision's ImageNet VGG-16 at relu3_1, relu3_2 and
relu3_3 (768 channels), on renders downscaled x0.5 before the network. Where those weights do not exist (no
internet, no cached copy) the normalised VGG-19 to relu3_1 is the closest real substitute (relu2_1 + relu3_1
by default). Both are plain ``nn.Sequential`` stacks with torchvision's layer indices
(``features.N.weight``), so torchvision state dicts load unchanged; torchvision itself cannot be imported
beside the torch CPU wheel used here (docs/architecture.md, "Feature network and weights"). Which weights
are found, and the reported no-weights fallback, is :mod:`.weights`' business.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import torch
import torch.nn.functional as F
from torch import nn

if TYPE_CHECKING:
    from .weights import ResolvedWeights
from .specs import FALLBACK_SEED, IMAGENET_MEAN, IMAGENET_STD, RENDER_SCALE, FeatureSpec


def build_layers(spec: FeatureSpec) -> nn.Sequential:
    """The ``features`` stack of ``spec`` up to its deepest tap, torchvision indices."""
    make = {
        "conv": lambda c_in, c_out: nn.Conv2d(c_in, c_out, 3, padding=1, padding_mode=spec.padding),
        "relu": lambda c_in, c_out: nn.ReLU(),
        "pool": lambda c_in, c_out: nn.MaxPool2d(2, 2),
    }
    return nn.Sequential(*(make[kind](c_in, c_out) for kind, _, c_in, c_out in spec.stack[: spec.depth]))


def random_init_(layers: nn.Sequential, seed: int = FALLBACK_SEED) -> None:
    """Deterministic Kaiming init (torchvision's VGG init: normal, fan_out, zero bias)."""
    generator = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for module in layers:
            if isinstance(module, nn.Conv2d):
                nn.init.kaiming_normal_(module.weight, mode="fan_out", nonlinearity="relu", generator=generator)
                module.bias.zero_()


def resize(x: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    """Bilinear, antialiased resize of (B,C,H,W) (a no-op at the same size)."""
    if tuple(x.shape[-2:]) == tuple(size):
        return x
    return F.interpolate(x, size=size, mode="bilinear", antialias=True, align_corners=False)


def scaled_size(height: int, width: int, scale: float) -> tuple[int, int]:
    """Image size after scaling by ``scale``, rounded as :meth:`Camera.scaled` rounds."""
    return max(1, round(height * scale)), max(1, round(width * scale))


class FeatureExtractor(nn.Module):
    """Frozen VGG features of images in [0, 1]: (B,3,H,W) -> (B,C,h,w), differentiable w.r.t. images.

    ``scale`` (default the paper's 0.5) resizes the input before the network; pass ``scale=1`` to
    ``forward`` for images that are already at the wanted size (e.g. texture crops). ``info``
    says exactly which network and weights were loaded, and whether this is the fallback;
    ``fingerprint`` changes whenever the spec, the scale or a parameter does (a cache key).
    """

    def __init__(
        self,
        spec: FeatureSpec,
        weights: ResolvedWeights,
        scale: float = RENDER_SCALE,
        autocast: torch.dtype | None = None,
    ) -> None:
        super().__init__()
        self.spec = spec
        self.scale = float(scale)
        self.autocast = autocast
        self.layers = build_layers(spec)
        if weights.state_dict is None:
            random_init_(self.layers)
        else:
            self._load(weights.state_dict)
        self._tap_indices = frozenset(spec.relu_indices[t] for t in spec.taps)
        self.register_buffer("mean", torch.tensor(IMAGENET_MEAN).reshape(1, 3, 1, 1), persistent=False)
        self.register_buffer("std", torch.tensor(IMAGENET_STD).reshape(1, 3, 1, 1), persistent=False)
        self.requires_grad_(False)
        self.eval()
        self.fingerprint = self._fingerprint()
        self.info: dict[str, Any] = {
            **weights.info,
            "spec": spec.name,
            "channels": spec.out_channels,
            "fingerprint": self.fingerprint,
            "autocast": None if autocast is None else str(autocast).removeprefix("torch."),
        }

    def _fingerprint(self) -> str:
        """Short SHA-256 of the spec, the scale and every parameter's bytes."""
        digest = hashlib.sha256(repr((self.spec, self.scale, self.autocast)).encode())
        for tensor in self.layers.state_dict().values():
            digest.update(tensor.detach().cpu().contiguous().numpy().tobytes())
        return digest.hexdigest()[:16]

    def _load(self, state_dict: Mapping[str, torch.Tensor]) -> None:
        """Copy the spec's parameters out of ``state_dict`` (extra keys are ignored)."""
        expected = self.spec.parameter_shapes()
        wrong = [k for k, shape in expected.items() if k not in state_dict or tuple(state_dict[k].shape) != shape]
        if wrong:
            raise ValueError(f"weights lack or mis-shape {', '.join(wrong)} needed by {self.spec.name}")
        self.layers.load_state_dict({k.removeprefix("features."): state_dict[k] for k in expected})

    def forward(self, images: torch.Tensor, scale: float | None = None) -> torch.Tensor:
        """Concatenated tap features of (B,3,H,W) images in [0, 1]."""
        return self.network(self.network_input(images, scale))

    def network_input(self, images: torch.Tensor, scale: float | None = None) -> torch.Tensor:
        """(B,3,H,W) images in [0, 1] as the network reads them: resized by ``scale`` (default ``self.scale``) and
        normalised."""
        if images.dim() != 4 or images.shape[1] != 3:
            raise ValueError(f"expected (B,3,H,W) images, got {tuple(images.shape)}")
        x = resize(images, scaled_size(*images.shape[-2:], self.scale if scale is None else scale))
        if self.spec.preprocessing == "imagenet":
            x = (x - self.mean) / self.std
        return x

    def network(self, x: torch.Tensor) -> torch.Tensor:
        """Concatenated tap features of a :meth:`network_input` (or any window of one)."""
        dtype = x.dtype
        if x.device.type == "cpu":  # oneDNN convolves NHWC faster: VGG fwd+bwd at 128 px 58 -> 49 ms, same features
            x = x.contiguous(memory_format=torch.channels_last)
        taps = []
        with self._precision(x.device):
            for index, module in enumerate(self.layers):
                x = module(x)
                if index in self._tap_indices:
                    taps.append(x)
        return torch.cat([resize(t.to(dtype), tuple(x.shape[-2:])) for t in taps], dim=1)

    def _precision(self, device: torch.device) -> contextlib.AbstractContextManager:
        """Autocast of the convolutions to ``self.autocast`` (resizing stays in the input's dtype)."""
        if self.autocast is None:
            return contextlib.nullcontext()
        return torch.autocast(device.type, dtype=self.autocast)


def load_feature_extractor(
    preference: str = "auto",
    weights_path: str | os.PathLike | None = None,
    device: torch.device | str = "cpu",
    *,
    scale: float = RENDER_SCALE,
    allow_download: bool = False,
    autocast: torch.dtype | None = None,
) -> FeatureExtractor:
    """Resolve weights (see :func:`.weights.resolve_weights`) and build the extractor on ``device``
    (``autocast``: run the convolutions in that dtype, see :func:`mixed_precision_dtype`).

    Check ``extractor.info["fallback"]``: with no weights found the network is a seeded random
    VGG-19 and the caller must report ``info["reason"]``.
    """
    from .weights import resolve_weights  # weights imports this module's specs

    weights = resolve_weights(preference, weights_path, allow_download=allow_download)
    return FeatureExtractor(weights.spec, weights, scale=scale, autocast=autocast).to(device)


def mixed_precision_dtype(device: torch.device | str, enabled: bool = True) -> torch.dtype | None:
    """The dtype the VGG convolutions run in on ``device``: float16 on a CUDA GPU, bfloat16 on a CPU with bfloat16
    instructions (:func:`cpu_has_bfloat16`), else None = float32.

    Measured with the same autocast on real features (tests/test_features.py): float16 features are within 0.07 % of
    float32, 99.8 % of cells keep their nearest texture feature and the texture loss's image gradient stays at cosine
    0.995 (a 1024x loss scale only reaches 0.997, so none is used); bfloat16 0.66 %, 99.0 % and 0.969, yet on this
    project's AVX512-BF16 CPU it ran VGG's forward and backward 1.5x as fast and the captures' ``fast`` runs 1.2-1.35x,
    finding the same textures at the same content (docs/speed.md). float16 convolutions there were 18x slower than
    float32; a CPU without bfloat16 instructions would emulate it, so it keeps float32."""
    device = torch.device(device)
    if not enabled:
        return None
    if device.type == "cuda":
        return torch.float16
    return torch.bfloat16 if device.type == "cpu" and cpu_has_bfloat16() else None


def precision_note(device: torch.device | str) -> tuple[str, str]:
    """(dtype name, why) of the feature network's convolutions on ``device`` with *Mixed Precision* on: what the
    machine check shows."""
    mixed = mixed_precision_dtype(device)
    why = _PRECISION_WHY.get(mixed, "this CPU has no bfloat16 instructions")
    return str(mixed or torch.float32).removeprefix("torch."), why


_PRECISION_WHY = {torch.float16: "a CUDA GPU", torch.bfloat16: "this CPU has bfloat16 instructions"}


def cpu_has_bfloat16() -> bool:
    """Whether this CPU multiplies bfloat16 in hardware (AVX512-BF16 or AMX), as torch's own kernels check."""
    checks = ("_is_avx512_bf16_supported", "_is_amx_tile_supported")
    return any(bool(getattr(torch.cpu, name, lambda: False)()) for name in checks)
