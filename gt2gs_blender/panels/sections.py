"""The Texture Transfer panel's sub-panels in an artist's terms: Texture, Views, Quality, Advanced.

``SECTION_OF_PART`` is the one table from the settings' parts (``core/transfer/config.py``, which the
command line groups by) to these sub-panels; a new setting shows in its part's sub-panel by itself, and
a part the table does not know shows under Advanced. ``FRONT`` names the few settings a sub-panel shows
first, whatever their part (Texture: what an artist sets - the orientation, the repeats and how much of the
scene to keep; the texture part's other settings are under Advanced). Each sub-panel draws its own front-end
settings first, then every other scene setting of its parts. Where a setting's 0 (or ``auto``) means
"automatic", the value a run will actually use is shown under it (``effective_text``). ``draw`` only lays out
what functions return.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import Any

import bpy

from ..blender import machine, textures, transfer_run, views
from ..core.transfer.config import MAX_DEPTH_RATIO, SETTINGS, keeps_scene, user_settings
from ..core.transfer.setting import IN_SCENE, PARTS
from .sidebar import CATEGORY, LABEL_CHARS, text_lines

SECTIONS = ("Texture", "Views", "Quality", "Advanced")
SECTION_OF_PART = {
    "texture": "Advanced",
    "gt2": "Advanced",
    "views": "Views",
    "stylise": "Quality",
    "gpb": "Quality",
    "afcm": "Advanced",
    "speed": "Advanced",
    "machine": "Advanced",
}
"""Which sub-panel shows the settings of each part of the method."""
FRONT = {
    "Texture": (
        "angle",
        "texture_repeats",
        "texture_offset_right",
        "texture_offset_up",
        "texture_softness",
        "keep_scene",
        "keep_material",
        "scene_colour",
        "keep_accents",
        "keep_hues",
        "scene_brightness",
    ),
    "Views": ("n_views", "view_kind"),
    "Quality": ("lambda_content",),
}
"""Settings a sub-panel shows first, beside its own front-end properties (those the config has)."""
OPEN = ("Texture", "Views")
"""Sub-panels open in a new file; the others start closed."""

AUTOMATIC: dict[str, Callable[[dict[str, Any]], str]] = {
    "depth_ratio": lambda info: f"measured from the views, at most {MAX_DEPTH_RATIO:g}×",
    "match_channels": lambda info: "all channels of the feature network",
    "dedup_threshold": lambda info: "every texture bank entry kept",
    "plateau_window": lambda info: "every step of every phase",
    "threads": lambda info: f"{info['threads']} (one per physical core)" if "threads" in info else "one per core",
}
"""What a run uses for each setting whose 0 means automatic; a new such setting shows its help's words."""
FROM_FRONT: dict[str, tuple[str, str]] = {
    "layout_projection": ("View", "Box"),
    "stylise_geometry": ("On", "Off"),
}
"""What the settings whose ``auto`` follows the views take when the views all look from the front, and not."""
_ZERO_MEANS = re.compile(r"\b0(?: =|:) ([^;)]+)")


def section_of(part: str) -> str:
    """The sub-panel that shows the settings of ``part``."""
    return SECTION_OF_PART.get(part, "Advanced")


def front_settings(section: str) -> list[str]:
    """The settings ``section`` shows first, in order (a name the config lacks is left out)."""
    return [name for name in FRONT.get(section, ()) if name in SETTINGS]


def section_settings(section: str) -> list[tuple[str, list[str]]]:
    """(part, setting names) of the scene settings ``section`` lists after its front settings, in part order
    (a setting some sub-panel shows first is not listed again)."""
    fronts = {name for shown in SECTIONS for name in front_settings(shown)}
    grouped: dict[str, list[str]] = {}
    for name, meta, _ in user_settings(IN_SCENE):
        if section_of(meta.part) == section and name not in fronts:
            grouped.setdefault(meta.part, []).append(name)
    return list(grouped.items())


def effective_text(name: str, value: Any, info: dict[str, Any] | None = None) -> str | None:
    """What a run will use for setting ``name`` at ``value`` when that value means automatic (0, or ``auto``),
    else None; ``info``: what the machine check found (e.g. the thread count) and ``front``, whether the
    views all look from the front (None: no views yet)."""
    meta = SETTINGS.get(name)
    if name in FROM_FRONT and value == "auto":
        front = (info or {}).get("front")
        if front is None:
            return None
        on, off = FROM_FRONT[name]
        return f"Uses {on}: the views all look from the front" if front else f"Uses {off}: the views surround it"
    if meta is None or isinstance(value, bool) or value != 0:
        return None
    if name in AUTOMATIC:
        return f"Uses {AUTOMATIC[name](info or {})}"
    found = _ZERO_MEANS.search(meta.help)
    return f"At 0: {found.group(1).strip()}" if found else None


USED_WHEN: dict[str, Callable[[Any], bool]] = {
    "texture_height": lambda s: s.texture_repeats == 0,
    "layout_projection": lambda s: s.layout,
    "box_fits_faces": lambda s: s.layout and s.layout_projection != "view",
    "keep_scene": lambda s: s.layout,
    "scene_colour": lambda s: s.layout,
    "keep_accents": lambda s: s.layout and s.scene_colour < 1 and keeps_scene(s),  # raises what is kept
    "keep_hues": lambda s: s.layout and s.scene_colour < 1 and keeps_scene(s),  # tints what is kept
    "scene_brightness": lambda s: s.layout,
    "keep_material": lambda s: s.layout and (s.keep_scene > 0 or s.scene_brightness > 0),  # the shade, the exposure
    "shade_softness": lambda s: s.layout and (s.keep_scene > 0 or s.scene_colour > 0),  # what it averages
    "split_size": lambda s: s.layout,
    "split_first": lambda s: s.layout and s.split_size > 0,
    "split_budget": lambda s: s.layout and s.split_size > 0,
    "lambda_layout": lambda s: s.layout,
}
"""Settings a run uses only when another one allows it: greyed out otherwise, as Blender does."""


def setting_used(owner: Any, name: str) -> bool:
    """Whether a run with ``owner``'s settings uses setting ``name``."""
    return name not in USED_WHEN or bool(USED_WHEN[name](owner))


def draw_setting(layout, owner, name: str, info: dict[str, Any] | None) -> None:
    """A setting's property (greyed out when the run ignores it), with the value a run will use under it
    when it is automatic; a label too long for the label column gets the row's whole width (a checkbox) or a
    row of its own above the value."""
    column = layout.column()
    column.active = setting_used(owner, name)
    prop = owner.bl_rna.properties[name]
    if len(prop.name) <= LABEL_CHARS:
        column.prop(owner, name)
    elif prop.type == "BOOLEAN":
        row = column.row()
        row.use_property_split = False
        row.prop(owner, name)
    else:
        column.label(text=prop.name)
        column.prop(owner, name, text="")
    text = effective_text(name, getattr(owner, name), info)
    if text:
        text_lines(layout, text, icon="INFO")


def _draw_texture_front(layout, context) -> None:
    """Texture: where it comes from, its thumbnail, the angle with the orientation preview of the first view."""
    settings = context.scene.gt2gs
    layout.prop(settings, "texture_source", expand=True)
    layout.prop(settings, "texture_path" if settings.texture_source == "FILE" else "texture_image")
    preview = textures.thumbnail(settings)
    if preview is not None:
        layout.template_icon(icon_value=preview.icon_id, scale=5.0)
    row = layout.row(align=True)
    row.prop(settings, "angle")
    row.prop(settings, "auto_preview", text="", icon="FILE_REFRESH")
    for name in front_settings("Texture")[1:]:
        draw_setting(layout, settings, name, machine.current().info)
    layout.operator("gt2gs.preview_orientation", icon="ORIENTATION_GIMBAL")
    icon = transfer_run.preview_icon()
    if icon:
        layout.template_icon(icon_value=icon, scale=10.0)
        layout.label(text=transfer_run.preview_caption(), icon="CAMERA_DATA")
        splats = transfer_run.preview_splats_text()
        if splats:
            layout.label(text=splats, icon="POINTCLOUD_DATA")
        views = transfer_run.preview_views_text()
        if views:
            text_lines(layout, views, icon="VIEW_CAMERA")


def _draw_views_front(layout, context) -> None:
    """Views: where they come from (the view count and where they stand only for automatic views)."""
    settings = context.scene.gt2gs
    layout.prop(settings, "view_source")
    if settings.view_source == "AUTO":
        layout.prop(settings, "n_views")
        layout.prop(settings, "view_kind")
    elif settings.view_source == "COLLECTION":
        layout.prop(settings, "camera_collection")
    elif settings.view_source == "CAMERAS_JSON":
        layout.prop(settings, "cameras_json")


def _draw_quality_front(layout, context) -> None:
    """Quality: how much of the scene's content the loss keeps."""
    for name in front_settings("Quality"):
        draw_setting(layout, context.scene.gt2gs, name, machine.current().info)


FRONT_DRAW = {"Texture": _draw_texture_front, "Views": _draw_views_front, "Quality": _draw_quality_front}


def section_panel(section: str) -> type:
    """The sub-panel of ``section``: its front settings, then its parts' settings under their part's name."""
    groups = section_settings(section)
    front = FRONT_DRAW.get(section)

    def draw(self, context) -> None:
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        if front is not None:
            front(layout, context)
        info = {**(machine.current().info or {}), "front": views.views_from_front(context.scene.gt2gs, context.scene)}
        for part, names in groups:
            column = layout.column()
            heading = PARTS.get(part, part.title())
            if len(groups) > 1 or (front is not None and heading != section):  # no "Views" inside Views
                column.separator()
                column.label(text=heading)
            for name in names:
                draw_setting(column, context.scene.gt2gs, name, info)

    return type(
        f"VIEW3D_PT_gt2gs_{section.lower()}",
        (bpy.types.Panel,),
        {
            "bl_space_type": "VIEW_3D",
            "bl_region_type": "UI",
            "bl_category": CATEGORY,
            "bl_label": section,
            "bl_parent_id": "VIEW3D_PT_gt2gs_transfer",
            "bl_options": set() if section in OPEN else {"DEFAULT_CLOSED"},
            "draw": draw,
            "__doc__": f"The {section} settings of the texture transfer",
        },
    )


classes = tuple(section_panel(section) for section in SECTIONS)


def register() -> None:
    for cls in classes:
        bpy.utils.register_class(cls)


def unregister() -> None:
    textures.release_thumbnails()
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
