"""Features of an object over a plain backdrop from the network run on its window only, against the whole image."""

from __future__ import annotations

import pytest
import torch

from gt2gs_blender.core.features.extractor import FeatureExtractor, load_feature_extractor
from gt2gs_blender.core.features.specs import VGG16_RELU3, VGG19_NORM_RELU3
from gt2gs_blender.core.features.window import plain_features, reached_cells, selected_features, windowed_features

from .test_features import random_weights
from .test_ssim import fern_rgb

BACKDROP = torch.tensor([1.0, 1.0, 1.0])


def over_backdrop(
    photo: torch.Tensor, height: int, width: int, box: tuple[int, int, int, int]
) -> tuple[torch.Tensor, ...]:
    """(1,3,H,W) an object (a patch of ``photo`` faded at its edge) inside ``box`` (top, bottom, left, right) over
    the backdrop, and its coverage (H,W): 0 exactly outside the box, as a render's alpha is where no splat lies."""
    top, bottom, left, right = box
    alpha = torch.zeros(height, width)
    alpha[top:bottom, left:right] = torch.linspace(0.2, 1.0, right - left)[None, :]
    colour = photo[: bottom - top, : right - left].permute(2, 0, 1)
    image = BACKDROP.reshape(3, 1, 1).expand(3, height, width).clone()
    inside = image[:, top:bottom, left:right]
    image[:, top:bottom, left:right] = (
        alpha[top:bottom, left:right] * colour + (1 - alpha[top:bottom, left:right]) * inside
    )
    return image[None], alpha


def test_reached_cells_are_those_whose_span_meets_the_changed_pixels():
    """A cell j reads pixels 4j-3..4j+6: pixels 40..43 are read by cells 9..11 (4*9+6 >= 40, 4*11-3 <= 43), whose
    spans 33..50 lie in the crop 32..51 (whole strides); at the image's edges the crop stops at the edge."""
    assert reached_cells(40, 43, 64, 4, (-3, 6)) == (9, 11, 32, 52)
    assert reached_cells(0, 2, 64, 4, (-3, 6)) == (0, 1, 0, 12)
    assert reached_cells(60, 63, 64, 4, (-3, 6)) == (14, 15, 52, 64)


@pytest.mark.parametrize(
    ("spec", "box"),
    [
        (VGG19_NORM_RELU3, (60, 140, 90, 130)),  # reflect padding, two taps: a thin object in the middle
        (VGG16_RELU3, (0, 70, 150, 192)),  # zero padding, three taps: an object against the image's edges
    ],
)
def test_window_features_and_their_gradient_match_the_whole_image(spec, box):
    torch.manual_seed(0)
    net = FeatureExtractor(spec, random_weights(spec))
    photo = torch.rand(160, 192, 3)
    image, alpha = over_backdrop(photo, 160, 192, box)
    image.requires_grad_(True)
    plain = plain_features(net, 160, 192, BACKDROP)
    whole = net(image)
    window, area = windowed_features(net, image, alpha, lambda: plain)
    assert 0 < area < 1
    assert window.shape == whole.shape
    scale = float(whole.detach().abs().max())
    torch.testing.assert_close(window.detach(), whole.detach(), rtol=1e-4, atol=1e-5 * scale)
    weight = torch.randn_like(whole)
    (grad_whole,) = torch.autograd.grad((whole * weight).sum(), image)
    (grad_window,) = torch.autograd.grad((window * weight).sum(), image)
    covered = (alpha > 0).expand_as(image)  # where a render depends on its splats; the backdrop does not
    torch.testing.assert_close(
        grad_window[covered], grad_whole[covered], rtol=1e-4, atol=1e-5 * float(grad_whole.abs().max())
    )


def test_the_real_network_on_a_window_of_a_real_photo(shared):
    net = load_feature_extractor("vgg19_norm_relu3")
    photo = torch.from_numpy(fern_rgb(shared, 0)).float()
    image, alpha = over_backdrop(photo, 256, 256, (30, 230, 100, 150))
    plain = plain_features(net, 256, 256, BACKDROP)
    whole, (window, _) = net(image), windowed_features(net, image, alpha, lambda: plain)
    torch.testing.assert_close(window, whole, rtol=1e-4, atol=1e-5 * float(whole.detach().abs().max()))


def never() -> torch.Tensor:
    raise AssertionError("the plain backdrop's features were asked for with no cell left out")


def test_an_empty_view_is_the_plain_backdrop_and_a_full_or_odd_one_is_the_whole_image():
    net = FeatureExtractor(VGG19_NORM_RELU3, random_weights(VGG19_NORM_RELU3))
    plain = plain_features(net, 64, 64, BACKDROP)
    empty = BACKDROP.reshape(1, 3, 1, 1).expand(1, 3, 64, 64).contiguous()
    features, area = windowed_features(net, empty, torch.zeros(64, 64), lambda: plain)
    assert features is plain and area == 0.0
    full = torch.rand(1, 3, 64, 64)
    features, area = windowed_features(net, full, torch.ones(64, 64), never)
    assert area == 1.0 and torch.equal(features, net(full))
    odd, alpha = over_backdrop(torch.rand(90, 90, 3), 90, 90, (20, 40, 20, 40))  # 45 px at half scale: no whole strides
    features, area = windowed_features(net, odd, alpha, never)
    assert area == 1.0 and torch.equal(features, net(odd))


@pytest.mark.parametrize(
    ("spec", "box"),
    [
        (VGG19_NORM_RELU3, (60, 140, 90, 130)),  # reflect padding: a thin object in the middle
        (VGG16_RELU3, (0, 70, 150, 192)),  # zero padding: against the image's edges
        (VGG16_RELU3, (0, 160, 0, 192)),  # the whole image
    ],
)
def test_selected_cells_read_what_they_read_in_the_whole_image(spec, box):
    """The texture-match measure's covered cells, from the network run on their crop only: the same vectors in the
    same order as picked from the whole image's features (the cells picked scatter inside the box, as an object's
    covered cells do), and none picked gives none."""
    from gt2gs_blender.core.transfer.metrics import covered_features

    torch.manual_seed(1)
    net = FeatureExtractor(spec, random_weights(spec))
    image, alpha = over_backdrop(torch.rand(160, 192, 3), 160, 192, box)
    alpha = alpha * (torch.rand(160, 192) > 0.3)  # holes: the picked cells are not one rectangle
    whole = net(image)[0]

    def pick(hw: tuple[int, int]) -> torch.Tensor:
        return torch.nn.functional.interpolate(alpha[None, None], size=hw, mode="area")[0, 0] > 0.5

    expected = whole.flatten(1).T[pick(tuple(whole.shape[-2:])).flatten()]
    assert len(expected) > 4
    torch.testing.assert_close(selected_features(net, image, pick), expected, atol=1e-4, rtol=1e-4)
    assert selected_features(net, image, lambda hw: torch.zeros(hw, dtype=torch.bool)).shape == (0, whole.shape[0])
    covered = covered_features(net, image[0].permute(1, 2, 0), alpha)
    assert covered.shape[1] == whole.shape[0] and len(covered) > 0
