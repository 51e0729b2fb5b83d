"""Feature network specifications: layers, preprocessing and padding of each supported VGG, by name."""

from __future__ import annotations

from dataclasses import dataclass, replace

IMAGENET_MEAN = (0.485, 0.456, 0.406)


IMAGENET_STD = (0.229, 0.224, 0.225)


PREPROCESSING = ("imagenet", "none")


PADDING = ("zeros", "reflect")


RENDER_SCALE = 0.5
"""The paper's downscale of renders and content images before VGG."""


FALLBACK_SEED = 0


_POOL = "M"


@dataclass(frozen=True)
class FeatureSpec:
    """What network computes the features and how its input is prepared.

    ``layers`` is torchvision's VGG configuration: an int is a 3x3 conv with that many output
    channels followed by a ReLU, ``"M"`` a 2x2 max-pool (floor mode, as torchvision). ``taps`` are
    the ReLU outputs concatenated, in network order, into the feature map (``relu<block>_<conv>``),
    all resized to the deepest tap's resolution. ``weight_files`` are the file names :mod:`.weights` looks for.
    """

    name: str
    layers: tuple[int | str, ...]
    taps: tuple[str, ...]
    preprocessing: str
    padding: str
    weight_files: tuple[str, ...]
    description: str

    def __post_init__(self) -> None:
        if self.preprocessing not in PREPROCESSING:
            raise ValueError(f"preprocessing must be one of {PREPROCESSING}, got {self.preprocessing!r}")
        if self.padding not in PADDING:
            raise ValueError(f"padding must be one of {PADDING}, got {self.padding!r}")
        unknown = [t for t in self.taps if t not in self.relu_indices]
        if not self.taps or unknown:
            raise ValueError(f"{self.name}: taps {unknown or '()'} not among {sorted(self.relu_indices)}")

    @property
    def stack(self) -> tuple[tuple[str, str, int, int], ...]:
        """One (kind, name, in_channels, out_channels) per torchvision ``features`` index, all layers;
        kind is ``conv``, ``relu`` or ``pool``; names as ``conv2_1``, ``relu2_1``, ``pool1``."""
        out: list[tuple[str, str, int, int]] = []
        block, conv, channels = 1, 0, 3
        for item in self.layers:
            if item == _POOL:
                out.append(("pool", f"pool{block}", channels, channels))
                block, conv = block + 1, 0
            else:
                conv += 1
                out += [
                    ("conv", f"conv{block}_{conv}", channels, int(item)),
                    ("relu", f"relu{block}_{conv}", int(item), int(item)),
                ]
                channels = int(item)
        return tuple(out)

    @property
    def relu_indices(self) -> dict[str, int]:
        """``relu<block>_<conv>`` -> index of that ReLU in the ``features`` stack."""
        return {name: i for i, (kind, name, _, _) in enumerate(self.stack) if kind == "relu"}

    @property
    def depth(self) -> int:
        """Number of ``features`` modules up to and including the deepest tap."""
        return max(self.relu_indices[t] for t in self.taps) + 1

    @property
    def tap_channels(self) -> dict[str, int]:
        """Channels of each tap, in network (= concatenation) order."""
        return {t: self.stack[self.relu_indices[t]][3] for t in sorted(self.taps, key=self.relu_indices.get)}

    @property
    def out_channels(self) -> int:
        """Channels of the concatenated feature map."""
        return sum(self.tap_channels.values())

    @property
    def stride(self) -> int:
        """Network-input pixels per feature cell along each axis (2 ** pools before the deepest tap)."""
        return 2 ** sum(kind == "pool" for kind, *_ in self.stack[: self.depth])

    def cell_reach(self) -> tuple[int, int]:
        """The input pixels cell j of the concatenated feature map reads: ``stride * j + before`` to
        ``stride * j + after`` (both included; before < 0). Each 3x3 convolution (padding 1) widens a
        tap's span by its stride on each side, each 2x2 pool doubles the stride and adds one stride after;
        a shallower tap is resized to the deepest tap's grid by antialiased bilinear downscaling, whose
        output cell j reads that tap's cells ``f*j - f/2`` to ``f*j + 3f/2 - 1`` (f the stride ratio, as torch's
        ``interpolate(antialias=True)``). Pixels outside the image are padding: a cell whose span stays
        inside the image is the same as that patch's cell inside any larger image."""
        spans: dict[str, tuple[int, int, int]] = {}
        stride, before, after = 1, 0, 0
        for kind, name, *_ in self.stack[: self.depth]:
            if kind == "conv":
                before, after = before - stride, after + stride
            elif kind == "pool":
                stride, after = stride * 2, after + stride
            elif name in self.taps:
                spans[name] = (stride, before, after)
        lows, highs = [], []
        for tap_stride, tap_before, tap_after in spans.values():
            ratio = stride // tap_stride
            first, last = (0, 0) if ratio == 1 else (-(ratio // 2), 3 * ratio // 2 - 1)
            lows.append(tap_stride * first + tap_before)
            highs.append(tap_stride * last + tap_after)
        return min(lows), max(highs)

    def parameter_shapes(self) -> dict[str, tuple[int, ...]]:
        """State-dict keys (``features.N.weight/bias``) the network up to the deepest tap needs."""
        out: dict[str, tuple[int, ...]] = {}
        for index, (kind, _, c_in, c_out) in enumerate(self.stack[: self.depth]):
            if kind == "conv":
                out[f"features.{index}.weight"] = (c_out, c_in, 3, 3)
                out[f"features.{index}.bias"] = (c_out,)
        return out

    def with_taps(self, *taps: str) -> FeatureSpec:
        """The same network tapped elsewhere (e.g. ``VGG19_NORM_RELU3.with_taps("relu3_1")``)."""
        return replace(self, taps=tuple(taps))


VGG16_RELU3 = FeatureSpec(
    name="vgg16_relu3",
    layers=(64, 64, _POOL, 128, 128, _POOL, 256, 256, 256),
    taps=("relu3_1", "relu3_2", "relu3_3"),
    preprocessing="imagenet",
    padding="zeros",
    weight_files=("vgg16-397923af.pth",),
    description="torchvision ImageNet VGG-16, relu3_1+relu3_2+relu3_3 (the paper's features)",
)


VGG19_NORM_RELU3 = FeatureSpec(
    name="vgg19_norm_relu3",
    layers=(64, 64, _POOL, 128, 128, _POOL, 256),
    taps=("relu2_1", "relu3_1"),
    preprocessing="none",
    padding="reflect",
    weight_files=("vgg19_normalised_to_relu3_1.pth",),
    description="normalised ImageNet VGG-19, relu2_1+relu3_1 (substitute for the paper's VGG-16 relu3_x)",
)


SPECS = {spec.name: spec for spec in (VGG16_RELU3, VGG19_NORM_RELU3)}
