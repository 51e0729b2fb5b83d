"""GaussianScene: activations, structure operations and their bookkeeping of extra PLY properties."""

from __future__ import annotations

import numpy as np
import torch

from gt2gs_blender.core.scene.gaussians import SH_C0, GaussianScene, concat


def scene_with_extras(n: int = 5, degree: int = 2) -> GaussianScene:
    scene = GaussianScene.from_activated(
        torch.rand(n, 3), torch.full((n, 3), 0.1), torch.full((n,), 0.5), torch.rand(n, 3), sh_degree=degree
    )
    scene.extras = {"nx": np.arange(n, dtype=np.float32), "label": np.arange(n, dtype=np.int32) * 10}
    return scene


def test_subset_keeps_extras_aligned_for_every_index_kind():
    scene = scene_with_extras()
    for index in (torch.tensor([True, False, True, False, False]), np.array([4, 0]), slice(1, 3)):
        sub = scene.subset(index)
        rows = np.arange(5)[index.numpy() if isinstance(index, torch.Tensor) else index]
        assert torch.equal(sub.means, scene.means[torch.as_tensor(rows)])
        assert np.array_equal(sub.extras["label"], rows * 10) and sub.sh_degree == 2


def test_activations_and_from_activated_round_trip():
    colors = torch.tensor([[0.2, 0.5, 0.9]])
    scene = GaussianScene.from_activated(
        torch.zeros(1, 3), torch.tensor([[0.1, 0.2, 0.3]]), torch.tensor([0.7]), colors
    )
    assert torch.allclose(scene.scales, torch.tensor([[0.1, 0.2, 0.3]]))
    assert torch.allclose(scene.opacities, torch.tensor([0.7]))
    assert torch.allclose(scene.base_colors, colors) and torch.allclose(0.5 + SH_C0 * scene.sh_dc, colors)


def test_concat_raises_degree_and_keeps_common_extras():
    a, b = scene_with_extras(3, degree=0), scene_with_extras(2, degree=3)
    both = concat([a, b])
    assert len(both) == 5 and both.sh_degree == 3
    assert torch.count_nonzero(both.sh_rest[:3]) == 0
    assert np.array_equal(both.extras["label"], np.array([0, 10, 20, 0, 10]))
