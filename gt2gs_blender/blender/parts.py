"""A splat object's parts (``core.scene.parts``) in Blender: each point's part in a hidden point attribute, the list
the sidebar shows (``scene.gt2gs_parts``), the object and point count they were found for, and a part's points
selected as Edit Mode's selection (or the points selected there grown to
their whole parts), the region a run restyles with Selected Points Only.

The functions take the scene's parts list (``store``: ``items`` of part / splats / colour, ``object``,
``point_count``) and the object; the operators and the sidebar only call them.
"""

from __future__ import annotations

import bpy
import numpy as np

from ..core.scene.parts import find_parts_in
from . import splats, transfer_run
from .transfer_run import SELECTION_ATTRIBUTE, RunError

LABEL_ATTRIBUTE = ".gt2gs_part"
"""Each point's part (INT, POINT domain); the leading dot keeps it out of exported files."""


def find(obj: bpy.types.Object, store: bpy.types.PropertyGroup) -> int:
    """Find ``obj``'s parts, label its points and list the parts in ``store``; the number of parts."""
    scene, _ = splats.object_to_scene(obj)
    parts = find_parts_in(scene)
    attributes = obj.data.attributes
    old = attributes.get(LABEL_ATTRIBUTE)
    if old is not None:
        attributes.remove(old)
    attributes.new(LABEL_ATTRIBUTE, "INT", "POINT").data.foreach_set("value", parts.labels.astype(np.int32))
    store.items.clear()
    for part, (size, colour) in enumerate(zip(parts.sizes, splats.srgb_to_linear(parts.colours), strict=True)):
        item = store.items.add()
        item.part, item.splats, item.colour = part, int(size), tuple(float(c) for c in colour)
    store.object, store.point_count, store.active = obj, len(obj.data.points), 0
    return len(parts)


def stale_text(store: bpy.types.PropertyGroup, obj: bpy.types.Object) -> str | None:
    """Why the listed parts are not those of ``obj`` (the run's object) any more, or None when they are (or none
    are listed)."""
    if not store.items:
        return None
    found = store.object
    if found is None:
        return "Found for an object that is gone: Find Parts again"
    if obj is None or found.name != obj.name:
        return f"Found for {found.name!r}, not this object: Find Parts again"
    if len(obj.data.points) != store.point_count or obj.data.attributes.get(LABEL_ATTRIBUTE) is None:
        return "The object changed since: Find Parts again"
    return None


def select(obj: bpy.types.Object, store: bpy.types.PropertyGroup, part: int, extend: bool = False) -> list[int]:
    """Select exactly the points of ``part`` of ``obj`` (Edit Mode's selection), or add them to it (``extend``);
    the parts now selected whole. RunError when the listed parts are stale or there is no such part."""
    labels = _labels(obj, store)
    if not 0 <= part < len(store.items):
        raise RunError(f"there is no part {part}: the object has parts 0 to {len(store.items) - 1}")
    chosen = labels == part
    current = transfer_run.selection_mask(obj) if extend else None
    if current is not None:
        chosen |= current
    _set_selection(obj, chosen)
    return [p for p in range(len(store.items)) if chosen[labels == p].all() and (labels == p).any()]


def grow(obj: bpy.types.Object, store: bpy.types.PropertyGroup) -> list[int]:
    """Grow the points selected in Edit Mode to the whole parts they belong to (a click on a splat picks its part);
    the parts now selected. RunError when the listed parts are stale or no point is selected."""
    labels = _labels(obj, store)
    chosen = np.unique(labels[transfer_run.selected_points(obj)])
    _set_selection(obj, np.isin(labels, chosen))
    return [int(p) for p in chosen]


def _labels(obj: bpy.types.Object, store: bpy.types.PropertyGroup) -> np.ndarray:
    """(N,) each point's part; RunError when there are no parts or they are stale."""
    problem = stale_text(store, obj) if store.items else "No parts yet: Find Parts first"
    if problem:
        raise RunError(problem)
    labels = np.empty(len(obj.data.points), np.int32)
    obj.data.attributes[LABEL_ATTRIBUTE].data.foreach_get("value", labels)
    return labels


def _set_selection(obj: bpy.types.Object, chosen: np.ndarray) -> None:
    """Make ``chosen`` (N,) bool Edit Mode's point selection."""
    attributes = obj.data.attributes
    selection = attributes.get(SELECTION_ATTRIBUTE)
    if selection is not None and selection.domain != "POINT":
        attributes.remove(selection)
        selection = None
    if selection is None:
        selection = attributes.new(SELECTION_ATTRIBUTE, "BOOLEAN", "POINT")
    selection.data.foreach_set("value", chosen if selection.data_type == "BOOLEAN" else chosen.astype(np.float32))
    obj.data.update_tag()
