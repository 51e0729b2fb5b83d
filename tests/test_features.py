"""Feature extractor specs, shapes and taps; weight resolution order, fallback report and file errors."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
import torch.nn.functional as F

from gt2gs_blender.core.errors import GT2GSError, InputFileError
from gt2gs_blender.core.features import weights as weights_mod
from gt2gs_blender.core.features.extractor import (
    FeatureExtractor,
    build_layers,
    cpu_has_bfloat16,
    load_feature_extractor,
    mixed_precision_dtype,
    precision_note,
    random_init_,
)
from gt2gs_blender.core.features.specs import VGG16_RELU3, VGG19_NORM_RELU3
from gt2gs_blender.core.features.weights import ENV_VAR, ResolvedWeights, resolve_weights

from .test_ssim import fern_rgb

VGG16_FILE = VGG16_RELU3.weight_files[0]
VGG19_FILE = VGG19_NORM_RELU3.weight_files[0]
BF16_ERROR, BF16_SAME, BF16_GRADIENT = 0.01, 0.97, 0.95
"""bfloat16 keeps 8 bits of mantissa to float16's 11: on the fern photo it measured 0.0066, 0.990 and 0.969."""


def random_weights(spec, seed: int = 1) -> ResolvedWeights:
    """A torchvision-layout state dict of ``spec`` with random values, plus an unused extra key."""
    layers = build_layers(spec)
    random_init_(layers, seed)
    state = {f"features.{k}": v for k, v in layers.state_dict().items()}
    state["classifier.0.weight"] = torch.zeros(2, 2)
    return ResolvedWeights(spec, state, None, "test")


@pytest.fixture
def isolated(monkeypatch, tmp_path) -> Path:
    """No weights anywhere: empty torch hub cache, no $GT2GS_WEIGHTS_DIR. Returns the hub checkpoint dir."""
    monkeypatch.setenv("TORCH_HOME", str(tmp_path / "torch_home"))
    monkeypatch.delenv(ENV_VAR, raising=False)
    return tmp_path / "torch_home" / "hub" / "checkpoints"


@pytest.fixture(scope="module")
def vgg16_file(tmp_path_factory) -> Path:
    """A synthetic full torchvision VGG-16 file (random values, real key names and shapes)."""
    path = tmp_path_factory.mktemp("vgg16") / VGG16_FILE
    torch.save(random_weights(VGG16_RELU3).state_dict, path)
    return path


def place(path: Path, folder: Path) -> Path:
    """Symlink ``path`` into ``folder`` under its own name."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / path.name).symlink_to(path)
    return folder / path.name


def fern(shared, index: int) -> torch.Tensor:
    """A fern photograph as a (1,3,H,W) batch."""
    return torch.from_numpy(fern_rgb(shared, index)).permute(2, 0, 1)[None]


def distance(a: torch.Tensor, b: torch.Tensor) -> float:
    """Mean cosine distance of feature maps away from a 2-cell border."""
    return float((1 - F.cosine_similarity(a, b, dim=1))[..., 2:-2, 2:-2].mean())


# -- specs and the extractor ---------------------------------------------------------------------------
def test_specs_match_torchvision_layout():
    assert VGG16_RELU3.relu_indices == {
        "relu1_1": 1,
        "relu1_2": 3,
        "relu2_1": 6,
        "relu2_2": 8,
        "relu3_1": 11,
        "relu3_2": 13,
        "relu3_3": 15,
    }
    assert VGG16_RELU3.out_channels == 768 and VGG19_NORM_RELU3.out_channels == 128 + 256
    assert sorted(VGG19_NORM_RELU3.parameter_shapes()) == sorted(
        f"features.{i}.{p}" for i in (0, 2, 5, 7, 10) for p in ("weight", "bias")
    )
    assert VGG19_NORM_RELU3.with_taps("relu1_2").depth == 4 and VGG19_NORM_RELU3.with_taps("relu1_2").stride == 1
    with pytest.raises(ValueError, match="relu3_2"):
        VGG19_NORM_RELU3.with_taps("relu3_2")


@pytest.mark.parametrize("spec", [VGG16_RELU3, VGG19_NORM_RELU3], ids=lambda s: s.name)
def test_shapes_and_half_scale(spec):
    net = FeatureExtractor(spec, random_weights(spec))
    images = torch.rand(2, 3, 50, 38)
    assert net(images).shape == (2, spec.out_channels, 25 // 4, 19 // 4)  # x0.5 then two floor pools
    assert net(images, scale=1.0).shape == (2, spec.out_channels, 50 // 4, 38 // 4)
    half = F.interpolate(images, size=(25, 19), mode="bilinear", antialias=True, align_corners=False)
    torch.testing.assert_close(net(images), net(half, scale=1.0))


def test_taps_are_concatenated_in_order_after_imagenet_normalisation():
    weights = random_weights(VGG16_RELU3)
    net = FeatureExtractor(VGG16_RELU3, weights, scale=1.0)
    assert torch.equal(net.layers[14].weight, weights.state_dict["features.14.weight"])
    images = torch.rand(1, 3, 32, 24)
    x = (images - torch.tensor([0.485, 0.456, 0.406]).reshape(1, 3, 1, 1)) / torch.tensor(
        [0.229, 0.224, 0.225]
    ).reshape(1, 3, 1, 1)
    out = net(images)
    for k, index in enumerate((11, 13, 15)):
        torch.testing.assert_close(out[:, 256 * k : 256 * (k + 1)], net.layers[: index + 1](x))


def test_reflection_padding_keeps_a_flat_image_flat():
    flat = torch.full((1, 3, 24, 24), 0.4)
    reflect = FeatureExtractor(VGG19_NORM_RELU3, random_weights(VGG19_NORM_RELU3), scale=1.0)(flat)
    zeros = FeatureExtractor(VGG16_RELU3, random_weights(VGG16_RELU3), scale=1.0)(flat)
    assert torch.allclose(reflect, reflect[..., :1, :1].expand_as(reflect), atol=1e-5)
    assert not torch.allclose(zeros, zeros[..., 2:3, 2:3].expand_as(zeros), atol=1e-3)


def test_fingerprint_tracks_weights_taps_and_scale():
    spec = VGG19_NORM_RELU3
    base = FeatureExtractor(spec, random_weights(spec)).fingerprint
    assert FeatureExtractor(spec, random_weights(spec)).fingerprint == base
    others = [
        FeatureExtractor(spec, random_weights(spec, seed=2)),
        FeatureExtractor(spec, random_weights(spec), scale=1.0),
        FeatureExtractor(spec.with_taps("relu3_1"), random_weights(spec)),
    ]
    assert len({base, *(net.fingerprint for net in others)}) == 4


def test_frozen_but_differentiable_in_the_image():
    net = FeatureExtractor(VGG19_NORM_RELU3, random_weights(VGG19_NORM_RELU3))
    images = torch.rand(1, 3, 32, 32, requires_grad=True)
    net(images).square().mean().backward()
    assert images.grad is not None and images.grad.abs().sum() > 0
    assert not any(p.requires_grad for p in net.parameters())


def test_real_vgg19_features_are_deterministic_and_discriminative(shared, monkeypatch):
    monkeypatch.setenv(ENV_VAR, str(shared / "weights"))
    net = load_feature_extractor("vgg19_norm_relu3")
    assert net.info["fallback"] is False and net.info["weights_file"].endswith(VGG19_FILE)
    image, other = fern(shared, 0), fern(shared, 10)
    shifted = torch.roll(image, 8, dims=3)  # 8 px = one feature cell at x0.5 scale
    with torch.no_grad():
        f_image, f_again, f_shifted, f_other = net(image), net(image), net(shifted), net(other)
    assert torch.equal(f_image, f_again)
    assert f_image.shape == (1, 384, 378 // 2 // 4, 504 // 2 // 4) and f_image.std() > 0.1
    assert distance(f_image[..., :-1], f_shifted[..., 1:]) < 1e-3  # shift-equivariant away from the borders
    assert distance(f_image, f_shifted) < distance(f_image, f_other)  # a shifted image is still closer


# -- weight resolution ---------------------------------------------------------------------------------
def test_auto_uses_env_dir_and_names_the_partial_vgg16(shared, isolated, monkeypatch):
    monkeypatch.setenv(ENV_VAR, str(shared / "weights"))
    resolved = resolve_weights()
    assert resolved.spec is VGG19_NORM_RELU3 and not resolved.fallback
    assert resolved.weights_file == shared / "weights" / VGG19_FILE
    assert "vgg16_to_relu2_2.pth holds VGG-16 only up to relu2_2" in resolved.reason
    assert f"no {VGG16_FILE} found" in resolved.reason


def test_fallback_is_reported_with_a_reason(isolated):
    net = load_feature_extractor()
    assert net.info["fallback"] is True and net.info["weights_file"] is None
    assert net.info["spec"] == "vgg19_norm_relu3" and "FALLBACK" in net.info["reason"]
    assert str(isolated) in net.info["reason"]
    again = load_feature_extractor()  # seeded: the same random network every time
    assert all(torch.equal(a, b) for a, b in zip(net.parameters(), again.parameters()))


def test_paper_vgg16_in_hub_cache_beats_vgg19_anywhere(shared, isolated, monkeypatch, vgg16_file):
    place(vgg16_file, isolated)
    monkeypatch.setenv(ENV_VAR, str(shared / "weights"))
    resolved = resolve_weights()
    assert resolved.spec is VGG16_RELU3 and resolved.weights_file == isolated / VGG16_FILE
    assert "torch hub cache" in resolved.reason and "classifier.0.weight" not in resolved.state_dict
    assert resolve_weights("vgg19_norm_relu3").spec is VGG19_NORM_RELU3


def test_explicit_path_comes_first(shared, isolated, monkeypatch, vgg16_file, tmp_path):
    place(vgg16_file, isolated)
    explicit = shared / "weights" / VGG19_FILE
    assert resolve_weights(weights_path=explicit).weights_file == explicit
    env_dir, explicit_dir = tmp_path / "env", tmp_path / "explicit"
    place(vgg16_file, env_dir)
    place(vgg16_file, explicit_dir)
    monkeypatch.setenv(ENV_VAR, str(env_dir))
    assert resolve_weights(weights_path=explicit_dir).weights_file == explicit_dir / VGG16_FILE
    assert resolve_weights().weights_file == env_dir / VGG16_FILE


def test_named_spec_not_found_is_an_error(isolated):
    with pytest.raises(GT2GSError, match="vgg16_relu3 weights not found"):
        resolve_weights("vgg16_relu3")
    with pytest.raises(GT2GSError, match="unknown feature network"):
        resolve_weights("resnet")


def test_unusable_user_files_are_input_file_errors(shared, isolated, monkeypatch, tmp_path):
    corrupt = tmp_path / "corrupt.pth"
    corrupt.write_bytes(b"PK\x03\x04 not really a zip")
    with pytest.raises(InputFileError, match="cannot read it as PyTorch weights"):
        resolve_weights(weights_path=corrupt)
    with pytest.raises(InputFileError, match="not found"):
        resolve_weights(weights_path=tmp_path / "missing.pth")
    with pytest.raises(InputFileError, match="vgg16_relu3 needs conv layers"):
        resolve_weights("vgg16_relu3", shared / "weights" / "vgg16_to_relu2_2.pth")
    (tmp_path / "env").mkdir()
    (tmp_path / "env" / VGG19_FILE).write_bytes(b"\x00" * 64)
    monkeypatch.setenv(ENV_VAR, str(tmp_path / "env"))
    with pytest.raises(InputFileError, match=VGG19_FILE):
        resolve_weights()
    monkeypatch.setenv(ENV_VAR, str(tmp_path / "nowhere"))
    with pytest.raises(InputFileError, match=ENV_VAR):
        resolve_weights()


def test_download_only_on_request(isolated, monkeypatch, vgg16_file):
    calls = []

    def fake_download(url, dst, hash_prefix=None):
        calls.append((url, hash_prefix))
        Path(dst).write_bytes(vgg16_file.read_bytes())

    monkeypatch.setattr(torch.hub, "download_url_to_file", fake_download)
    assert resolve_weights().fallback and not calls
    with pytest.raises(GT2GSError, match="explicit permission"):
        weights_mod.download_vgg16(False)
    resolved = resolve_weights(allow_download=True)
    assert calls == [(weights_mod.VGG16_URL, "397923af")]
    assert resolved.spec is VGG16_RELU3 and resolved.weights_file == isolated / VGG16_FILE


def test_a_corrupt_download_is_refused_and_leaves_no_file(isolated, monkeypatch, tmp_path):
    """The real downloader (torch.hub, here over a file:// URL): content that does not match the published
    hash is refused with the URL in the message, and nothing is left in the weights cache."""
    served = tmp_path / "served.pth"
    served.write_bytes(b"not the VGG-16 weights" * 4096)
    monkeypatch.setattr(weights_mod, "VGG16_URL", served.as_uri())
    with pytest.raises(GT2GSError, match="could not download file://"):
        weights_mod.download_vgg16(True)
    assert not [p for p in weights_mod.hub_checkpoint_dir().rglob("*") if p.is_file()]


# -- mixed precision -----------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("dtype", "error", "same_nearest", "gradient"),
    [(torch.float16, 0.005, 0.98, 0.99), (torch.bfloat16, BF16_ERROR, BF16_SAME, BF16_GRADIENT)],
)
def test_mixed_convolutions_stay_close_to_float32(shared, monkeypatch, dtype, error, same_nearest, gradient):
    """The accuracy behind mixed precision (float16 on CUDA, bfloat16 on a CPU that has it), measured with the same
    autocast on the CPU: real VGG features of a real photo within ``error`` of float32, the same nearest texture
    feature for ``same_nearest`` of the cells, and the texture loss's image gradient pointing the same way."""
    monkeypatch.setenv(ENV_VAR, str(shared / "weights"))
    exact = load_feature_extractor("vgg19_norm_relu3")
    mixed = load_feature_extractor("vgg19_norm_relu3", autocast=dtype)
    assert mixed.info["autocast"] == str(dtype).removeprefix("torch.") and exact.info["autocast"] is None
    assert mixed.fingerprint != exact.fingerprint  # cached banks of the two never mix
    image = fern(shared, 0).requires_grad_(True)
    f32, low = exact(image), mixed(image)
    assert low.dtype == torch.float32 and low.shape == f32.shape
    assert float((low - f32).detach().norm() / f32.detach().norm()) < error
    rows32, rows_low = (F.normalize(f.detach().flatten(2)[0].T, dim=1) for f in (f32, low))
    bank = F.normalize(exact(fern(shared, 10)).flatten(2)[0].T, dim=1)
    same = ((rows32 @ bank.T).argmax(1) == (rows_low @ bank.T).argmax(1)).float().mean()
    assert same >= same_nearest
    grads = [
        torch.autograd.grad((1 - (F.normalize(f.flatten(2)[0].T, dim=1) * bank[:1]).sum(1)).mean(), image)[0]
        for f in (f32, low)
    ]
    assert F.cosine_similarity(grads[0].flatten(), grads[1].flatten(), dim=0) > gradient


def test_mixed_precision_is_float16_on_cuda_and_bfloat16_on_a_cpu_with_it():
    assert mixed_precision_dtype("cuda") is torch.float16 and mixed_precision_dtype("cuda", enabled=False) is None
    assert mixed_precision_dtype("cpu") is (torch.bfloat16 if cpu_has_bfloat16() else None)
    assert mixed_precision_dtype("cpu", enabled=False) is None
    name, why = precision_note("cpu")
    assert name == ("bfloat16" if cpu_has_bfloat16() else "float32") and "bfloat16 instructions" in why


def test_cpu_bfloat16_follows_the_instructions_torch_reports(monkeypatch):
    """bfloat16 on the CPU only where its instructions are (elsewhere it would be emulated)."""
    for avx512_bf16, amx, expected in [(False, False, False), (True, False, True), (False, True, True)]:
        monkeypatch.setattr(torch.cpu, "_is_avx512_bf16_supported", lambda v=avx512_bf16: v)
        monkeypatch.setattr(torch.cpu, "_is_amx_tile_supported", lambda v=amx: v)
        assert cpu_has_bfloat16() is expected
        assert mixed_precision_dtype("cpu") is (torch.bfloat16 if expected else None)
        assert precision_note("cpu")[0] == ("bfloat16" if expected else "float32")
    assert precision_note("cuda") == ("float16", "a CUDA GPU")
