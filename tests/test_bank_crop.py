"""The texture bank's crop against the real VGG weights in ../shared/weights: the receptive field each
feature cell reads (``FeatureSpec.cell_reach``) is the real network's gradient support, and a crop of
``bank_crop`` px keeps the cells the same patch has inside a larger image; 16 px less does not."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch

from gt2gs_blender.core.features.extractor import FeatureExtractor
from gt2gs_blender.core.features.specs import VGG16_RELU3, VGG19_NORM_RELU3, FeatureSpec
from gt2gs_blender.core.features.weights import ResolvedWeights, load_state_dict
from gt2gs_blender.core.transfer.bank import BANK_CELLS, bank_crop
from gt2gs_blender.core.transfer.texture_bank import build_texture_bank, exact_crop

VGG16_PARTIAL = VGG16_RELU3.with_taps("relu1_2", "relu2_2")
"""VGG-16 as far as the shared weights hold it (to relu2_2), tapped at two strides so the resize counts."""
FILES = {VGG19_NORM_RELU3.name: "vgg19_normalised_to_relu3_1.pth", VGG16_RELU3.name: "vgg16_to_relu2_2.pth"}


def real_network(shared, spec: FeatureSpec) -> FeatureExtractor:
    """``spec`` with the real ImageNet weights of the shared file holding it (scale 1: crops are fed as they are)."""
    path = shared / "weights" / FILES[spec.name]
    return FeatureExtractor(spec, ResolvedWeights(spec, load_state_dict(path), path, "shared"), scale=1.0)


def texture(shared, name: str = "herringbone_wood.jpg") -> np.ndarray:
    """A real texture photo, RGB float in [0, 1], at 256 px high."""
    image = cv2.cvtColor(cv2.imread(str(shared / "data" / "textures" / name)), cv2.COLOR_BGR2RGB)
    height, width = image.shape[:2]
    image = cv2.resize(image, (round(width * 256 / height), 256), interpolation=cv2.INTER_AREA)
    return image.astype(np.float32) / 255.0


@pytest.mark.parametrize("spec", [VGG19_NORM_RELU3, VGG16_PARTIAL], ids=lambda s: "+".join(s.taps))
def test_cell_reach_is_the_real_networks_gradient_support(shared, spec):
    net = real_network(shared, spec)
    image = torch.from_numpy(texture(shared)[:96, :96]).permute(2, 0, 1)[None].contiguous().requires_grad_(True)
    feats = net(image)
    cell = 6  # far enough from every border that the support is not clipped
    feats[0, :, cell, cell].sum().backward()
    touched = image.grad[0].abs().sum(dim=0) > 0
    rows, cols = torch.nonzero(touched.any(dim=1)).flatten(), torch.nonzero(touched.any(dim=0)).flatten()
    before, after = spec.cell_reach()
    expected = (spec.stride * cell + before, spec.stride * cell + after)
    assert (int(rows.min()), int(rows.max())) == expected
    assert (int(cols.min()), int(cols.max())) == expected


def test_exact_crop_is_the_smallest_side_whose_kept_cells_read_no_padding():
    assert bank_crop(VGG19_NORM_RELU3) == 64  # 8 cells x 4 px + 10 px before, 13 after
    assert bank_crop(VGG16_RELU3) == 80  # relu3_3 reads 18 px before and 21 after: 64 px let the ring see padding
    assert exact_crop(4, (0, 3), 8) == 32 and exact_crop(4, (-1, 4), 8) == 48
    with pytest.raises(ValueError, match="reach"):
        exact_crop(4, (2, 3), 8)


def test_bank_crop_keeps_the_full_crops_cells_on_the_real_network(shared):
    net = real_network(shared, VGG19_NORM_RELU3)
    kwargs = {"extractor_id": "real", "n_scales": 1, "n_angles": 6, "texture_height": 256, "cells": BANK_CELLS}
    image = texture(shared)
    full = build_texture_bank(image, net, **kwargs)  # 176 px crops: the kept cells far from any border
    capped = build_texture_bank(image, net, max_crop=bank_crop(VGG19_NORM_RELU3), **kwargs)
    smaller = build_texture_bank(image, net, max_crop=bank_crop(VGG19_NORM_RELU3) - 16, **kwargs)
    torch.testing.assert_close(capped.features, full.features, atol=1e-4, rtol=0)
    # 16 px less: the outer ring reads VGG-19's reflected padding, 50x the tolerance off
    assert float((smaller.features - full.features).abs().max()) > 5e-3
