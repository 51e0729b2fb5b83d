"""Gaussian scenes (core ``SplatArrays``, numpy) as Blender point-cloud objects, and back.

One point per Gaussian. Every PLY vertex property is a POINT attribute named as in the file (INRIA
names: ``f_dc_0``, ``f_rest_*``, ``opacity``, ``scale_*``, ``rot_*``, normals, extras); x, y, z are
the point positions. Float properties become FLOAT attributes, integer ones INT attributes (uint32
keeps its bits). Blender-owned names (``position``, ``radius``, the colour attribute, names starting
with ".") cannot hold a PLY property; such a property is stored as ``ply:<name>`` and mapped back on
export. Two display attributes are added and never exported:

- ``Col`` (FLOAT_COLOR): the DC colour 0.5 + C0·f_dc, clamped to [0, 1] and converted from sRGB to
  scene-linear (Blender's convention for float colours), alpha = sigmoid(opacity);
- ``radius``: the point-cloud sphere radius, the radius of the disc with the area of the splat's
  1σ ellipse across its two largest axes, clamped to 5% of the scene's extent against floaters.

The source layout (property order and types), file format and path are kept as JSON in the custom
property ``gt2gs_ply`` of the PointCloud data, so an unchanged object exports byte for byte. The path
(a transfer's result keeps its original's) is the file Export refuses to overwrite.

The PLY is in the object's local space; exporting may bake the object's world transform.
Nothing here loops over points in Python.
"""

from __future__ import annotations

import contextlib
import json
from dataclasses import dataclass

import bpy
import numpy as np

from ..core.scene import inria
from ..core.scene.arrays import SplatArrays
from ..core.scene.inria import POSITION_NAMES, REST_PREFIX, SH_C0, core_groups, core_property_names, tensor_view
from ..core.scene.ply_header import SCALAR_TYPES, TYPE_FOR_CODE, type_code
from ..core.scene.ply_write import write_layout
from . import compat, display, transform

COLOR_ATTRIBUTE = "Col"
RADIUS_ATTRIBUTE = "radius"
POSITION_ATTRIBUTE = "position"
META_KEY = "gt2gs_ply"
MATERIAL_NAME = "GT² Splats"
MATERIAL_TAG = "gt2gs_splat_material"
RENAME_PREFIX = "ply:"
MAX_ATTRIBUTE_NAME = 63
"""Longest attribute name (bytes) Blender keeps without truncating."""
RADIUS_MAX_FRACTION = 0.05
"""Largest display radius as a fraction of the scene's (1%-99% quantile) bounding-box diagonal."""

REQUIRED = tuple(name for name in inria.REQUIRED if name not in POSITION_NAMES)
"""Point attributes (besides positions) that make a point cloud a splat object."""
RESERVED = frozenset({POSITION_ATTRIBUTE, RADIUS_ATTRIBUTE, COLOR_ATTRIBUTE})

_FLOAT_CODES = {code for code in TYPE_FOR_CODE if code[0] == "f"}
_INT_CODES = set(TYPE_FOR_CODE) - _FLOAT_CODES


class SplatObjectError(ValueError):
    """An object cannot be read back as Gaussians; the message is meant for the user."""


# -- naming -------------------------------------------------------------------------------------------


def attribute_name_for(prop: str) -> str:
    """The point attribute that holds PLY property ``prop``."""
    if prop in RESERVED or prop.startswith(".") or prop.startswith(RENAME_PREFIX):
        return RENAME_PREFIX + prop
    return prop


# -- SplatArrays -> object -----------------------------------------------------------------------------


def scene_to_object(
    scene: SplatArrays,
    name: str,
    collection: bpy.types.Collection,
    *,
    source_path: str | None = None,
    source_format: str | None = None,
    with_material: bool = True,
    with_display: bool = True,
) -> bpy.types.Object:
    """A new point-cloud object for ``scene`` (core ``SplatArrays``), linked into ``collection``.

    Needs a context with a scene and view layer (Blender converts mesh -> point cloud with its
    operator). ``with_display`` adds the Gaussian display modifier (``display.apply_display``); it draws
    from the attributes and adds none to the point cloud. On failure nothing is left behind.
    """
    columns, layout = _scene_columns(scene)
    for prop in columns:
        attr = attribute_name_for(prop)
        if len(attr.encode("utf-8")) > MAX_ATTRIBUTE_NAME:
            raise SplatObjectError(
                f"PLY property name {prop!r} is longer than Blender's attribute names ({MAX_ATTRIBUTE_NAME} bytes)"
            )
    n = len(scene)
    created: list[bpy.types.ID] = []
    try:
        mesh = bpy.data.meshes.new(name)
        created.append(mesh)
        mesh.vertices.add(n)
        mesh.vertices.foreach_set("co", np.ascontiguousarray(scene.means, np.float32).ravel())
        for prop, values in columns.items():
            kind = "INT" if values.dtype == np.int32 else "FLOAT"
            attr = mesh.attributes.new(attribute_name_for(prop), kind, "POINT")
            attr.data.foreach_set("value", values)
        colors = splat_colors(scene.sh_dc, scene.opacity_logits)
        mesh.attributes.new(COLOR_ATTRIBUTE, "FLOAT_COLOR", "POINT").data.foreach_set("color", colors.ravel())
        radii = display_radii(scene.log_scales, scene.means)
        mesh.attributes.new(RADIUS_ATTRIBUTE, "FLOAT", "POINT").data.foreach_set("value", radii)

        obj = bpy.data.objects.new(name, mesh)
        created.append(obj)
        obj.color = object_colour(colors)
        # Convert in the scene's own collection, which is always in the view layer and visible, then
        # move the object to its collection (which may be hidden or excluded).
        master = bpy.context.scene.collection
        master.objects.link(obj)
        _convert_to_point_cloud(obj)
        if collection != master:
            collection.objects.link(obj)
            master.objects.unlink(obj)
        cloud = obj.data
        created.append(cloud)
        compat.drop_converted_selection(cloud)
        created.remove(mesh)
        with contextlib.suppress(ReferenceError):  # the conversion may already have freed it
            bpy.data.meshes.remove(mesh)  # left without users by the conversion
        if cloud.name != name:
            cloud.name = name
        set_meta(cloud, layout=layout, fmt=source_format, source=source_path)
        if with_material:
            material, made = ensure_material()
            if made:
                created.append(material)
            cloud.materials.append(material)
        if with_display:
            display.apply_display(obj)
        return obj
    except BaseException:
        _remove_ids(created)
        raise


def _scene_columns(scene: SplatArrays) -> tuple[dict[str, np.ndarray], tuple[tuple[str, str], ...]]:
    """PLY property -> contiguous 1-D attribute values (float32 or int32) in file order, positions left
    out; and the layout (property, PLY type) that core's ``write_ply`` would write for ``scene``."""
    try:
        layout = write_layout(scene)
    except ValueError as exc:  # extras PLY cannot hold
        raise SplatObjectError(str(exc)) from None
    values = {**_parameter_columns(scene), **{p: _attribute_values(np.asarray(v)) for p, v in scene.extras.items()}}
    return {prop: values[prop] for prop, _ in layout if prop not in POSITION_NAMES}, layout


def _parameter_columns(scene: SplatArrays) -> dict[str, np.ndarray]:
    """The Gaussian parameters but the positions as PLY property -> contiguous float32 row."""
    columns: dict[str, np.ndarray] = {}
    for key, names in core_groups(int(scene.sh_rest.shape[1])).items():
        if key != "means":
            rows = np.empty((len(names), len(scene)), np.float32)
            np.copyto(tensor_view(key, rows.T), scene.tensors()[key])
            columns.update(zip(names, rows))
    return columns


def _attribute_values(values: np.ndarray) -> np.ndarray:
    """A PLY property's values as a Blender attribute holds them: float32, or int32 (uint32 bit for bit)."""
    code = type_code(values.dtype)
    if code in _FLOAT_CODES:
        return np.ascontiguousarray(values, np.float32)
    if code == "u4":
        return np.ascontiguousarray(values.astype(np.uint32, copy=False)).view(np.int32)  # keep the bits
    if code in _INT_CODES:
        return np.ascontiguousarray(values, np.int32)
    raise SplatObjectError(f"cannot store a property of type {values.dtype} as a Blender attribute")


def splat_colors(sh_dc: np.ndarray, opacity_logits: np.ndarray) -> np.ndarray:
    """(N,4) float32 scene-linear RGBA: sRGB DC colour clamped to [0,1] -> linear, alpha = sigmoid(opacity)."""
    srgb = np.clip(0.5 + SH_C0 * sh_dc.astype(np.float32), 0.0, 1.0)
    rgba = np.empty((len(srgb), 4), np.float32)
    rgba[:, :3] = srgb_to_linear(srgb)
    with np.errstate(over="ignore"):
        rgba[:, 3] = 1.0 / (1.0 + np.exp(-opacity_logits.astype(np.float32).reshape(-1)))
    return rgba


def srgb_to_linear(srgb: np.ndarray) -> np.ndarray:
    """sRGB values in [0, 1] as scene-linear (Blender's float colours and colour properties)."""
    return np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)


def object_colour(colors: np.ndarray) -> tuple[float, float, float, float]:
    """The object's viewport colour: the opacity-weighted mean of its splats' (N,4) linear RGBA, opaque; what
    Solid mode's Object colour shows (it cannot read per-splat colours from the display's generated quads)."""
    weights = colors[:, 3].astype(np.float64)
    total = float(weights.sum())
    if not np.isfinite(total) or total <= 0.0:
        return (0.8, 0.8, 0.8, 1.0)
    mean = (colors[:, :3].astype(np.float64) * weights[:, None]).sum(0) / total
    return (*(float(c) for c in np.clip(mean, 0.0, 1.0)), 1.0)


def display_radii(log_scales: np.ndarray, means: np.ndarray) -> np.ndarray:
    """Sphere radius per splat: sqrt of the two largest 1σ scales' product, clamped against floaters."""
    n = len(log_scales)
    if n == 0:
        return np.empty(0, np.float32)
    top_two = np.sort(log_scales.astype(np.float32), axis=1)[:, 1:]
    radii = np.exp(top_two.mean(axis=1))
    if n >= 2:
        lo, hi = np.quantile(means, [0.01, 0.99], axis=0)
        diagonal = float(np.linalg.norm(hi - lo))
    else:
        diagonal = 0.0
    upper = RADIUS_MAX_FRACTION * diagonal if diagonal > 0 else 1.0
    return np.ascontiguousarray(np.clip(np.nan_to_num(radii, nan=0.0, posinf=upper), 0.0, upper), np.float32)


def _convert_to_point_cloud(obj: bpy.types.Object) -> None:
    """Mesh object -> point-cloud object in place (bpy cannot size a PointCloud before Blender 5.1)."""
    with bpy.context.temp_override(
        active_object=obj, object=obj, selected_objects=[obj], selected_editable_objects=[obj]
    ):
        result = bpy.ops.object.convert(target="POINTCLOUD")
    if result != {"FINISHED"} or obj.type != "POINTCLOUD":
        raise SplatObjectError(f"Blender could not convert the mesh to a point cloud ({result})")


# -- material -------------------------------------------------------------------------------------------


def find_material() -> bpy.types.Material | None:
    """The shared splat material of this file, if there is one."""
    for material in bpy.data.materials:
        if material.get(MATERIAL_TAG) and material.node_tree is not None and material.library is None:
            return material
    return None


def ensure_material() -> tuple[bpy.types.Material, bool]:
    """The shared splat material (emission from the colour attribute, alpha from opacity); made if absent."""
    material = find_material()
    if material is not None:
        return material, False
    material = bpy.data.materials.new(MATERIAL_NAME)
    try:
        material[MATERIAL_TAG] = True
        compat.use_nodes(material)
        nodes, links = material.node_tree.nodes, material.node_tree.links
        nodes.clear()
        attribute = nodes.new("ShaderNodeAttribute")
        attribute.attribute_type = "GEOMETRY"
        attribute.attribute_name = COLOR_ATTRIBUTE
        attribute.location = (-600, 0)
        emission = nodes.new("ShaderNodeEmission")
        emission.inputs["Strength"].default_value = 1.0
        emission.location = (-300, -100)
        transparent = nodes.new("ShaderNodeBsdfTransparent")
        transparent.location = (-300, 100)
        mix = nodes.new("ShaderNodeMixShader")
        mix.location = (0, 0)
        output = nodes.new("ShaderNodeOutputMaterial")
        output.location = (250, 0)
        links.new(attribute.outputs["Color"], emission.inputs["Color"])
        links.new(attribute.outputs["Alpha"], mix.inputs["Fac"])
        links.new(transparent.outputs["BSDF"], mix.inputs[1])
        links.new(emission.outputs["Emission"], mix.inputs[2])
        links.new(mix.outputs["Shader"], output.inputs["Surface"])
        material.diffuse_color = (0.8, 0.8, 0.8, 1.0)
    except BaseException:
        bpy.data.materials.remove(material)
        raise
    return material, True


# -- object -> SplatArrays -------------------------------------------------------------------------------


@dataclass(frozen=True)
class SplatSummary:
    """What the sidebar shows about a splat object."""

    name: str
    count: int
    sh_degree: int
    extras: tuple[str, ...]
    source: str | None
    format: str | None


def is_splat_object(obj) -> bool:
    """A point-cloud object with the Gaussian attributes (however it was made)."""
    if obj is None or obj.type != "POINTCLOUD" or obj.data is None:
        return False
    attributes = obj.data.attributes
    return all(_point_attribute(attributes, name) is not None for name in REQUIRED)


def splat_summary(obj) -> SplatSummary | None:
    """Count, SH degree, extras and source of a splat object; None for anything else. Cheap (no data read)."""
    if not is_splat_object(obj):
        return None
    cloud = obj.data
    meta = get_meta(cloud)
    k = _rest_per_channel(cloud.attributes)
    degree = inria.sh_degree_from_rest(k) if k is not None else -1
    extras = tuple(prop for prop, _ in _export_properties(cloud, meta, k or 0)[2])
    return SplatSummary(
        name=obj.name,
        count=len(cloud.points),
        sh_degree=degree,
        extras=extras,
        source=meta.get("source"),
        format=meta.get("format"),
    )


def object_to_scene(obj, *, bake_transform: bool = False) -> tuple[SplatArrays, list[str]]:
    """The object's Gaussians as core ``SplatArrays`` (numpy; no torch needed), and notes for the user.

    With ``bake_transform`` the object's world matrix is baked into the Gaussians (see ``transform``);
    otherwise they stay in the object's local space, exactly as stored, and a note says so when the object was
    moved, turned or scaled in Blender (the file would not show it where the scene does).
    """
    if not is_splat_object(obj):
        raise SplatObjectError(
            f"{obj.name if obj else 'None'!r} is not a Gaussian splat point cloud "
            f"(needs the attributes {', '.join(REQUIRED)})"
        )
    cloud = obj.data
    k = _rest_per_channel(cloud.attributes)
    if k is None:
        raise SplatObjectError(
            f"{obj.name!r}: the f_rest_* attributes do not form an SH degree 0-3 set "
            "(expected f_rest_0 .. f_rest_<n-1> with n = 0, 9, 24 or 45)"
        )
    layout, notes, extras_props = _export_properties(cloud, get_meta(cloud), k)
    n = len(cloud.points)
    scene = SplatArrays(
        **_read_parameters(cloud, k),
        extras={prop: _read_extra(cloud.attributes, prop, code, n) for prop, code in extras_props},
        ply_layout=tuple((p, t) for p, t in layout) if layout is not None else None,
    )
    if bake_transform:
        scene, baked_notes = _bake_world_matrix(obj, scene)
        notes.extend(baked_notes)
    elif not transform.is_identity(np.array(obj.matrix_world, np.float64)):
        notes.append(
            f"{obj.name!r} is moved, turned or scaled in Blender, which the file does not keep: its splats are "
            "written where the file had them (tick Apply Object Transform to bake the transform in)"
        )
    return scene, notes


def _read_parameters(cloud, k: int) -> dict[str, np.ndarray]:
    """The Gaussian parameters of a splat point cloud by ``SplatArrays`` field (contiguous float32)."""
    n = len(cloud.points)
    means = np.empty(n * 3, np.float32)
    if n:  # an empty point cloud has no position attribute
        cloud.attributes[POSITION_ATTRIBUTE].data.foreach_get("vector", means)
    fields = {"means": means.reshape(n, 3)}
    for key, names in core_groups(k).items():
        if key != "means":
            fields[key] = np.ascontiguousarray(tensor_view(key, _read_rows(cloud.attributes, names, n).T))
    return fields


def _read_rows(attributes, names: list[str], n: int) -> np.ndarray:
    """(len(names), n) float32: one row per PLY property, read from its point attribute (FLOAT or INT)."""
    out = np.empty((len(names), n), np.float32)
    for row, prop in zip(out, names, strict=True):
        attr = _point_attribute(attributes, attribute_name_for(prop))
        if attr.data_type == "FLOAT":
            attr.data.foreach_get("value", row)
        else:
            raw = np.empty(n, np.int32)
            attr.data.foreach_get("value", raw)
            row[:] = raw
    return out


def _bake_world_matrix(obj, scene: SplatArrays) -> tuple[SplatArrays, list[str]]:
    """``scene`` with the object's world matrix baked in (as it is for the identity), and notes for the user."""
    matrix = np.array(obj.matrix_world, np.float64)
    if transform.is_identity(matrix):
        return scene, []
    try:
        return transform.bake(scene, matrix)
    except transform.TransformError as exc:
        raise SplatObjectError(f"{obj.name!r}: {exc}") from None


def _export_properties(cloud, meta: dict, k: int) -> tuple[list | None, list[str], list[tuple[str, str]]]:
    """(layout or None, notes, [(extra property, numpy type code)]) for what an export would write."""
    attributes = cloud.attributes
    core = set(core_property_names(k))
    notes: list[str] = []
    layout = meta.get("layout")
    extras: list[tuple[str, str]] = []
    listed: set[str] = set()
    if layout is not None:
        for prop, ply_type in layout:
            listed.add(prop)
            if prop in core or prop.startswith(REST_PREFIX):
                continue
            attr = _point_attribute(attributes, attribute_name_for(prop))
            if attr is None or attr.data_type not in ("FLOAT", "INT"):
                notes.append(f"property {prop!r} of the source file has no attribute any more; not written")
                continue
            code = SCALAR_TYPES.get(ply_type, "f4")
            if (code in _FLOAT_CODES) != (attr.data_type == "FLOAT"):
                code = "f4" if attr.data_type == "FLOAT" else "i4"
            extras.append((prop, code))
    for attr in attributes:
        name = attr.name
        if attr.domain != "POINT" or attr.data_type not in ("FLOAT", "INT") or name.startswith(".") or name in RESERVED:
            continue
        prop = name[len(RENAME_PREFIX) :] if name.startswith(RENAME_PREFIX) else name
        if prop in listed or prop in core or prop.startswith(REST_PREFIX):
            continue
        extras.append((prop, "f4" if attr.data_type == "FLOAT" else "i4"))
    return layout, notes, extras


def _read_extra(attributes, prop: str, code: str, n: int) -> np.ndarray:
    """An extra property's values from its attribute, as numpy type ``code`` (ints clipped to its range)."""
    attr = _point_attribute(attributes, attribute_name_for(prop))
    if attr.data_type == "FLOAT":
        values = np.empty(n, np.float32)
        attr.data.foreach_get("value", values)
        return values.astype(code, copy=False)
    values = np.empty(n, np.int32)
    attr.data.foreach_get("value", values)
    if code == "u4":
        return values.view(np.uint32).copy()
    info = np.iinfo(code)
    return np.clip(values, info.min, info.max).astype(code)


def _rest_per_channel(attributes) -> int | None:
    """K (f_rest per channel) from the f_rest_* attributes; None if they are not a full SH set."""
    return inria.rest_per_channel(
        a.name for a in attributes if a.name.startswith(REST_PREFIX) and a.domain == "POINT" and a.data_type == "FLOAT"
    )


def _point_attribute(attributes, name: str):
    """The POINT-domain attribute ``name``, or None."""
    attr = attributes.get(name)
    if attr is None or attr.domain != "POINT":
        return None
    return attr


# -- metadata -------------------------------------------------------------------------------------------


def set_meta(cloud, *, layout, fmt: str | None, source: str | None) -> None:
    """Store the source layout, format and path as JSON on the point cloud (read back by ``get_meta``)."""
    cloud[META_KEY] = json.dumps({"version": 1, "layout": layout, "format": fmt, "source": source})


def get_meta(cloud) -> dict:
    """The stored source layout/format/path; {} when absent or unreadable (then exports use INRIA order)."""
    raw = cloud.get(META_KEY)
    if not isinstance(raw, str):
        return {}
    try:
        meta = json.loads(raw)
    except ValueError:
        return {}
    if not isinstance(meta, dict):
        return {}
    layout = meta.get("layout")
    if layout is not None and not (
        isinstance(layout, list)
        and all(isinstance(e, list) and len(e) == 2 and all(isinstance(s, str) for s in e) for e in layout)
    ):
        meta["layout"] = None
    return meta


# -- helpers --------------------------------------------------------------------------------------------


def _remove_ids(ids: list) -> None:
    """Best-effort removal of datablocks a failed import created (some may already be gone)."""
    for block in reversed(ids):
        with contextlib.suppress(KeyError, ReferenceError, RuntimeError):
            collection = {
                bpy.types.Object: bpy.data.objects,
                bpy.types.Mesh: bpy.data.meshes,
                bpy.types.PointCloud: bpy.data.pointclouds,
                bpy.types.Material: bpy.data.materials,
            }[type(block)]
            collection.remove(block)
