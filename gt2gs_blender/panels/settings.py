"""The GT² settings of a scene (``scene.gt2gs``): what the sidebar edits and the transfer operator reads."""
from __future__ import annotations

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty, StringProperty

from ..blender import splats
from ..core.transfer.config import PRESETS, TransferConfig

DEFAULTS = TransferConfig()


PRESET_ITEMS = [(name, name.title(), f"The {name} preset") for name in PRESETS]


def _is_splat(self, obj) -> bool:
    return splats.is_splat_object(obj)


def _layout_changed(self, context) -> None:
    """Re-render the orientation preview when the texture's angle or size changes, if the user asked for it."""
    if self.auto_preview and bpy.ops.gt2gs.preview_orientation.poll():
        bpy.ops.gt2gs.preview_orientation("INVOKE_DEFAULT")


class GT2GS_PG_settings(bpy.types.PropertyGroup):
    target: PointerProperty(
        name="Target", type=bpy.types.Object, poll=_is_splat,
        description="The splat object to re-texture (empty: the active object)")
    texture_source: EnumProperty(
        name="Texture", default="FILE",
        items=(("FILE", "File", "A texture photograph on disk"),
               ("IMAGE", "Image", "An image datablock of this file")))
    texture_path: StringProperty(name="Texture File", subtype="FILE_PATH",
                                 description="The texture photograph to transfer")
    texture_image: PointerProperty(name="Texture Image", type=bpy.types.Image,
                                   description="The image datablock to transfer")
    view_source: EnumProperty(
        name="Views", default="AUTO",
        items=(("AUTO", "Automatic", "Views generated around the object"),
               ("SCENE_CAMERAS", "Scene Cameras", "Every perspective camera of the scene, by name"),
               ("COLLECTION", "Camera Collection", "The cameras in a collection, by name"),
               ("CAMERAS_JSON", "cameras.json", "The cameras.json written by the 3DGS trainer")))
    n_views: IntProperty(name="View Count", default=0, min=0, soft_max=64,
                         description="Automatic views (0: the preset's count)")
    camera_collection: PointerProperty(name="Camera Collection", type=bpy.types.Collection)
    cameras_json: StringProperty(name="cameras.json", subtype="FILE_PATH",
                                 description="cameras.json of the 3DGS scene (in the object's own space)")
    preset: EnumProperty(name="Preset", items=PRESET_ITEMS, default="fast",
                         description="preview: seconds; fast: minutes on a CPU; balanced: more views and detail")
    angle: FloatProperty(name="Orientation", default=0.0, min=-180.0, max=180.0, precision=1,
                         description="Angle of the texture in the first view, degrees counter-clockwise",
                         update=_layout_changed)
    auto_preview: BoolProperty(name="Live Orientation Preview", default=False,
                               description="Re-render the orientation preview whenever the angle or the texture "
                                           "size changes")
    lambda_content: FloatProperty(
        name="Content Strength", default=DEFAULTS.lambda_content, min=0.0, soft_max=0.05, precision=4, step=0.01,
        description="How strongly the original appearance is kept (paper: 0.005 forward-facing, 0.0005 360°)")
    show_advanced: BoolProperty(name="Advanced", default=False)
    steps: IntProperty(name="Steps", default=0, min=0, soft_max=2000, description="Stylisation steps (0: preset)")
    resolution: IntProperty(name="Resolution", default=0, min=0, soft_max=1024,
                            description="Longest side of the working views in pixels (0: preset)")
    n_angles: IntProperty(name="Texture Rotations", default=0, min=0, max=360,
                          description="Rotations of the texture in the feature bank (0: preset)")
    texture_size: IntProperty(name="Texture Size", default=0, min=0, soft_max=1024,
                              description="Height of the texture on the nearest surfaces, in pixels of the view at "
                                          "half the working resolution, as the feature network sees it (0: preset, "
                                          "256; preview 128); smaller repeats the pattern more often. Preview "
                                          "Orientation shows it",
                              update=_layout_changed)
    seed: IntProperty(name="Seed", default=0, min=0)
    color_transfer: BoolProperty(name="Colour Transfer", default=True,
                                 description="Match the scene's colours to the texture's before and after")
    depth_groups: BoolProperty(name="Depth Groups", default=True,
                               description="Show the texture larger on near surfaces than on far ones")
    depth_ratio: FloatProperty(name="Depth Ratio", default=0.0, min=0.0, max=16.0,
                               description="How many times smaller the texture shows on the farthest surfaces than "
                                           "on the nearest (below 1: as perspective shows it, measured from the "
                                           "views, at most 2; the paper's code always uses 2)")
    object_backdrop: BoolProperty(name="Object Backdrop", default=False,
                                  description="Stylise the object over its own mean colour, not the background, "
                                              "so the texture does not trace its outline (dark rims; with Texture "
                                              "Moves Splats, halos of splats); the texture comes out weaker")
    gt2: BoolProperty(name="GT² Loss", default=True,
                      description="Carry the texture's orientation from view to view (off: plain NNFM matching)")
    afcm: BoolProperty(name="Adaptive Control", default=True,
                       description="Weight the texture loss by depth, detail and distortion (AFCM)")
    gpb: BoolProperty(name="Geometry Preservation", default=True,
                      description="Alternate stylisation with phases that keep the geometry (off: faster)")
    stylise_geometry: BoolProperty(name="Texture Moves Splats", default=False,
                                   description="Let the texture loss move, scale and turn splats too, as the paper's "
                                               "code does (always on in the paper presets): bolder texture, looser "
                                               "shape, which Geometry Preservation pulls back")
    densify: BoolProperty(name="Densify", default=True,
                          description="Add splats where the texture needs detail (off: the splat count stays)")
    device: EnumProperty(
        name="Device", default="DEFAULT",
        items=(("DEFAULT", "Default", "The device chosen in the preferences"),
               ("AUTO", "Auto", "CUDA when available, else CPU"),
               ("CPU", "CPU", "Run on the processor"), ("CUDA", "CUDA", "Run on an NVIDIA GPU")))
    result_mode: EnumProperty(
        name="Result", default="NEW",
        items=(("NEW", "New Object", "Add the re-textured splats as a new object beside the original"),
               ("IN_PLACE", "In Place", "Replace the object's splats (undoable)")))
    region_only: BoolProperty(name="Selected Points Only", default=False,
                              description="Restyle only the points selected in Edit Mode")


classes = (GT2GS_PG_settings,)


def register() -> None:
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.gt2gs = PointerProperty(type=GT2GS_PG_settings)


def unregister() -> None:
    del bpy.types.Scene.gt2gs
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
