"""The compiled CPU rasterizer kernel: present wherever the tests run, and built once per content.

Without the kernel every rasterizer test still passes on the portable torch backend, so losing it
(a compiler or header problem at import) would go unnoticed: test_cpu_kernel_is_built_and_loaded
fails instead. On a machine knowingly without a C++ toolchain, set GT2GS_ALLOW_NO_CPU_KERNEL=1 to
skip it; CI does not set it.
"""

from __future__ import annotations

import os
import shutil
import stat
from pathlib import Path
from types import ModuleType

import pytest

from gt2gs_blender.core.render import available_backends, cpu_backend, kernel_cache, resolve_backend

ALLOW_NO_KERNEL = "GT2GS_ALLOW_NO_CPU_KERNEL"


def test_cpu_kernel_is_built_and_loaded():
    """The fast ``cpu`` backend is the one ``auto`` picks on the CPU (unless explicitly allowed away)."""
    if "cpu" not in available_backends("cpu") and os.environ.get(ALLOW_NO_KERNEL) == "1":
        pytest.skip(f"{ALLOW_NO_KERNEL}=1 and the kernel is unavailable: {cpu_backend.unavailable_reason()}")
    assert available_backends("cpu")[0] == "cpu", (
        f"the compiled cpu rasterizer did not build or load: {cpu_backend.unavailable_reason()} "
        f"(set {ALLOW_NO_KERNEL}=1 to run without it on purpose)"
    )
    assert resolve_backend("auto", "cpu") == "cpu"


@pytest.fixture
def kernel() -> ModuleType:
    """The kernel as the backend loaded it (from the user's cache: built there at most once)."""
    module = cpu_backend.load_kernel()
    if module is None:
        pytest.skip(
            f"no compiled kernel here (test_cpu_kernel_is_built_and_loaded says why): "
            f"{cpu_backend.unavailable_reason()}"
        )
    return module


def copy_sources(folder: Path) -> Path:
    """A copy of the kernel's csrc folder under ``folder`` (as an installed extension would hold it)."""
    return Path(shutil.copytree(kernel_cache.CSRC, folder / "csrc"))


def built_files(directory: Path) -> dict[str, int]:
    """The compiled objects and library in a build folder, by modification time (ns)."""
    return {p.name: p.stat().st_mtime_ns for p in directory.iterdir() if p.suffix in (".o", kernel_cache.LIB_EXT)}


def build_folders() -> set[str]:
    """The kernel build folders in the cache."""
    return {p.name for p in kernel_cache.cache_base().glob("raster_cpu-*")}


def test_identical_sources_in_two_folders_share_one_build(kernel, tmp_path):
    """The sources copied to two other places key the same build folder and load its library: nothing
    is compiled and no build folder appears."""
    home = kernel_cache.build_dir()
    assert Path(kernel.__file__) == home / f"{kernel_cache.NAME}{kernel_cache.LIB_EXT}"
    folders, files = build_folders(), built_files(home)
    for place in ("installed extension", "source tree"):
        csrc = copy_sources(tmp_path / place)
        assert kernel_cache.build_dir(csrc) == home
        assert Path(kernel_cache.load(csrc).__file__) == Path(kernel.__file__)
    assert build_folders() == folders and built_files(home) == files


def test_edited_sources_get_their_own_build_folder(tmp_path):
    """One changed byte in a source is a different kernel: a different folder, never a stale library."""
    csrc = copy_sources(tmp_path)
    with (csrc / kernel_cache.SOURCE_NAMES[0]).open("a") as source:
        source.write("\n")
    assert kernel_cache.build_dir(csrc) != kernel_cache.build_dir()


def test_another_compiler_gets_its_own_build_folder(tmp_path, monkeypatch):
    """The compiler's ``--version`` is part of the key (CXX is the compiler torch's loader runs)."""
    fake = tmp_path / "fake-c++"
    fake.write_text("#!/bin/sh\necho 'fake-c++ 99.1'\n")
    fake.chmod(fake.stat().st_mode | stat.S_IXUSR)
    home = kernel_cache.build_dir()
    monkeypatch.setenv("CXX", str(fake))
    assert kernel_cache.build_inputs()["compiler"] == "fake-c++ 99.1"
    assert kernel_cache.build_dir() != home


def test_a_build_folder_without_its_done_marker_is_not_imported(tmp_path):
    """A library with no marker may be half written (a build still running or killed): it is rebuilt."""
    (tmp_path / f"{kernel_cache.NAME}{kernel_cache.LIB_EXT}").write_bytes(b"not a library")
    assert kernel_cache.import_built(tmp_path) is None


@pytest.mark.parametrize("n", [0, 1, 2, 1000, 300_000])
def test_depth_order_is_a_stable_argsort(kernel, n):
    """The kernel's radix depth sort gives exactly torch's stable argsort: negative, zero (both signs),
    infinite and tied depths included, ties in index order (what the tile lists' front-to-back order needs)."""
    import torch

    depths = torch.randn(n, generator=torch.Generator().manual_seed(n)) * 5.0
    if n >= 1000:
        depths[::7] = depths[3]  # ties
        depths[1::97] = 0.0
        depths[2::97] = -0.0
        depths[5] = float("inf")
        depths[6] = -float("inf")
        depths[8::11] = depths[8::11] * 1e-30  # subnormal-range magnitudes of both signs
    order = cpu_backend.depth_order(depths)
    assert order.dtype == torch.int64
    assert torch.equal(order, torch.argsort(depths, stable=True))


@pytest.mark.parametrize("n_cams", [1, 3])
def test_tile_lists_equal_the_portable_binning(kernel, n_cams):
    """The kernel's parallel counting sort gives the portable binning's tile lists exactly (offsets and
    every tile's entries front to back), over enough entries that every thread sorts a run of them."""
    import torch

    from gt2gs_blender.core.render.binning import bin_entries_torch

    g = torch.Generator().manual_seed(n_cams)
    m, tiles_x, tiles_y = 60_000, 12, 9
    x0, y0 = torch.randint(0, tiles_x, (m,), generator=g), torch.randint(0, tiles_y, (m,), generator=g)
    x1 = (x0 + torch.randint(0, 4, (m,), generator=g)).clamp(max=tiles_x - 1)
    y1 = (y0 + torch.randint(0, 3, (m,), generator=g)).clamp(max=tiles_y - 1)
    bbox = torch.stack([x0, y0, x1, y1], 1).to(torch.int32).contiguous()
    cams = torch.randint(0, n_cams, (m,), generator=g).to(torch.int32)
    depths = torch.randperm(m, generator=g).float() * 1e-3 + 0.1  # distinct: the portable sort is not stable
    offsets, pairs = kernel.bin_tiles(bbox, cams, cpu_backend.depth_order(depths), n_cams, tiles_x, tiles_y)
    portable = bin_entries_torch(bbox, cams, depths, n_cams, tiles_x, tiles_y)
    assert torch.equal(offsets, portable.offsets)
    assert torch.equal(pairs, portable.pair_gauss)
