"""What differs between the Blender versions the extension supports (4.5 LTS to 5.2 LTS), in one place.

Tried with bpy 4.5.15, 5.0.1, 5.1.2 and 5.2.3: 4.5 makes a material without its node tree until ``use_nodes`` is
set (always on, and deprecated, from 5.0), and its Remove Named Attribute node takes the pattern mode as a
property where 5.0 on take it as a menu input; from 5.2 a geometry-nodes modifier keeps its inputs under
``modifier.properties.inputs.<identifier>.value`` (``modifier[identifier]`` raises TypeError there, and a
driver needs that path), where 5.1 and earlier keep them as ID properties of the modifier; a mesh turned into a
point cloud brings its vertex selection along as ``.select_vert`` (4.5, 5.0) or, every point selected, as the
cloud's own ``.selection`` (5.1 on). (5.2's Random
Value node has one output where earlier ones have one per data type: ``display`` picks the output by name and
availability, which needs no check.)
"""

from __future__ import annotations

from typing import Any

import bpy

MODIFIER_PROPERTIES = bpy.app.version >= (5, 2, 0)
"""Geometry-nodes modifier inputs are RNA properties under ``modifier.properties.inputs`` (5.2 on)."""


CONVERTED_SELECTIONS = (".select_vert", ".selection")
"""Where a point cloud converted from a mesh keeps the mesh's vertex selection (4.5 and 5.0; 5.1 on)."""


def drop_converted_selection(cloud: bpy.types.PointCloud) -> None:
    """Remove the selection a mesh conversion left on ``cloud``: a new splat object has no points selected."""
    for name in CONVERTED_SELECTIONS:
        attribute = cloud.attributes.get(name)
        if attribute is not None:
            cloud.attributes.remove(attribute)


def use_nodes(material: bpy.types.Material) -> None:
    """Give a new material its node tree (4.5 needs ``use_nodes``; from 5.0 it is always on)."""
    if bpy.app.version < (5, 0, 0):
        material.use_nodes = True


def wildcard_removal() -> tuple[dict[str, str], dict[str, str]]:
    """(inputs, node properties) that make a Remove Named Attribute node take a wildcard pattern."""
    if bpy.app.version >= (5, 0, 0):
        return {"Pattern Mode": "Wildcard"}, {}
    return {}, {"pattern_mode": "WILDCARD"}


def modifier_input_path(modifier: bpy.types.NodesModifier, identifier: str) -> str:
    """The data path, from the object, of the modifier's group input ``identifier`` (for a driver)."""
    base = f'modifiers["{bpy.utils.escape_identifier(modifier.name)}"]'
    return f"{base}.properties.inputs.{identifier}.value" if MODIFIER_PROPERTIES else f'{base}["{identifier}"]'


def get_modifier_input(modifier: bpy.types.NodesModifier, identifier: str) -> Any:
    """The modifier's value of its group input ``identifier``."""
    if MODIFIER_PROPERTIES:
        return getattr(modifier.properties.inputs, identifier).value
    return modifier[identifier]


def set_modifier_input(modifier: bpy.types.NodesModifier, identifier: str, value: Any) -> None:
    """Set the modifier's group input ``identifier``; an unchanged value is not written again (a 5.2 window
    froze when an Object input was set to None while it already was)."""
    if get_modifier_input(modifier, identifier) == value:
        return
    if MODIFIER_PROPERTIES:
        getattr(modifier.properties.inputs, identifier).value = value
    else:
        modifier[identifier] = value
