"""Texture-transfer settings and what each one means: the one source of both (the presets: ``presets.py``).

Every field of :class:`TransferConfig` carries a :class:`Setting` (label, one-line help in an artist's words,
unit, range or choices, the part of the method it belongs to), which also validates it. The command line's
flags, the Blender panel's properties and tooltips, and the panel-to-config map are generated from these, so a
new setting is written once, here (the machine's and the speed settings in their own bases, ``machine.py`` and
``speed.py``). The paper's value of a setting is read from the ``paper-llff`` preset.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import asdict, dataclass, fields, replace
from typing import Any, get_args, get_type_hints

from .setting import (
    DEGREES,
    PARTS,
    Projection,
    Setting,
    Switch,
    UpAxis,
    ViewKind,
    setting,
    value_type,
)
from .speed import SpeedSettings

MAX_DEPTH_RATIO = 2.0
"""Largest measured depth ratio the bank follows (the authors' fixed one): deeper scenes keep it, not a smudge."""
SPLATS_PER_PIXEL = 4.0
"""Splats behind each pixel of the object above which the run works at a larger size (up to Dense Upscale):
denser than this, the run sets their colours only in blends and a capture's fine lines blur."""
FORWARD_SPREAD_DEG = 45.0
"""Views all within this angle of their mean direction are a capture seen from the front (the Auto choices)."""
PRUNE_SCREEN_RADIUS = 20.0
PRUNE_WORLD_SCALE = 0.2
"""Prune Large Splats' limits: a screen radius in pixels and a share of the views' extent (the authors'
``densify_and_prune(..., 20)`` and ``0.2 * extent``)."""


@dataclass(frozen=True)
class TransferConfig(SpeedSettings):
    """Every setting of a transfer run (the machine's and the speed settings first, from the bases). Loss weights
    follow the paper's names (lambda_*)."""

    # -- views
    resolution: int = setting(
        256,
        "Resolution",
        "Longest side of the working views; automatic views frame the object in a square this size (with Views Fit "
        "Object, less the empty bands beside it)",
        "views",
        unit="px",
        min=16,
        max=8192,
        soft_max=1024,
    )
    dense_upscale: float = setting(
        1.0,
        "Dense Upscale",
        f"A dense capture (more than {SPLATS_PER_PIXEL:g} splats behind each pixel of the object at Resolution) is "
        "worked at up to this many times Resolution, so its fine lines and the texture's stay sharp; the run takes "
        "longer (1: always at Resolution)",
        "views",
        min=1.0,
        soft_max=4.0,
    )
    n_views: int = setting(
        16,
        "View Count",
        "Automatic views around the object (when no cameras are given)",
        "views",
        min=1,
        soft_max=64,
        flag="--views",
    )
    view_kind: ViewKind = setting(
        "auto",
        "Automatic Views",
        "Where the automatic views stand when no cameras are given. Auto: Inside when the splats' sizes say the "
        "capture was taken from within it, else Orbit. Orbit: a ring all round the object. Front: a short arc on "
        "the side the capture was taken from, read from its splats' sizes (splats near the cameras are small; where "
        "they do not tell, the arc on Blender's front), for a capture seen from the front, such as a plant before "
        "its wall, given without its cameras. Inside: standing where the cameras stood (else in the middle) and "
        "looking out all round, for a room",
        "views",
        choices=get_args(ViewKind),
        flag="--auto-views",
    )
    up: UpAxis = setting(
        "auto",
        "Up Axis",
        "The scene's up direction, for automatic views. Auto: in Blender, the object's axis you turned to point "
        "up; else from the splats: the end a tall object stands on, the ground under a capture, else +Z "
        "(Blender's up; -Y for a trainer's capture lying flat). "
        "Set it when the views lie on their side (on the command line: --up=-y)",
        "views",
        choices=get_args(UpAxis),
    )
    feature_scale: float = setting(
        0.5, "Feature Scale", "Renders are resized by this before the feature network", "views", min=0.05, max=4.0
    )
    background: tuple[float, float, float] = setting(
        (1.0, 1.0, 1.0), "Background", "Colour behind the object in the working views", "views", min=0.0, max=1.0
    )
    # -- texture
    layout: bool = setting(
        False,
        "Lay Out Texture",
        "Lay the texture on the object before optimising (projected as Projection says, at the set size "
        "and angle), so planks, bricks and cells show; off: start from the object's own colours, as the paper does",
        "texture",
    )
    layout_projection: Projection = setting(
        "auto",
        "Projection",
        "How Lay Out Texture puts the texture on the scene: Box wraps it around an object seen from all "
        "sides; View throws it from the first view like a slide projector (a capture seen from the front); "
        f"Auto: View when every view looks within {FORWARD_SPREAD_DEG:g}° of the views' mean direction, else Box",
        "texture",
        choices=get_args(Projection),
    )
    box_fits_faces: bool = setting(
        True,
        "Box Fits Faces",
        "With Projection Box, turn the box about the up axis onto the object's own flat faces (a cabinet's front "
        "and sides, a guitar's body), so each face shows the texture undistorted and once, however its file turns "
        "it; an object whose sides face every way alike (a drum, a figure on flat ground) keeps the box as the "
        "first view stands; off: always as the first view stands",
        "texture",
    )
    keep_scene: float = setting(
        0.85,
        "Keep Scene",
        "How much of the scene's light and dark shows through the laid-out texture: 1 all of it (edges and "
        "parts read; the texture fainter in dark parts); 0.85 eases the darks so the texture reads there too; "
        "on a dark capture (a guitar on its stand) lower values lay more of the pattern, at the cost of the "
        "capture's own parts (its sunburst, its pickups); "
        "0 lays the texture evenly, so only the outline shows the scene",
        "texture",
        min=0.0,
        max=1.0,
    )
    scene_colour: float = setting(
        0.15,
        "Scene Colour",
        "How much of the capture's own colour shows under the laid-out texture: 0 colours it with the "
        "texture alone; 0.15 mixes in 15 % of each spot's own colour, a trace of each part's hue; 0.3-0.5 "
        "keeps parts that differ only in hue (pink icing on beige dough, a robot's eyes) plainly apart, at the "
        "texture's expense; 1 keeps the capture's colours with no texture",
        "texture",
        min=0.0,
        max=1.0,
    )
    keep_accents: float = setting(
        0.8,
        "Keep Accents",
        "How much of the capture's rare, vivid colours keeps its hue under the laid-out texture (a robot's "
        "glowing eyes, a donut's sprinkles, a logo: colours few splats have); the texture's light and dark run on "
        "through them: 0.8 keeps most of their hue, so they still read as what they are; 0 gives them only the "
        "Scene Colour every part keeps; 1 all of it",
        "texture",
        min=0.0,
        max=1.0,
    )
    keep_hues: float = setting(
        0.5,
        "Keep Hues",
        "How much each part's own hue tints the laid-out texture (pink icing on beige dough, an amber top above "
        "a dark neck), one hue per part and no change to its light and dark, so the texture keeps its pattern; "
        "grey parts keep the texture's own hue; 0.5 keeps parts apart in colour; 1 more so, though saturated "
        "parts show more colour speckle; 0: the texture's hue everywhere",
        "texture",
        min=0.0,
        max=1.0,
    )
    scene_brightness: float = setting(
        1.0,
        "Scene Brightness",
        "How far the laid-out texture takes on the capture's overall brightness: 1 as bright as the capture "
        "on average (a dim room stays dim, a white object stays light, colours keep their hue); 0 the texture's "
        "own brightness under the kept light and dark (darker than the capture where the texture is darker "
        "than white)",
        "texture",
        min=0.0,
        max=1.0,
    )
    keep_material: float = setting(
        1.0,
        "Keep Material",
        "How much of each part's own brightness stays under the laid-out texture: 1 keeps dark wood and black "
        "metal dark, the texture darkened with them; 0 gives every part (as Find Parts finds them) the texture's "
        "own brightness and keeps only the light and shade across it: straw on a dark guitar comes out "
        "straw-coloured, but a bright scene loses the light and dark between its parts",
        "texture",
        min=0.0,
        max=1.0,
    )
    shade_softness: float = setting(
        0.0,
        "Scene Softness",
        "How broad the kept scene is, in texture repeats: 0 keeps every edge and speck of the capture; "
        "larger keeps only its broad light and dark, so the texture's own pattern reads more, while the "
        "scene's shapes fade",
        "texture",
        min=0.0,
        max=1.0,
    )
    texture_softness: float = setting(
        0.01,
        "Texture Softness",
        "Softens the texture photo's finest grain, over this share of one repeat, before it is laid on: 0.01 "
        "smooths its speckle away, so the capture's edges read under the planks, bricks and cells; 0: the photo "
        "as it is",
        "texture",
        min=0.0,
        max=0.1,
        soft_max=0.05,
    )
    texture_repeats: float = setting(
        0.0,
        "Texture Repeats",
        "How many times the texture repeats across the object; 0: use Texture Size in pixels instead",
        "texture",
        min=0.0,
        soft_max=12.0,
    )
    texture_offset_right: float = setting(
        0.0,
        "Offset Right",
        "With Lay Out Texture on, slide the texture to the right as the first view sees it, by this share of one "
        "repeat (1: a whole repeat, the same look), to line a row of bricks or planks up with an edge",
        "texture",
        min=-1.0,
        max=1.0,
    )
    texture_offset_up: float = setting(
        0.0,
        "Offset Up",
        "With Lay Out Texture on, slide the texture up as the first view sees it, by this share of one repeat "
        "(1: a whole repeat, the same look)",
        "texture",
        min=-1.0,
        max=1.0,
    )
    split_size: float = setting(
        0.015,
        "Split Splats Above",
        "With Lay Out Texture on, splats larger than this share of one texture repeat are split (within "
        "Split Budget), so the texture's lines can run between them; 0: never split",
        "texture",
        min=0.0,
        max=1.0,
    )
    split_budget: float = setting(
        12.0,
        "Split Budget",
        "The most splats Split Splats Above may make, as a multiple of the object's: larger draws finer "
        "lines where the splats are coarse, but the saved file and the run grow with it (1: never split)",
        "texture",
        min=1.0,
        soft_max=24.0,
    )
    split_first: bool = setting(
        True,
        "Split Before Refining",
        "Split the coarse splats before the texture loss refines them, so it draws the texture's lines on "
        "the fine splats (sharper planks, bricks and cells; about twice the time); off: split at the end",
        "texture",
    )
    lambda_layout: float = setting(
        10.0,
        "Layout Strength",
        "How closely the result keeps the laid-out texture, with the scene under it as Keep Scene lays it (its "
        "planks, bricks and cells, and the capture's light and dark), while the texture loss refines its look "
        "(with Lay Out Texture on); lower lets the texture loss repaint more of the scene",
        "texture",
        min=0.0,
        soft_max=50.0,
    )
    texture_height: int = setting(
        256,
        "Texture Size",
        "Height of the texture on the nearest surfaces, in pixels of the view at half the "
        "working resolution (as the feature network sees it), when Texture Repeats is 0; smaller "
        "repeats the pattern more often",
        "texture",
        unit="px",
        min=8,
        soft_max=1024,
    )
    n_angles: int = setting(
        36, "Texture Rotations", "Rotations of the texture over 360° the bank holds", "texture", min=1, max=360
    )
    n_scales: int = setting(
        4, "Depth Groups", "Texture sizes, one per depth group of the view (paper: K)", "texture", min=1, max=8
    )
    depth_groups: bool = setting(
        True, "Depth Grouping", "Show the texture larger on near surfaces than on far ones", "texture"
    )
    depth_ratio: float = setting(
        0.0,
        "Depth Ratio",
        "How many times smaller the texture shows on the farthest surfaces than on the nearest: "
        f"0 = as perspective shows it, measured from the views (at most {MAX_DEPTH_RATIO:g}); 1-16 fixed",
        "texture",
        min=0.0,
        max=16.0,
    )
    cell_coverage: float = setting(
        0.5,
        "Cell Coverage",
        "How much of a feature cell the object must cover for the texture to count there",
        "texture",
        min=0.0,
        max=1.0,
    )
    # -- stylise
    stylise_steps: int = setting(
        200,
        "Steps",
        "Optimisation steps of the stylisation",
        "stylise",
        unit="steps",
        min=0,
        soft_max=2000,
        flag="--steps",
    )
    lr: float = setting(0.02, "Learning Rate", "Step size on the splats' colours", "stylise", min=1e-6, soft_max=0.2)
    stylised_sh_degree: int = setting(
        0,
        "View-Dependent Colour",
        "Spherical-harmonic degree of restyled colours: 0 = the same from every side, "
        "1-3 also train view-dependent bands",
        "stylise",
        min=0,
        max=3,
    )
    lambda_style: float = setting(
        1.0,
        "Texture Strength",
        "How strongly the texture loss draws the photo's look into the result; 0 turns it off (with Lay Out Texture "
        "on: the laid-out texture alone, fitted to every view)",
        "stylise",
        min=0.0,
        soft_max=10.0,
    )
    texture_keeps_hue: bool = setting(
        False,
        "Texture Loss Keeps Hue",
        "The texture loss (and the content loss beside it) may only lighten or darken the splats, and each splat's "
        "red, green and blue change by one step size, so it sharpens the texture's pattern without painting hues "
        "of its own (pink and green patches on a dark capture); the hues come from the laid-out texture and the "
        "scene; off: it may change hue too, as the paper's does",
        "stylise",
    )
    hue_on_path: bool = setting(
        False,
        "No New Hues",
        "The run may lighten and darken each splat but move its hue only between the laid-out texture's and the "
        "capture's own, so it paints no hue that neither has (pink and green patches on a dark capture); needs "
        "Lay Out Texture",
        "stylise",
    )
    lambda_content: float = setting(
        0.005,
        "Content Strength",
        "How strongly the original appearance is kept (paper: 0.005 forward-facing, 0.0005 all-around scenes)",
        "stylise",
        min=0.0,
        soft_max=0.05,
    )
    lambda_tv: float = setting(
        0.02,
        "Smoothness",
        "How strongly neighbouring pixels of the result are evened out (total variation): higher calms speckle, "
        "lower keeps the finest grain",
        "stylise",
        min=0.0,
        soft_max=1.0,
    )
    color_transfer: bool = setting(
        True, "Colour Transfer", "Match the scene's colours to the texture's before and after", "stylise"
    )
    object_backdrop: bool = setting(
        False,
        "Object Backdrop",
        "Stylise the object over its own mean colour, not the background, so the texture "
        "does not trace its outline; the texture comes out weaker",
        "stylise",
    )
    stylise_geometry: Switch = setting(
        "auto",
        "Texture Moves Splats",
        "Let the texture loss move, scale and turn the splats too, as the paper's code does: bolder texture, "
        "looser shape. Auto: on for a capture seen from the front (every view within "
        f"{FORWARD_SPREAD_DEG:g}° of the views' mean direction), where near and far surfaces would carry "
        "the texture twice; off for an object seen from all sides, which keeps its outline",
        "stylise",
        choices=get_args(Switch),
    )
    densify: bool = setting(
        True,
        "Densify",
        "Add splats where the texture needs detail (split coarse ones, copy small ones). A copy helps only while "
        "Texture Moves Splats is on, so with it off none is made; with it off and Split Before Refining on, no "
        "splat is added at all",
        "stylise",
    )
    densify_every: int = setting(
        25,
        "Densify Every",
        "Stylisation steps between densification events",
        "stylise",
        unit="steps",
        min=1,
        soft_max=200,
    )
    densify_grad_threshold: float = setting(
        2e-4,
        "Densify Threshold",
        "Colour gradient that makes a splat split or clone",
        "stylise",
        min=0.0,
        soft_max=0.01,
    )
    densify_max_growth: float = setting(
        1.5,
        "Densify Growth Limit",
        "No densification once the splat count has grown by this factor",
        "stylise",
        min=1.0,
        soft_max=4.0,
    )
    prune_large: bool = setting(
        False,
        "Prune Large Splats",
        f"At each densification also remove splats wider than {PRUNE_SCREEN_RADIUS:g} px on screen or "
        f"{PRUNE_WORLD_SCALE:g} of the views' extent, as the authors' code does (off: only near-transparent ones)",
        "stylise",
    )
    seed: int = setting(0, "Seed", "Random seed of the run", "stylise", min=0)
    # -- GT²
    gt2: bool = setting(
        True,
        "GT² Loss",
        "Carry the texture's scale and orientation from view to view, so it lies the same way in every view (off: "
        "each view matches the texture on its own, the paper's NNFM baseline)",
        "gt2",
    )
    angle: float = setting(
        0.0,
        "Orientation",
        "Angle of the texture in the first view, counter-clockwise",
        "gt2",
        unit=DEGREES,
        min=-360.0,
        max=360.0,
    )
    lambda_prior: float = setting(
        0.002,
        "Orientation Prior",
        "Cost per degree of turning the texture away from the previous views' angle",
        "gt2",
        min=0.0,
        soft_max=100.0,
    )
    nnfm_half: bool = setting(
        False,
        "NNFM Half-Rounds",
        "Split every round into a GT² phase and a plain nearest-match phase (no orientation prior, no "
        "adaptive weights), each followed by its share of the preservation steps, as the authors' code does",
        "gt2",
    )
    # -- AFCM
    afcm: bool = setting(True, "Adaptive Control", "Weight the texture loss by depth, detail and distortion", "afcm")
    lambda_depth: float = setting(
        0.8, "Depth Weight", "How much less the texture counts on far surfaces", "afcm", min=0.0, max=1.0
    )
    lambda_frequency: float = setting(
        0.8, "Detail Weight", "How much less the texture counts on detailed areas", "afcm", min=0.0, max=1.0
    )
    lambda_distortion: float = setting(
        0.25,
        "Distortion Weight",
        "How much less the texture counts where it is seen at a grazing angle",
        "afcm",
        min=0.0,
        max=1.0,
    )
    # -- GPB
    gpb: bool = setting(
        True, "Geometry Preservation", "Alternate stylisation with phases that keep the geometry (off: faster)", "gpb"
    )
    rounds: int = setting(
        4, "Rounds", "Stylise/preserve alternations (the steps are split evenly)", "gpb", min=1, soft_max=20
    )
    correct_steps: int = setting(
        100, "Preservation Steps", "Geometry preservation steps in all", "gpb", unit="steps", min=0, soft_max=4000
    )
    lambda_scale: float = setting(
        0.1, "Scale Regulariser", "Weight of the penalty on needle-like splats", "gpb", min=0.0, soft_max=1.0
    )
    scale_ratio_limit: float = setting(
        10.0,
        "Needle Limit",
        "Largest/second splat scale ratio tolerated before it is penalised",
        "gpb",
        min=1.0,
        soft_max=100.0,
    )
    scale_ratio_from_start: bool = setting(
        True,
        "Keep Original Needles",
        "Tolerate each splat's own starting ratio if larger: only needles the stylisation makes are penalised",
        "gpb",
    )
    preview_every: int = setting(10, "Preview Every", "Steps between preview frames", "stylise", min=1, internal=True)

    def __post_init__(self) -> None:
        """Refuse a value outside its setting's choices or range (the settings' metadata), naming the setting."""
        for name, meta in SETTINGS.items():
            if (problem := meta.problem(getattr(self, name))) is not None:
                raise ValueError(f"{name} {problem}")
        if 0.0 < self.depth_ratio < 1.0:
            raise ValueError(f"depth_ratio must be 0 (measured from the views) or 1..16, got {self.depth_ratio}")

    def to_dict(self) -> dict[str, Any]:
        """Every setting by name (JSON-ready but for the background's tuple)."""
        return asdict(self)

    def with_overrides(self, **overrides: Any) -> TransferConfig:
        """A copy with the given fields changed (None values are ignored: 'not given'). A texture height given
        without a repeat count is the size used: it sets ``texture_repeats`` to 0, its "use the size" value."""
        unknown = set(overrides) - {f.name for f in fields(self)}
        if unknown:
            raise ValueError(f"unknown transfer settings: {', '.join(sorted(unknown))}")
        given = {k: v for k, v in overrides.items() if v is not None}
        if "texture_height" in given and "texture_repeats" not in given:
            given["texture_repeats"] = 0.0
        return replace(self, **given)


SETTINGS: dict[str, Setting] = {f.name: f.metadata["setting"] for f in fields(TransferConfig)}
"""Every setting's meaning, by field name."""


def user_settings(where: str | None = None) -> Iterator[tuple[str, Setting, type]]:
    """(name, setting, Python type) of the settings users set, in part order; ``where``: only those Blender
    offers there (IN_SCENE or IN_PREFERENCES)."""
    for part in PARTS:
        for name, meta in SETTINGS.items():
            if meta.part == part and not meta.internal and (where is None or meta.blender == where):
                yield name, meta, setting_type(name)


def setting_type(name: str) -> type:
    """The value type of setting ``name``: bool, int, float, str (a choice's words, a path) or tuple."""
    return value_type(_HINTS[name])


_HINTS = get_type_hints(TransferConfig)


def splits_first(config: TransferConfig) -> bool:
    """Whether the layout splits coarse splats to the texture's detail before the optimisation (Split Before
    Refining)."""
    return config.layout and config.split_first and config.split_size > 0


def splits_last(config: TransferConfig) -> bool:
    """Whether the layout splits them after the optimisation instead."""
    return config.layout and config.split_size > 0 and not config.split_first


def keeps_scene(config: TransferConfig) -> bool:
    """Whether the laid-out texture keeps anything of the scene under it (its light and dark, colour or brightness)."""
    return config.keep_scene > 0 or config.scene_colour > 0 or config.scene_brightness > 0
