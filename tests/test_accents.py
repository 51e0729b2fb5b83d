"""Keep Accents: a capture's rare, vivid colours keep most of themselves under the texture, on the splats, in the
preview and in the layout term's images alike; common or grey colours keep only Scene Colour."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from gt2gs_blender.core.render import render
from gt2gs_blender.core.transfer.accents import COMMON, ColourShare, colour_share
from gt2gs_blender.core.transfer.config import TransferConfig
from gt2gs_blender.core.transfer.layout import (
    layout_frame,
    layout_images,
    layout_parts,
    scene_colour_mix,
    seen_images,
    with_colours,
)
from gt2gs_blender.core.transfer.shade import kept_scene, under_scene
from gt2gs_blender.core.transfer.views import render_views
from tests.test_layout import front_camera, wall, zero_step_config

GREY, VIVID_BLUE = (0.5, 0.5, 0.5), (0.1, 0.2, 0.9)
LUMA = np.array([0.2126, 0.7152, 0.0722])


def spotted_wall() -> tuple:
    """The grey wall with a small vivid blue square in its middle (a robot's eye), its front camera, and which
    splats are blue."""
    base, cam = wall(n=60), front_camera(96)
    spot = (base.means[:, 0].abs() < 0.12) & (base.means[:, 1].abs() < 0.12)
    colours = torch.where(spot[:, None], torch.tensor(VIVID_BLUE).expand(len(base), 3), torch.tensor(GREY))
    return with_colours(base, colours), cam, spot


def expected_share(base: float, keep: float, share_of_scene: float) -> float:
    """The share a fully vivid colour held by ``share_of_scene`` of the scene's weight keeps (the module's rule,
    worked out by hand: rarity 1 - share / COMMON)."""
    return base + (1.0 - base) * keep * max(0.0, 1.0 - share_of_scene / COMMON)


def test_a_rare_vivid_colour_keeps_more_of_itself_and_grey_or_common_ones_keep_scene_colour():
    colours = torch.tensor([VIVID_BLUE] * 2 + [GREY] * 98)
    share = colour_share(colours, torch.ones(100), 0.15, 0.8)
    assert isinstance(share, ColourShare)
    got = share(colours).numpy()
    assert got[0] == pytest.approx(expected_share(0.15, 0.8, 0.02), abs=0.01)
    assert got[2:] == pytest.approx(0.15, abs=1e-6)  # grey: nothing vivid to keep
    halves = torch.tensor([VIVID_BLUE] * 50 + [(0.9, 0.3, 0.1)] * 50)  # vivid, but half the scene each
    assert colour_share(halves, torch.ones(100), 0.15, 0.8)(halves).numpy() == pytest.approx(0.15, abs=1e-6)
    rare_grey = torch.tensor([(0.1, 0.1, 0.1)] * 2 + [VIVID_BLUE] * 98)  # rare, but grey
    kept = colour_share(rare_grey, torch.ones(100), 0.15, 0.8)(rare_grey)
    assert kept[:2].numpy() == pytest.approx(0.15, abs=1e-6)


def test_an_accent_takes_its_hue_and_keeps_the_texture_s_light_and_dark():
    """Under any texture an accent's mix has the luminance the mix without Keep Accents has (the texture's pattern
    runs on through it), and its hue turns to the accent's own: the blue channel's share rises."""
    colours = torch.tensor([VIVID_BLUE] * 2 + [GREY] * 98)
    shade = torch.rand(100, generator=torch.Generator().manual_seed(0)) * 0.8 + 0.1
    texture = torch.rand(100, 3, generator=torch.Generator().manual_seed(1)) * 0.5
    share = colour_share(colours, torch.ones(100), 0.15, 0.8)
    plain, accented = (under_scene(texture, kept_scene(shade, colours, c)) for c in (0.15, share))
    luma = torch.tensor(LUMA, dtype=torch.float32)
    assert torch.allclose(accented @ luma, plain @ luma, atol=1e-6)
    assert torch.equal(accented[2:], plain[2:])  # grey: no accent, the same mix
    blue_share = (accented[:2, 2] / accented[:2].sum(1)).mean(), (plain[:2, 2] / plain[:2].sum(1)).mean()
    assert blue_share[0] > blue_share[1] + 0.1


def test_the_share_weighs_splats_by_what_they_cover_and_is_plain_when_off_or_empty():
    colours = torch.tensor([VIVID_BLUE] * 2 + [GREY] * 98)
    heavy = torch.ones(100)
    heavy[:2] = 49.0  # two huge blue splats cover half the view: common, no accent
    assert colour_share(colours, heavy, 0.15, 0.8)(colours)[0] == pytest.approx(0.15, abs=1e-6)
    assert colour_share(colours, torch.ones(100), 0.15, 0.0) == 0.15
    assert colour_share(colours, torch.zeros(100), 0.3, 0.8) == 0.3
    assert colour_share(colours[:0], torch.ones(0), 0.3, 0.8) == 0.3


def test_with_nothing_of_the_scene_kept_accents_keep_nothing_either():
    """Keep Scene, Scene Colour and Scene Brightness 0 lay the texture alone (the old, bolder default): no accent
    comes back through Keep Accents."""
    scene, _, _ = spotted_wall()
    alone = TransferConfig(keep_scene=0.0, scene_colour=0.0, scene_brightness=0.0, keep_accents=1.0)
    assert scene_colour_mix(scene, None, alone) == 0.0
    assert isinstance(scene_colour_mix(scene, None, replace(alone, keep_scene=0.5)), ColourShare)


@pytest.mark.parametrize("keep", [0.8, 0.0])
def test_a_run_keeps_a_small_vivid_spot_its_colour_on_the_splats_the_preview_and_the_layout_image(
    shared, tmp_path, keep
):
    """A flat dark grey texture (0.3) on the spotted wall, Keep Scene 1, Scene Colour 0.15, Scene Brightness 0:
    every splat comes out (1 - share) x grey x its shade + 0.15 x its own colour, and the spot, its share raised by
    Keep Accents as the rule says for its share of the wall, adds that raise of its own hue at the shaded texture's
    luminance (its shade times the texture's 0.3: the blue as dark against the wall as in the scene, not lighter);
    the preview shows what the run lays and the layout term's image holds the spot to the same colour."""
    from gt2gs_blender.core.api import transfer
    from gt2gs_blender.core.transfer.orientation_preview import preview

    scene, cam, spot = spotted_wall()
    grey = np.full((64, 64, 3), 0.3, np.float32)
    config = zero_step_config(
        shared, tmp_path, keep_scene=1.0, scene_colour=0.15, keep_accents=keep, keep_hues=0.0, scene_brightness=0.0
    )
    result = transfer(scene, grey, [cam], config)
    share = expected_share(0.15, keep, float(spot.float().mean()))
    luminance = float(np.dot(VIVID_BLUE, LUMA))
    shade = luminance / 0.5  # against the bright end: the grey wall
    hue_at = np.array(VIVID_BLUE) * shade * 0.3 / luminance
    expected = (1.0 - share) * 0.3 * shade + 0.15 * np.array(VIVID_BLUE) + (share - 0.15) * hue_at
    laid, centre = result.scene, result.scene.means[:, :2].abs().amax(dim=1)  # the detail split's children too
    assert laid.base_colors[centre < 0.1].mean(0).numpy() == pytest.approx(expected, abs=0.02)
    rest = (1.0 - 0.15) * 0.3 + 0.15 * np.array(GREY)
    assert laid.base_colors[centre > 0.16].mean(0).numpy() == pytest.approx(rest, abs=0.01)

    shown = render(result.scene, [cam], background=torch.zeros(3)).colors[0].clamp(0, 1).numpy() * 255.0
    assert np.abs(preview(scene, grey, [cam], config, size=96).image.astype(np.float32) - shown).max() <= 1.0

    views = render_views(scene, [cam], torch.zeros(3), "auto")
    mix = colour_share(scene.base_colors, torch.ones(len(scene)), 0.15, keep)
    (ideal,) = layout_images(views, grey, layout_frame(scene, views, config), 0.0, True, keep=1.0, colour=mix)
    middle = ideal[47:49, 47:49]  # the spot's middle on screen (it spans 7 px)
    assert middle[..., :3].reshape(-1, 3).mean(0).numpy() == pytest.approx(expected, abs=0.03)


ICING, DOUGH = (0.85, 0.55, 0.65), (0.80, 0.65, 0.45)


def chromaticities(colours: np.ndarray) -> np.ndarray:
    """(N, 3) ``colours`` over their luminance, by hand."""
    return colours / (colours @ LUMA)[:, None]


def test_keep_hues_shifts_each_splat_s_texture_by_its_part_s_hue_against_grey_and_adds_no_light():
    """Keep Hues 1 with no Scene Colour or accents: each splat's mix is the shaded texture with its chromaticity
    moved by exactly its part's chromaticity less grey's (worked out by hand), whatever the splat's own colour (its
    noise does not pass into the shift), a grey part's not at all, and its luminance is the plain mix's; with no
    parts given, or Keep Hues 0, the mix is as it was."""
    noise = torch.rand(100, 3, generator=torch.Generator().manual_seed(2)) * 0.1 - 0.05
    parts = torch.tensor([ICING] * 30 + [DOUGH] * 50 + [GREY] * 20)
    colours = (parts + noise).clamp(0.0, 1.0)
    shade = torch.rand(100, generator=torch.Generator().manual_seed(0)) * 0.5 + 0.4
    texture = torch.rand(100, 3, generator=torch.Generator().manual_seed(1)) * 0.3 + 0.35
    share = colour_share(colours, torch.ones(100), 0.0, 0.0, hues=1.0)
    assert isinstance(share, ColourShare) and colour_share(colours, torch.ones(100), 0.0, 0.0) == 0.0
    plain = under_scene(texture, kept_scene(shade, colours, 0.0))
    tinted = under_scene(texture, kept_scene(shade, colours, share, parts=parts))
    luma = torch.tensor(LUMA, dtype=torch.float32)
    assert torch.allclose(tinted @ luma, plain @ luma, atol=1e-6)
    moved = chromaticities(tinted.double().numpy()) - chromaticities(plain.double().numpy())
    assert moved == pytest.approx(chromaticities(parts.double().numpy()) - 1.0, abs=1e-4)
    assert np.abs(moved[80:]).max() < 1e-5  # a grey part keeps the texture's hue
    assert torch.equal(under_scene(texture, kept_scene(shade, colours, share)), plain)  # no parts, no hue
    untinted = colour_share(colours, torch.ones(100), 0.0, 0.8, hues=0.0)
    assert torch.equal(under_scene(texture, kept_scene(shade, colours, untinted, parts=parts)), plain)


def test_a_run_keeps_each_part_s_hue_on_the_splats_the_preview_and_the_layout_image(shared, tmp_path):
    """A flat grey texture on a wall whose left half is icing and right half dough, Keep Scene 1, Keep Hues 1 and
    nothing else of the scene's colour: the texture's grey takes each part's chromaticity (``find_parts`` finds
    the two halves), so each half comes out in its own hue at the shaded texture's luminance; the preview shows
    what the run lays and the layout term's image holds each half to the same colour."""
    from gt2gs_blender.core.api import transfer
    from gt2gs_blender.core.transfer.orientation_preview import preview

    base, cam = wall(n=60), front_camera(96)
    left = base.means[:, 0] < 0
    scene = with_colours(base, torch.where(left[:, None], torch.tensor(ICING), torch.tensor(DOUGH)))
    grey = np.full((64, 64, 3), 0.3, np.float32)
    config = zero_step_config(
        shared, tmp_path, keep_scene=1.0, scene_colour=0.0, keep_accents=0.0, keep_hues=1.0, scene_brightness=0.0
    )
    laid = transfer(scene, grey, [cam], config).scene
    for side, colour in ((laid.means[:, 0] < -0.1, ICING), (laid.means[:, 0] > 0.1, DOUGH)):
        got = laid.base_colors[side].double().numpy()
        assert np.abs(chromaticities(got) - chromaticities(np.array([colour]))).max() < 0.01
        assert np.abs(got @ LUMA - 0.3 * float(np.dot(colour, LUMA)) / max_luma()).max() < 0.01  # shaded

    shown = render(laid, [cam], background=torch.zeros(3)).colors[0].clamp(0, 1).numpy() * 255.0
    assert np.abs(preview(scene, grey, [cam], config, size=96).image.astype(np.float32) - shown).max() <= 1.0

    views = render_views(scene, [cam], torch.zeros(3), "auto")
    parts = seen_images(scene, views, layout_parts(scene, config), "auto")
    mix = colour_share(scene.base_colors, torch.ones(len(scene)), 0.0, 0.0, hues=1.0)
    frame = layout_frame(scene, views, config)
    (ideal,) = layout_images(views, grey, frame, 0.0, True, keep=1.0, colour=mix, parts=parts)
    for columns, colour in ((slice(20, 30), ICING), (slice(66, 76), DOUGH)):
        seen = ideal[40:56, columns, :3].reshape(-1, 3).double().numpy()
        assert chromaticities(seen).mean(0) == pytest.approx(chromaticities(np.array([colour]))[0], abs=0.02)


def max_luma() -> float:
    """The wall's bright end: the lighter half's luminance (the shade is each splat's luminance over it)."""
    return max(float(np.dot(ICING, LUMA)), float(np.dot(DOUGH, LUMA)))
