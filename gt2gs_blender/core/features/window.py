"""Features of an image that is a plain backdrop except inside a window (an object over its backdrop): the network
runs only on the crop whose cells the window's pixels can reach; every other cell is the plain backdrop's.

Exact up to the convolutions' rounding: a cell reads only the pixels of its span (``FeatureSpec.cell_reach``), so a
cell no changed pixel reaches reads the same backdrop as in the plain image, and a reached cell's span stays inside
the crop (or meets the image's own border there), so it reads what it reads in the whole image. The crop starts on
the network's stride and spans whole strides, so its cells lie on the image's grid."""

from __future__ import annotations

import math
from collections.abc import Callable

import torch

from .extractor import FeatureExtractor, resize


def reached_cells(lo: int, hi: int, size: int, stride: int, reach: tuple[int, int]) -> tuple[int, int, int, int]:
    """Along one axis of a network input ``size`` pixels long (a multiple of ``stride``) whose pixels ``lo``..``hi``
    differ from the backdrop: the first and last cell those pixels reach, and the crop (start, stop pixels, multiples
    of ``stride``) inside which those cells read just what they read in the whole input."""
    before, after = reach
    first = max(0, math.ceil((lo - after) / stride))
    last = min(size // stride - 1, math.floor((hi - before) / stride))
    return (first, last, *cells_crop(first, last, size, stride, reach))


def cells_crop(first: int, last: int, size: int, stride: int, reach: tuple[int, int]) -> tuple[int, int]:
    """Along one axis of a network input ``size`` pixels long: the crop (start, stop pixels, multiples of
    ``stride``) that holds the spans of cells ``first``..``last``, so they read there what they read in the whole
    input."""
    before, after = reach
    start = max(0, (stride * first + before) // stride * stride)
    stop = min(size, math.ceil((stride * last + after + 1) / stride) * stride)
    return start, stop


def plain_features(extractor: FeatureExtractor, height: int, width: int, backdrop: torch.Tensor) -> torch.Tensor:
    """(1,C,h,w) features of a ``height`` x ``width`` image of the plain ``backdrop`` colour (3,)."""
    image = backdrop.reshape(1, 3, 1, 1).expand(1, 3, height, width)
    with torch.no_grad():
        return extractor(image.contiguous())


def windowed_features(
    extractor: FeatureExtractor, images: torch.Tensor, coverage: torch.Tensor, plain: Callable[[], torch.Tensor]
) -> tuple[torch.Tensor, float]:
    """``extractor(images)`` for (1,3,H,W) images that are the backdrop wherever ``coverage`` (H,W) is 0, from
    ``plain()`` (:func:`plain_features` of that backdrop at this size, asked for only when some cell is left out) and
    the network run on the covered window only; and the share of the network input it ran on. The whole image where
    the window is all of it, or where its network input is not whole strides (the crop's grid would shift)."""
    x = extractor.network_input(images)
    height, width = x.shape[-2:]
    stride = extractor.spec.stride
    if height % stride or width % stride:
        return extractor.network(x), 1.0
    box = _extent(resize(coverage.to(x.dtype)[None, None], (height, width))[0, 0] > 0)
    if box is None:
        return plain(), 0.0
    reach = extractor.spec.cell_reach()
    top, bottom, y0, y1 = reached_cells(box[0], box[1], height, stride, reach)
    left, right, x0, x1 = reached_cells(box[2], box[3], width, stride, reach)
    if (y0, y1, x0, x1) == (0, height, 0, width):  # the splats reach every cell: nothing to leave out
        return extractor.network(x), 1.0
    out = plain().clone()
    out[..., top : bottom + 1, left : right + 1] = _cells_on_crop(
        extractor, x, (top, bottom, left, right), (y0, x0, y1, x1)
    )
    return out, (y1 - y0) * (x1 - x0) / (height * width)


def _extent(mask: torch.Tensor) -> tuple[int, int, int, int] | None:
    """(first row, last row, first column, last column) where the (h, w) ``mask`` holds, None where it nowhere does."""
    rows, cols = mask.any(dim=1).nonzero().squeeze(1), mask.any(dim=0).nonzero().squeeze(1)
    if len(rows) == 0:
        return None
    return int(rows[0]), int(rows[-1]), int(cols[0]), int(cols[-1])


def _cells_on_crop(
    extractor: FeatureExtractor, x: torch.Tensor, cells: tuple[int, int, int, int], crop: tuple[int, int, int, int]
) -> torch.Tensor:
    """(B,C,rows,cols) features of the ``cells`` (top, bottom, left, right, inclusive) of the network input ``x``,
    the network run on its ``crop`` (y0, x0, y1, x1 pixels, on the stride's grid, holding those cells' spans)."""
    top, bottom, left, right = cells
    y0, x0, y1, x1 = crop
    stride = extractor.spec.stride
    inner = extractor.network(x[..., y0:y1, x0:x1])
    return inner[..., top - y0 // stride : bottom - y0 // stride + 1, left - x0 // stride : right - x0 // stride + 1]


def selected_features(
    extractor: FeatureExtractor, image: torch.Tensor, select: Callable[[tuple[int, int]], torch.Tensor]
) -> torch.Tensor:
    """(n, C) the features of the cells ``select(feature_hw)`` ((h, w) bool) picks of ``extractor(image)`` for one
    (1,3,H,W) image, in row-major order: the network runs only on the crop holding those cells' spans (exact, as
    :func:`windowed_features`), so a measure over an object's cells skips its backdrop."""
    x = extractor.network_input(image)
    height, width = x.shape[-2:]
    stride = extractor.spec.stride
    if height % stride or width % stride:
        features = extractor.network(x)[0]
        return features.flatten(1).T[select(tuple(features.shape[-2:])).flatten()]
    cells = select((height // stride, width // stride))
    box = _extent(cells)
    if box is None:  # nothing covered (an object out of view): the whole image gives the empty selection
        return extractor.network(x)[0].flatten(1).T[:0]
    top, bottom, left, right = box
    reach = extractor.spec.cell_reach()
    y0, y1 = cells_crop(top, bottom, height, stride, reach)
    x0, x1 = cells_crop(left, right, width, stride, reach)
    block = _cells_on_crop(extractor, x, box, (y0, x0, y1, x1))[0]
    return block.flatten(1).T[cells[top : bottom + 1, left : right + 1].flatten()]
