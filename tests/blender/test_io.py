"""Import/export of Gaussian splat PLYs through the real operators, in Blender 5.0.1 (bpy module).

Oracles are independent of the code under test: PLY files are parsed and written here with numpy
and hand-written type codes; transforms are built from Euler angles with numpy; view-dependent
colour is evaluated with the rasterizer's own SH code.
"""

from __future__ import annotations

import filecmp
import math
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

bpy = pytest.importorskip("bpy", exc_type=ModuleNotFoundError)

from gt2gs_blender.blender import splats, transform
from gt2gs_blender.core.scene.arrays import SplatArrays
from gt2gs_blender.core.scene.ply_write import write_ply

from ..splat_tools import core_names
from .conftest import DONUT_COUNT

pytestmark = pytest.mark.blender

TYPE_CODES = {
    "char": "i1",
    "uchar": "u1",
    "short": "i2",
    "ushort": "u2",
    "int": "i4",
    "uint": "u4",
    "float": "f4",
    "double": "f8",
}
C0 = 0.28209479177387814


# -- an independent PLY reader/writer -------------------------------------------------------------------


def read_ply_numpy(path) -> tuple[str, list[tuple[str, str]], np.ndarray]:
    """(format, vertex properties, records in native byte order) of a vertex-only PLY."""
    data = Path(path).read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    fmt, props, n = None, [], 0
    for line in data[:end].decode("ascii").splitlines():
        tokens = line.split()
        if tokens[0] == "format":
            fmt = tokens[1]
        elif tokens[0] == "element":
            n = int(tokens[2])
        elif tokens[0] == "property":
            props.append((tokens[2], tokens[1]))
    if fmt == "ascii":
        table = np.loadtxt(data[end:].decode("ascii").splitlines(), dtype=np.float64, ndmin=2)
        records = np.empty(n, [(name, TYPE_CODES[t]) for name, t in props])
        for column, (name, _) in zip(table.T, props, strict=True):
            records[name] = column
        return fmt, props, records
    order = "<" if fmt == "binary_little_endian" else ">"
    dtype = np.dtype([(name, order + TYPE_CODES[t]) for name, t in props])
    records = np.frombuffer(data, dtype, count=n, offset=end)
    return fmt, props, records.astype(dtype.newbyteorder("="))


def write_ply_numpy(path, props: list[tuple[str, str]], columns: dict[str, np.ndarray], fmt: str) -> None:
    order = "<" if fmt == "binary_little_endian" else ">"
    n = len(next(iter(columns.values())))
    records = np.empty(n, [(name, order + TYPE_CODES[t]) for name, t in props])
    for name, _ in props:
        records[name] = columns[name]
    header = "".join(
        [
            "ply\n",
            f"format {fmt} 1.0\n",
            f"element vertex {n}\n",
            *(f"property {t} {name}\n" for name, t in props),
            "end_header\n",
        ]
    )
    Path(path).write_bytes(header.encode("ascii") + records.tobytes())


def core_props(k: int) -> list[tuple[str, str]]:
    """The INRIA properties for K f_rest coefficients per channel, all float."""
    return [(name, "float") for name in core_names(k)]


EXTRAS = [
    ("nx", "float"),
    ("ny", "float"),
    ("nz", "float"),
    ("red", "uchar"),
    ("seg", "short"),
    ("count", "ushort"),
    ("tiny", "char"),
    ("label", "int"),
    ("flags", "uint"),
    ("conf", "double"),
    ("radius", "float"),
    ("position", "float"),
]
"""Normals and extra properties of every type, two of them named like Blender's own attributes."""


def sh3_columns(n: int, seed: int = 0) -> tuple[list[tuple[str, str]], dict[str, np.ndarray]]:
    """A random SH3 scene with normals and extras, in a non-canonical property order."""
    rng = np.random.default_rng(seed)
    core = core_props(15)
    props = [*core[:3], EXTRAS[9], *core[3:10], *EXTRAS[:3], *core[10:], *EXTRAS[3:9], *EXTRAS[10:]]
    columns = {}
    for name, t in props:
        code = TYPE_CODES[t]
        if name.startswith("scale_"):
            columns[name] = (rng.standard_normal(n) * 0.5 - 4).astype(code)
        elif name in ("nx", "ny", "nz"):
            columns[name] = rng.standard_normal(n).astype(code)
        elif code == "f8":  # values a float32 attribute holds exactly
            columns[name] = rng.standard_normal(n).astype(np.float32).astype(code)
        elif code[0] == "f":
            columns[name] = rng.standard_normal(n).astype(code)
        else:
            info = np.iinfo(code)
            columns[name] = rng.integers(info.min, int(info.max) + 1, n, dtype=np.int64).astype(code)
    columns["flags"][:4] = [0, 2**31, 2**32 - 1, 123]  # uint32 beyond int32: bits must survive
    return props, columns


def attribute_values(obj, name: str) -> np.ndarray:
    attr = obj.data.attributes[name]
    n = len(obj.data.points)
    if attr.data_type == "FLOAT_VECTOR":
        out = np.empty(n * 3, np.float32)
        attr.data.foreach_get("vector", out)
        return out.reshape(n, 3)
    if attr.data_type == "FLOAT_COLOR":
        out = np.empty(n * 4, np.float32)
        attr.data.foreach_get("color", out)
        return out.reshape(n, 4)
    out = np.empty(n, np.float32 if attr.data_type == "FLOAT" else np.int32)
    attr.data.foreach_get("value", out)
    return out


def datablock_counts(bpy_module) -> dict[str, int]:
    data = bpy_module.data
    return {k: len(getattr(data, k)) for k in ("objects", "meshes", "pointclouds", "materials", "collections")}


def import_file(path) -> bpy.types.Object:
    assert bpy.ops.gt2gs.import_ply(filepath=str(path)) == {"FINISHED"}
    return bpy.context.active_object


def euler_xyz(rx: float, ry: float, rz: float) -> np.ndarray:
    """Blender's XYZ Euler rotation: R = Rz @ Ry @ Rx."""
    cx, sx, cy, sy, cz, sz = math.cos(rx), math.sin(rx), math.cos(ry), math.sin(ry), math.cos(rz), math.sin(rz)
    rot_x = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    rot_y = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rot_z = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rot_z @ rot_y @ rot_x


def torch_oracle():
    """torch, for the tests whose oracle is the engine's torch side (skipped on a bpy whose Python has none here)."""
    return pytest.importorskip("torch", exc_type=ModuleNotFoundError, reason="this oracle is the engine's torch side")


def rotmats(quats: np.ndarray) -> np.ndarray:
    torch = torch_oracle()
    from gt2gs_blender.core.scene.gaussians import quats_to_rotmats

    return quats_to_rotmats(torch.from_numpy(quats.astype(np.float64))).numpy()


def sh_rest_of(records: np.ndarray, k: int) -> np.ndarray:
    """(N, K, 3) from f_rest_* columns (channel-major in the file)."""
    flat = np.stack([records[f"f_rest_{i}"] for i in range(3 * k)], axis=1).astype(np.float64)
    return flat.reshape(-1, 3, k).transpose(0, 2, 1)


# -- import ---------------------------------------------------------------------------------------------


def test_import_donut_has_every_property_as_an_attribute(fresh, donut):
    _, props, records = read_ply_numpy(donut)
    obj = import_file(donut)

    assert obj.type == "POINTCLOUD"
    assert obj.name == "donut"  # the generic point_cloud.ply is named after its scene folder
    assert len(obj.data.points) == DONUT_COUNT
    assert not bpy.data.meshes  # the conversion's temporary mesh is gone
    positions = attribute_values(obj, "position")
    np.testing.assert_array_equal(positions, np.stack([records["x"], records["y"], records["z"]], axis=1))
    for name, _ in props:
        if name in ("x", "y", "z"):
            continue
        assert obj.data.attributes[name].data_type == "FLOAT" and obj.data.attributes[name].domain == "POINT"
        np.testing.assert_array_equal(attribute_values(obj, name), records[name], err_msg=name)
    assert {a.name for a in obj.data.attributes if not a.name.startswith(".")} == (
        {n for n, _ in props} - {"x", "y", "z"} | {"position", "radius", "Col"}
    )


def test_import_donut_colour_radius_and_material(fresh, donut):
    _, _, records = read_ply_numpy(donut)
    obj = import_file(donut)

    color = attribute_values(obj, "Col")
    assert obj.data.attributes["Col"].data_type == "FLOAT_COLOR"
    dc = np.stack([records[f"f_dc_{i}"] for i in range(3)], axis=1).astype(np.float64)
    srgb = np.clip(0.5 + C0 * dc, 0, 1)
    linear = np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)
    np.testing.assert_allclose(color[:, :3], linear, atol=2e-6)
    np.testing.assert_allclose(color[:, 3], 1 / (1 + np.exp(-records["opacity"].astype(np.float64))), atol=2e-6)

    radius = attribute_values(obj, "radius")
    assert np.isfinite(radius).all() and (radius > 0).all()
    extent = np.linalg.norm(np.ptp(attribute_values(obj, "position"), axis=0))
    assert radius.max() <= 0.05 * extent
    scales = np.sort(np.stack([records[f"scale_{i}"] for i in range(3)], axis=1), axis=1)
    np.testing.assert_allclose(radius, np.minimum(np.exp(scales[:, 1:].mean(axis=1)), radius.max()), rtol=1e-5)

    (material,) = obj.data.materials
    nodes = material.node_tree.nodes
    attribute = next(n for n in nodes if n.bl_idname == "ShaderNodeAttribute")
    assert attribute.attribute_name == "Col" and attribute.attribute_type == "GEOMETRY"
    emission = next(n for n in nodes if n.bl_idname == "ShaderNodeEmission")
    assert emission.inputs["Color"].links[0].from_node == attribute
    output = next(n for n in nodes if n.bl_idname == "ShaderNodeOutputMaterial")
    assert output.inputs["Surface"].is_linked

    materials = len(bpy.data.materials)  # the splat material and the display's
    second = import_file(donut)  # a second import shares them and gets its own data
    assert second.data.materials[0] == material and second.data != obj.data
    assert len(bpy.data.materials) == materials


def test_import_selects_and_activates_only_the_new_object(fresh, donut):
    mesh_obj = bpy.data.objects.new("other", bpy.data.meshes.new("other"))
    bpy.context.scene.collection.objects.link(mesh_obj)
    mesh_obj.select_set(True)
    obj = import_file(donut)
    assert bpy.context.view_layer.objects.active == obj
    assert [o.name for o in bpy.context.selected_objects] == [obj.name]


@pytest.mark.parametrize("hidden", [False, True])
def test_import_goes_to_the_active_collection(fresh, donut, hidden):
    collection = bpy.data.collections.new("splats")
    bpy.context.scene.collection.children.link(collection)
    collection.hide_viewport = hidden  # (hiding the active collection would make another one active)
    bpy.context.view_layer.active_layer_collection = bpy.context.view_layer.layer_collection.children["splats"]
    obj = import_file(donut)
    assert obj.type == "POINTCLOUD" and len(obj.data.points) == DONUT_COUNT
    assert list(obj.users_collection) == [collection]


def test_import_leaves_edit_mode(fresh, donut):
    mesh_obj = bpy.data.objects.new("other", bpy.data.meshes.new("other"))
    bpy.context.scene.collection.objects.link(mesh_obj)
    bpy.context.view_layer.objects.active = mesh_obj
    bpy.ops.object.mode_set(mode="EDIT")
    obj = import_file(donut)
    assert bpy.context.mode == "OBJECT" and obj.type == "POINTCLOUD"


def test_import_several_files_at_once(fresh, donut, tmp_path):
    props, columns = sh3_columns(50)
    write_ply_numpy(tmp_path / "small.ply", props, columns, "binary_little_endian")
    result = bpy.ops.gt2gs.import_ply(directory=str(donut.parent), files=[{"name": donut.name}])
    assert result == {"FINISHED"}
    result = bpy.ops.gt2gs.import_ply(directory=str(tmp_path), files=[{"name": "small.ply"}, {"name": "small.ply"}])
    assert result == {"FINISHED"}
    assert sorted(len(o.data.points) for o in bpy.data.objects) == [50, 50, DONUT_COUNT]
    assert len(bpy.context.selected_objects) == 2


# -- export ---------------------------------------------------------------------------------------------


def test_export_donut_is_byte_identical(fresh, donut, tmp_path):
    import_file(donut)
    out = tmp_path / "donut.ply"
    assert bpy.ops.gt2gs.export_ply(filepath=str(out)) == {"FINISHED"}
    assert filecmp.cmp(out, donut, shallow=False)


@pytest.mark.parametrize("fmt", ["binary_little_endian", "binary_big_endian", "ascii"])
def test_sh3_scene_with_normals_and_extras_round_trips(fresh, tmp_path, fmt):
    props, columns = sh3_columns(300, seed=1)
    src = tmp_path / f"src_{fmt}.ply"
    if fmt == "ascii":  # ASCII number formatting is the writer's: let core write the source
        scene = SplatArrays(
            means=np.stack([columns[c] for c in "xyz"], 1),
            quats=np.stack([columns[f"rot_{i}"] for i in range(4)], 1),
            log_scales=np.stack([columns[f"scale_{i}"] for i in range(3)], 1),
            opacity_logits=columns["opacity"],
            sh_dc=np.stack([columns[f"f_dc_{i}"] for i in range(3)], 1),
            sh_rest=np.ascontiguousarray(
                np.stack([columns[f"f_rest_{i}"] for i in range(45)], 1).reshape(-1, 3, 15).transpose(0, 2, 1)
            ),
            extras={name: columns[name] for name, _ in EXTRAS},
            ply_layout=tuple(props),
        )
        write_ply(src, scene, fmt="ascii")
    else:
        write_ply_numpy(src, props, columns, fmt)
    obj = import_file(src)

    attributes = obj.data.attributes
    assert attributes["ply:radius"].data_type == "FLOAT"  # Blender-owned names are kept aside
    assert attributes["ply:position"].data_type == "FLOAT"
    np.testing.assert_array_equal(attribute_values(obj, "ply:radius"), columns["radius"])
    for name, _ in EXTRAS[3:9]:
        assert attributes[name].data_type == "INT", name
    np.testing.assert_array_equal(attribute_values(obj, "label"), columns["label"])
    np.testing.assert_array_equal(attribute_values(obj, "flags").view(np.uint32), columns["flags"])
    np.testing.assert_array_equal(attribute_values(obj, "conf"), columns["conf"].astype(np.float32))
    np.testing.assert_array_equal(attribute_values(obj, "f_rest_44"), columns["f_rest_44"])
    summary = splats.splat_summary(obj)
    assert summary.sh_degree == 3 and summary.count == 300 and summary.format == fmt
    assert set(summary.extras) == {name for name, _ in EXTRAS}

    out = tmp_path / f"out_{fmt}.ply"
    assert bpy.ops.gt2gs.export_ply(filepath=str(out)) == {"FINISHED"}
    assert filecmp.cmp(out, src, shallow=False)


def test_export_format_option_and_edited_attributes(fresh, donut, tmp_path):
    obj = import_file(donut)
    dc0 = attribute_values(obj, "f_dc_0")
    obj.data.attributes["f_dc_0"].data.foreach_set("value", dc0 * 0.5)
    confidence = obj.data.attributes.new("confidence", "FLOAT", "POINT")
    confidence.data.foreach_set("value", np.arange(DONUT_COUNT, dtype=np.float32))

    out = tmp_path / "edited.ply"
    assert bpy.ops.gt2gs.export_ply(filepath=str(out), ply_format="ASCII") == {"FINISHED"}
    fmt, props, records = read_ply_numpy(out)
    _, _, source = read_ply_numpy(donut)
    assert fmt == "ascii"
    assert [p for p, _ in props][-1] == "confidence"  # a new attribute is written as an extra property
    np.testing.assert_array_equal(records["f_dc_0"], (dc0 * 0.5))
    np.testing.assert_array_equal(records["confidence"], np.arange(DONUT_COUNT))
    np.testing.assert_array_equal(records["rot_3"], source["rot_3"])


def test_export_needs_a_splat_object(fresh, tmp_path):
    with pytest.raises(RuntimeError, match="Select a Gaussian splat"):
        bpy.ops.gt2gs.export_ply(filepath=str(tmp_path / "x.ply"))
    mesh_obj = bpy.data.objects.new("mesh", bpy.data.meshes.new("mesh"))
    bpy.context.scene.collection.objects.link(mesh_obj)
    bpy.context.view_layer.objects.active = mesh_obj
    assert not bpy.ops.gt2gs.export_ply.poll()
    assert not (tmp_path / "x.ply").exists()


# -- transforms -----------------------------------------------------------------------------------------


def test_export_bakes_translation_rotation_and_uniform_scale(fresh, tmp_path):
    torch = torch_oracle()
    from gt2gs_blender.core.render.sh import eval_sh

    props, columns = sh3_columns(400, seed=2)
    src = tmp_path / "src.ply"
    write_ply_numpy(src, props, columns, "binary_little_endian")
    obj = import_file(src)
    location, angles, s = np.array([1.5, -2.0, 0.25]), (0.3, -0.7, 1.1), 2.5
    obj.location, obj.rotation_euler, obj.scale = location, angles, (s, s, s)

    plain = tmp_path / "plain.ply"
    assert bpy.ops.gt2gs.export_ply(filepath=str(plain)) == {"FINISHED"}
    assert filecmp.cmp(plain, src, shallow=False)  # not baking: the object's own space, untouched
    assert any("tick Apply Object Transform" in note for note in splats.object_to_scene(obj)[1])  # and says so
    assert not any("Apply Object Transform" in note for note in splats.object_to_scene(obj, bake_transform=True)[1])

    out = tmp_path / "baked.ply"
    assert bpy.ops.gt2gs.export_ply(filepath=str(out), bake_transform=True) == {"FINISHED"}
    _, out_props, baked = read_ply_numpy(out)
    assert out_props == props
    rot = euler_xyz(*angles)

    means = np.stack([columns[c] for c in "xyz"], 1).astype(np.float64)
    np.testing.assert_allclose(
        np.stack([baked[c] for c in "xyz"], 1), means @ (s * rot).T + location, rtol=1e-5, atol=1e-5
    )
    quats = np.stack([columns[f"rot_{i}"] for i in range(4)], 1)
    baked_quats = np.stack([baked[f"rot_{i}"] for i in range(4)], 1)
    np.testing.assert_allclose(rotmats(baked_quats), rot[None] @ rotmats(quats), atol=2e-6)
    np.testing.assert_allclose(np.linalg.norm(baked_quats, axis=1), np.linalg.norm(quats, axis=1), rtol=1e-5)
    for i in range(3):
        np.testing.assert_allclose(baked[f"scale_{i}"], columns[f"scale_{i}"] + math.log(s), atol=1e-5)
    normals = np.stack([columns[c] for c in ("nx", "ny", "nz")], 1).astype(np.float64)
    np.testing.assert_allclose(np.stack([baked[c] for c in ("nx", "ny", "nz")], 1), normals @ rot.T, atol=1e-5)
    for name in ("opacity", "f_dc_0", "f_dc_1", "f_dc_2", "label", "flags", "conf", "radius"):
        np.testing.assert_array_equal(baked[name], columns[name], err_msg=name)

    # The view-dependent colour turned with the scene: seen along R·d after = along d before.
    dirs = np.random.default_rng(3).standard_normal((400, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    before = eval_sh(
        torch.from_numpy(
            np.concatenate(
                [
                    np.stack([columns[f"f_dc_{i}"] for i in range(3)], 1)[:, None].astype(np.float64),
                    sh_rest_of(columns, 15),
                ],
                axis=1,
            )
        ),
        torch.from_numpy(dirs),
        3,
    )
    after = eval_sh(
        torch.from_numpy(
            np.concatenate(
                [
                    np.stack([baked[f"f_dc_{i}"] for i in range(3)], 1)[:, None].astype(np.float64),
                    sh_rest_of(baked, 15),
                ],
                axis=1,
            )
        ),
        torch.from_numpy(dirs @ rot.T),
        3,
    )
    np.testing.assert_allclose(after.numpy(), before.numpy(), atol=1e-5)


@pytest.mark.parametrize("scale", [(1.0, 2.0, 0.5), (-1.0, 1.0, 1.0)], ids=["non-uniform", "mirror"])
def test_baking_a_non_similarity_keeps_covariances_exact(fresh, tmp_path, scale):
    torch = torch_oracle()
    from gt2gs_blender.core.render.sh import eval_sh

    props, columns = sh3_columns(200, seed=4)
    src = tmp_path / "src.ply"
    write_ply_numpy(src, props, columns, "binary_little_endian")
    obj = import_file(src)
    obj.location, obj.rotation_euler, obj.scale = (0.5, 0.0, -1.0), (0.2, 0.4, -0.9), scale
    linear = euler_xyz(0.2, 0.4, -0.9) @ np.diag(scale)
    bpy.context.view_layer.update()

    scene, notes = splats.object_to_scene(obj, bake_transform=True)
    assert notes and "non-uniform" in notes[0]

    def covariances(quats, log_scales):
        r = rotmats(np.asarray(quats))
        s2 = np.exp(2 * np.asarray(log_scales, np.float64))
        return r @ (s2[:, :, None] * r.transpose(0, 2, 1))

    before = covariances(
        np.stack([columns[f"rot_{i}"] for i in range(4)], 1), np.stack([columns[f"scale_{i}"] for i in range(3)], 1)
    )
    after = covariances(scene.quats, scene.log_scales)
    expected = linear[None] @ before @ linear.T[None]
    np.testing.assert_allclose(after, expected, rtol=1e-4, atol=1e-12 + 1e-5 * np.abs(expected).max())
    # View-dependent colour turns with the transform's orthogonal (polar) factor; exact for a mirror.
    u, _, vt = np.linalg.svd(linear)
    orth = u @ vt
    dirs = np.random.default_rng(6).standard_normal((200, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    dc = np.stack([columns[f"f_dc_{i}"] for i in range(3)], 1)[:, None].astype(np.float64)
    before = eval_sh(torch.from_numpy(np.concatenate([dc, sh_rest_of(columns, 15)], 1)), torch.from_numpy(dirs), 3)
    after = eval_sh(
        torch.from_numpy(np.concatenate([scene.sh_dc[:, None], scene.sh_rest], 1).astype(np.float64)),
        torch.from_numpy(dirs @ orth.T),
        3,
    )
    np.testing.assert_allclose(after.numpy(), before.numpy(), atol=1e-5)

    normals = np.stack([columns[c] for c in ("nx", "ny", "nz")], 1).astype(np.float64)
    turned = np.stack([scene.extras["nx"], scene.extras["ny"], scene.extras["nz"]], 1)
    expected = normals @ np.linalg.inv(linear)  # normals turn with A^-T, keeping their length
    expected *= np.linalg.norm(normals, axis=1, keepdims=True) / np.linalg.norm(expected, axis=1, keepdims=True)
    np.testing.assert_allclose(turned, expected, rtol=1e-4, atol=1e-5)


def test_singular_transform_is_refused(fresh, donut, tmp_path):
    obj = import_file(donut)
    obj.scale = (1.0, 0.0, 1.0)
    with pytest.raises(RuntimeError, match="singular"):
        bpy.ops.gt2gs.export_ply(filepath=str(tmp_path / "x.ply"), bake_transform=True)
    assert not (tmp_path / "x.ply").exists()


def test_transform_sh_basis_matches_the_rasterizer():
    torch = torch_oracle()
    from gt2gs_blender.core.render.sh import sh_basis

    dirs = np.random.default_rng(5).standard_normal((50, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    np.testing.assert_allclose(transform.sh_basis(dirs, 3), sh_basis(torch.from_numpy(dirs), 3).numpy(), atol=1e-12)


# -- failures leave nothing behind ----------------------------------------------------------------------


def truncated_copy(donut: Path, tmp_path: Path) -> Path:
    data = donut.read_bytes()
    path = tmp_path / "truncated.ply"
    path.write_bytes(data[: len(data) // 2])
    return path


@pytest.mark.parametrize(
    "case,match",
    [
        ("garbage", "not a PLY file"),
        ("empty", "empty"),
        ("truncated", "truncated"),
        ("not_gaussian", "missing required properties.*import it with File ▸ Import ▸ Stanford PLY"),
        ("missing", "no such file"),
        ("directory", "is a directory"),
    ],
)
def test_malformed_file_is_reported_and_creates_nothing(fresh, donut, tmp_path, case, match):
    path = tmp_path / f"{case}.ply"
    if case == "garbage":
        path.write_bytes(b"\x00\x01 this is not a ply file" * 10)
    elif case == "empty":
        path.write_bytes(b"")
    elif case == "truncated":
        path = truncated_copy(donut, tmp_path)
    elif case == "not_gaussian":
        path.write_bytes(
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
            b"property float z\nend_header\n0 0 0\n"
        )
    elif case == "directory":
        path.mkdir()
    before = datablock_counts(bpy)
    with pytest.raises(RuntimeError, match=match):
        bpy.ops.gt2gs.import_ply(filepath=str(path))
    assert datablock_counts(bpy) == before


def test_a_bad_file_among_several_cancels_the_whole_import(fresh, donut, tmp_path):
    props, columns = sh3_columns(20)
    write_ply_numpy(tmp_path / "good.ply", props, columns, "binary_little_endian")
    truncated_copy(donut, tmp_path)
    before = datablock_counts(bpy)
    with pytest.raises(RuntimeError, match="truncated"):
        bpy.ops.gt2gs.import_ply(directory=str(tmp_path), files=[{"name": "good.ply"}, {"name": "truncated.ply"}])
    assert datablock_counts(bpy) == before  # the good file's object and the new material are gone too


# -- registration and UI --------------------------------------------------------------------------------


def _menu_entries(menu, function) -> int:
    return sum(f is function for f in menu._dyn_ui_initialize())


def test_register_and_unregister_twice(fresh, extension, donut):
    from gt2gs_blender.operators import io_export, io_import

    try:
        for _ in range(2):
            extension.unregister()
            assert not hasattr(bpy.types, "GT2GS_OT_import_ply")
            assert not hasattr(bpy.types, "GT2GS_OT_export_ply")
            assert not hasattr(bpy.types, "GT2GS_FH_ply")
            assert not hasattr(bpy.types, "VIEW3D_PT_gt2gs_splat")
            assert _menu_entries(bpy.types.TOPBAR_MT_file_import, io_import.menu_func_import) == 0
            assert _menu_entries(bpy.types.TOPBAR_MT_file_export, io_export.menu_func_export) == 0
            extension.unregister()  # unregistering what is not registered is a no-op
        for _ in range(2):
            extension.register()
            assert _menu_entries(bpy.types.TOPBAR_MT_file_import, io_import.menu_func_import) == 1
            assert _menu_entries(bpy.types.TOPBAR_MT_file_export, io_export.menu_func_export) == 1
            extension.unregister()
    finally:
        extension.register()
    assert import_file(donut).type == "POINTCLOUD"


def test_file_handler_accepts_ply_drops_on_the_3d_view(fresh):
    handler = bpy.types.GT2GS_FH_ply
    assert handler.bl_import_operator == "gt2gs.import_ply"
    assert ".ply" in handler.bl_file_extensions.split(";")
    assert handler.poll_drop(SimpleNamespace(area=SimpleNamespace(type="VIEW_3D")))
    assert not handler.poll_drop(SimpleNamespace(area=SimpleNamespace(type="IMAGE_EDITOR")))
    assert not handler.poll_drop(SimpleNamespace(area=None))


def test_sidebar_rows(fresh, donut):
    from gt2gs_blender.panels import sidebar

    assert bpy.types.VIEW3D_PT_gt2gs_splat.bl_category == "GT²"
    assert sidebar.splat_rows(None) is None
    mesh_obj = bpy.data.objects.new("mesh", bpy.data.meshes.new("mesh"))
    assert sidebar.splat_rows(mesh_obj) is None
    obj = import_file(donut)
    assert sidebar.splat_rows(obj) == [
        ("Object", "donut"),
        ("Splats", "45,624"),
        ("SH Degree", "0"),
        ("Extras", "none"),
        ("Source", "point_cloud.ply"),
    ]
    obj.data.attributes.remove(obj.data.attributes["opacity"])
    assert sidebar.splat_rows(obj) is None


def test_non_finite_splats_are_refused_unless_dropped(fresh, tmp_path):
    props, columns = sh3_columns(30, seed=7)
    columns["opacity"][5] = np.nan
    path = tmp_path / "nan.ply"
    write_ply_numpy(path, props, columns, "binary_little_endian")
    before = datablock_counts(bpy)
    with pytest.raises(RuntimeError, match="non-finite"):
        bpy.ops.gt2gs.import_ply(filepath=str(path))
    assert datablock_counts(bpy) == before
    assert bpy.ops.gt2gs.import_ply(filepath=str(path), drop_invalid=True) == {"FINISHED"}
    obj = bpy.context.active_object
    assert len(obj.data.points) == 29
    np.testing.assert_array_equal(attribute_values(obj, "label"), np.delete(columns["label"], 5))


def test_import_and_export_work_without_torch(donut, tmp_path):
    """Blender's own Python has no torch until the user installs the engine's dependencies: PLY import
    and export must not need it (run in a fresh process where importing torch fails)."""
    out = tmp_path / "out.ply"
    code = (
        "import sys; sys.modules['torch'] = None\n"
        "import bpy, gt2gs_blender\n"
        "gt2gs_blender.register()\n"
        "bpy.ops.wm.read_factory_settings(use_empty=True)\n"
        f"assert bpy.ops.gt2gs.import_ply(filepath={str(donut)!r}) == {{'FINISHED'}}\n"
        f"assert bpy.ops.gt2gs.export_ply(filepath={str(out)!r}) == {{'FINISHED'}}\n"
        "assert 'torch' not in sys.modules or sys.modules['torch'] is None\n"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=Path(__file__).resolve().parents[2],
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert out.read_bytes() == donut.read_bytes()
