"""Every splat format through one entry point: detection from content, the .splat codec, ``info``, ``render``,
``convert`` and ``transfer -o`` on files splat-transform made, and our files read back by splat-transform."""

from __future__ import annotations

import json
import shutil
import struct
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from gt2gs_blender.app.cli import main as cli
from gt2gs_blender.app.cli.demo import stripes_texture
from gt2gs_blender.core.cameras.generate import auto_views
from gt2gs_blender.core.errors import SplatFormatError
from gt2gs_blender.core.render import render
from gt2gs_blender.core.scene.codec import (
    canonical_quats,
    colour_from_dc,
    from_smallest_three,
    sigmoid,
    smallest_three,
)
from gt2gs_blender.core.scene.files import (
    COMPRESSED_PLY,
    FORMATS,
    PLY,
    SOG,
    SPLAT,
    SPZ,
    WRITERS,
    detect_format,
    read_scene,
    read_splats,
    write_splats,
)
from gt2gs_blender.core.scene.ply import read_ply_arrays
from gt2gs_blender.core.scene.ply_header import read_ply_header
from gt2gs_blender.core.scene.ply_write import write_ply
from gt2gs_blender.core.scene.splat import read_splat

from .splat_tools import donut_path, splat_transform, synthetic_scene

MIN_PSNR = 30.0


def psnr(a: torch.Tensor, b: torch.Tensor) -> float:
    """Peak signal-to-noise ratio of two images in 0..1, in dB."""
    return float(10 * torch.log10(1.0 / torch.mean((a - b) ** 2)))


def renders(path: Path) -> torch.Tensor:
    """Four 128 px views of a splat file, over white, framed on the shared donut."""
    cameras = auto_views(read_scene(donut_path()), 4, width=128, height=128)
    return render(read_scene(path), cameras, background=(1.0, 1.0, 1.0)).colors.clamp(0, 1)


def test_hand_made_splat_records_read_as_the_format_says(tmp_path):
    path = tmp_path / "two.splat"
    records = [
        ((1, 2, 3), (0.1, 0.2, 0.3), (255, 0, 128, 64), (255, 128, 128, 128)),
        ((-1, 0, 5e3), (1e-4, 2.0, 7.5), (10, 20, 30, 255), (128, 255, 0, 128)),
    ]
    path.write_bytes(b"".join(struct.pack("<6f8B", *p, *s, *c, *r) for p, s, c, r in records))
    arrays = read_splat(path)
    assert np.array_equal(arrays.means, np.array([p for p, *_ in records], np.float32))
    assert np.allclose(np.exp(arrays.log_scales), [s for _, s, *_ in records], rtol=1e-6)
    assert np.allclose(colour_from_dc(arrays.sh_dc), [np.array(c[:3]) / 255 for *_, c, _ in records], atol=1e-6)
    assert np.allclose(sigmoid(arrays.opacity_logits), [c[3] / 255 for *_, c, _ in records], atol=1e-6)
    stored = np.array([r for *_, r in records], np.float64) / 255 * 2 - 1
    assert np.allclose(arrays.quats, canonical_quats(stored), atol=1e-6)
    assert arrays.sh_rest.shape == (2, 0, 3)


def test_our_splat_files_are_what_splat_transform_reads(tmp_path):
    scene = synthetic_scene(500, sh_degree=3)
    notes = write_splats(tmp_path / "s.splat", scene)
    assert notes == ["splat keeps SH degree 0 at most: bands 1-3 dropped"]
    splat_transform(tmp_path / "s.splat", tmp_path / "back.ply")
    back = read_ply_arrays(tmp_path / "back.ply")
    assert np.array_equal(back.means, scene.means)  # float32 both ways
    assert np.allclose(back.log_scales, scene.log_scales, atol=1e-6)
    step = 1 / 255  # 8-bit colour and opacity: half a step each way, plus float slack
    assert np.abs(colour_from_dc(back.sh_dc) - np.clip(colour_from_dc(scene.sh_dc), 0, 1)).max() <= step / 2 + 1e-6
    assert np.abs(sigmoid(back.opacity_logits) - sigmoid(scene.opacity_logits)).max() <= step / 2 + 1e-6
    rotation = np.abs(np.einsum("ij,ij->i", canonical_quats(back.quats), canonical_quats(scene.quats)))
    assert rotation.min() > 1 - 1e-3  # 8 bits a component: |<q, q'>| within 1e-3 of 1 (about 5 degrees at most)


def test_the_format_comes_from_the_content_not_the_name(donut_files, tmp_path):
    for fmt, path in donut_files.items():
        assert detect_format(path) == fmt
        if fmt != SPLAT:  # .splat has no magic bytes: only its name says what it is
            renamed = tmp_path / f"renamed_{fmt}.bin"
            shutil.copyfile(path, renamed)
            assert detect_format(renamed) == fmt
    unpacked = tmp_path / "unpacked"
    splat_transform(donut_files[PLY], unpacked / "meta.json")
    assert detect_format(unpacked) == detect_format(unpacked / "meta.json") == SOG


@pytest.mark.parametrize("fmt", [COMPRESSED_PLY, SOG, SPZ, SPLAT])
def test_info_and_render_read_every_format(fmt, donut_files, capsys, tmp_path):
    path = donut_files[fmt]
    assert cli.main(["info", str(path), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert (info["format"], info["count"], info["keeps"]) == (fmt, 45624, FORMATS[fmt].keeps)
    assert cli.main(["render", str(path), "-o", str(tmp_path / "views"), "--views", "2", "--width", "64"]) == 0
    assert sorted(p.name for p in (tmp_path / "views").glob("view_*.png")) == ["view_000.png", "view_001.png"]
    assert psnr(renders(path), renders(donut_files[PLY])) >= MIN_PSNR


@pytest.mark.parametrize("fmt", sorted(WRITERS))
def test_convert_round_trips_and_splat_transform_reads_our_files(fmt, donut_files, capsys, tmp_path):
    out = tmp_path / f"donut{FORMATS[fmt].extensions[0]}"
    assert cli.main(["convert", str(donut_files[PLY]), str(out)]) == 0
    assert f"wrote 45,624 splats to {out}" in capsys.readouterr().out
    assert detect_format(out) == fmt and len(read_splats(out)) == 45624
    assert psnr(renders(out), renders(donut_files[PLY])) >= MIN_PSNR
    splat_transform(out, tmp_path / "back.ply")  # its PLY may hold opacity logits of +-inf (bytes 0 and 255)
    vertices = next(e for e in read_ply_header(tmp_path / "back.ply").elements if e.name == "vertex")
    assert vertices.count == 45624


def test_a_lossy_write_says_what_it_dropped(capsys, tmp_path):
    write_ply(tmp_path / "sh3.ply", synthetic_scene(200, sh_degree=3))
    assert cli.main(["convert", str(tmp_path / "sh3.ply"), str(tmp_path / "sh3.splat")]) == 0
    assert "splat keeps SH degree 0 at most: bands 1-3 dropped" in capsys.readouterr().err


def test_sog_is_read_only_and_unknown_files_are_one_error(donut_files, capsys, tmp_path):
    assert cli.main(["convert", str(donut_files[PLY]), str(tmp_path / "out.sog")]) == 2
    assert "PlayCanvas SOG is read only here" in capsys.readouterr().err
    junk = tmp_path / "junk.spz"
    junk.write_bytes(b"not a splat file at all")
    with pytest.raises(SplatFormatError, match=r"junk\.spz: not a SPZ file \(it starts with"):
        read_splats(junk)
    (tmp_path / "empty").mkdir()
    with pytest.raises(SplatFormatError, match=r"is a directory, and not an unpacked SOG scene"):
        read_splats(tmp_path / "empty")
    with pytest.raises(SplatFormatError, match=r"not a whole number of 32-byte splat records"):
        (tmp_path / "cut.splat").write_bytes(b"\0" * 33)
        read_splats(tmp_path / "cut.splat")


def test_transfer_writes_the_format_its_output_names(donut_files, capsys, tmp_path):
    texture = tmp_path / "stripes.png"
    cv2.imwrite(str(texture), (stripes_texture(64)[..., ::-1] * 255).astype(np.uint8))
    out = tmp_path / "styled.spz"
    code = cli.main(
        [
            "transfer",
            str(donut_files[SPZ]),
            str(texture),
            "-o",
            str(out),
            "--preset",
            "preview",
            "--steps",
            "2",
            "--correct-steps",
            "2",
            "--resolution",
            "32",
            "--views",
            "2",
        ]
    )
    assert code == 0, capsys.readouterr().err
    assert detect_format(out) == SPZ and len(read_splats(out)) >= 45624


def test_smallest_three_round_trips_every_largest_component():
    rng = np.random.default_rng(1)
    quats = rng.normal(size=(400, 4))
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    largest, others = smallest_three(quats)
    assert set(largest.tolist()) == {0, 1, 2, 3} and np.abs(others).max() <= np.sqrt(0.5) + 1e-12
    rebuilt = from_smallest_three(largest, others)
    assert np.allclose(np.abs(np.einsum("ij,ij->i", rebuilt, quats)), 1.0)  # the same rotation (up to sign)


def test_the_readme_lists_every_format_with_what_it_keeps():
    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8")
    for fmt in FORMATS.values():
        assert fmt.keeps in readme, fmt.label
