"""The GT² settings of a scene (``scene.gt2gs``): what the sidebar edits and the transfer operator reads.

The transfer settings themselves are generated from their metadata (``blender/properties.py``);
this module adds what only the Blender front end has: the target, where the texture and the views
come from, the preset menu, the live orientation preview and where the result goes.
"""

from __future__ import annotations

import contextlib

import bpy
from bpy.props import BoolProperty, EnumProperty, PointerProperty, StringProperty

from ..blender import properties, splats, transfer_run
from ..core.transfer.presets import DEFAULT_PRESET, GPU_PRESETS, PRESET_HELP, PRESETS
from ..core.transfer.setting import IN_SCENE


def preset_item(name: str) -> tuple[str, str, str]:
    """The preset menu's entry for preset ``name``: GPU-only presets say so in their name and tooltip."""
    if name in GPU_PRESETS:
        return name, f"{name.replace('-', ' ').title()} (GPU)", f"Needs a CUDA GPU. {PRESET_HELP[name]}"
    return name, name.replace("-", " ").title(), PRESET_HELP[name]


PRESET_ITEMS = [preset_item(name) for name in PRESETS]
_applying_preset = False


def _is_splat(self, obj) -> bool:
    return splats.is_splat_object(obj)


PREVIEWED = (
    "angle",
    "texture_height",
    "layout",
    "layout_projection",
    "box_fits_faces",
    "keep_scene",
    "keep_material",
    "scene_colour",
    "keep_accents",
    "keep_hues",
    "scene_brightness",
    "shade_softness",
    "texture_softness",
    "texture_repeats",
    "texture_offset_right",
    "texture_offset_up",
    "split_size",
    "split_budget",
)
"""Settings the orientation preview shows: changing one re-renders it when the user asked for that."""


def _layout_changed(self, context) -> None:
    """Re-render the orientation preview when what it shows changes (PREVIEWED), if the user asked for it and there
    is a texture to show (the panel already says when there is none; a preview would only raise it again)."""
    if (
        self.auto_preview
        and not _applying_preset
        and transfer_run.texture_missing(self) is None
        and bpy.ops.gt2gs.preview_orientation.poll()
    ):
        with contextlib.suppress(RuntimeError):  # the operator has reported why it could not start (Info editor)
            bpy.ops.gt2gs.preview_orientation("INVOKE_DEFAULT")


def _preset_chosen(self, context) -> None:
    """Show the chosen preset's values in every setting."""
    global _applying_preset
    _applying_preset = True
    try:
        properties.apply_preset(self, self.preset)
    finally:
        _applying_preset = False


FRONT_END = {
    "target": PointerProperty(
        name="Target",
        type=bpy.types.Object,
        poll=_is_splat,
        description="The splat object to re-texture (empty: the active object)",
    ),
    "texture_source": EnumProperty(
        name="Texture",
        description="Where the texture comes from: a file on disk or an image of this Blender file",
        default="FILE",
        items=(("FILE", "File", "A texture photograph on disk"), ("IMAGE", "Image", "An image datablock of this file")),
    ),
    "texture_path": StringProperty(
        name="Texture File", subtype="FILE_PATH", description="The texture photograph to transfer"
    ),
    "texture_image": PointerProperty(
        name="Texture Image", type=bpy.types.Image, description="The image datablock to transfer"
    ),
    "view_source": EnumProperty(
        name="Views",
        description="The views the transfer looks at the object from (consecutive views should be neighbours)",
        default="AUTO",
        items=(
            ("AUTO", "Automatic", "Views generated around the object"),
            ("SCENE_CAMERAS", "Scene Cameras", "Every perspective camera of the scene, by name"),
            ("COLLECTION", "Camera Collection", "The cameras in a collection, by name"),
            ("CAMERAS_JSON", "cameras.json", "The cameras.json written by the 3DGS trainer"),
        ),
    ),
    "camera_collection": PointerProperty(
        name="Collection",
        type=bpy.types.Collection,
        description="The collection whose cameras are the views, in the order of their names",
    ),
    "cameras_json": StringProperty(
        name="cameras.json",
        subtype="FILE_PATH",
        description="cameras.json of the 3DGS scene (in the object's own space)",
    ),
    "preset": EnumProperty(
        name="Preset",
        items=PRESET_ITEMS,
        default=DEFAULT_PRESET,
        update=_preset_chosen,
        description="Sets every setting below to the preset's value",
    ),
    "auto_preview": BoolProperty(
        name="Live Orientation Preview",
        default=False,
        description="Re-render the orientation preview whenever something it shows changes: the angle, how the "
        "texture is laid (its size, placement, softness, projection), how much of the scene it keeps, how finely "
        "the splats are split, or which splats a run restyles",
    ),
    "result_mode": EnumProperty(
        name="Result",
        description="Where the re-textured splats go",
        default="NEW",
        items=(
            (
                "NEW",
                "New Object",
                "Add the re-textured splats as a new object in the original's place; the original "
                "is hidden (Alt+H shows it)",
            ),
            ("IN_PLACE", "In Place", "Replace the object's splats (undoable)"),
        ),
    ),
    "region_only": BoolProperty(
        name="Selected Points Only",
        default=False,
        description="Restyle only the points selected in Edit Mode",
        update=_layout_changed,
    ),
}
"""Properties of the Blender front end that are not transfer settings."""

GT2GS_PG_settings = type(
    "GT2GS_PG_settings",
    (bpy.types.PropertyGroup,),
    {
        "__doc__": "The scene's texture-transfer settings",
        "__annotations__": {
            **FRONT_END,
            **properties.annotations(IN_SCENE, dict.fromkeys(PREVIEWED, _layout_changed)),
        },
    },
)

classes = (GT2GS_PG_settings,)


def register() -> None:
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.gt2gs = PointerProperty(type=GT2GS_PG_settings)


def unregister() -> None:
    del bpy.types.Scene.gt2gs
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
