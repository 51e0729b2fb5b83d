"""Splats drawn as Gaussians in EEVEE, Cycles and Material Preview: a geometry-nodes group and a material.

The node group turns each point of a splat object into one quad through its centre, parallel to the
camera's image plane and large enough for the splat's alpha >= 1/255 footprint. The quads give Cycles
the rasterizer's depth order (centre by centre); the material evaluates the Gaussian exactly along each
pixel's ray: with the point P and view vector V in the Gaussian's whitened frame, d² = P·P − (P·V̂)²
and alpha = min(0.99, opacity · exp(−d²/2)) over an Emission of the DC colour. Each σ² is widened by
0.3 · (depth / focal_px)², the rasterizer's 0.3 px² screen-space dilation carried into 3D for the
camera. In Cycles a ray that has crossed ``OPAQUE_AFTER`` splat layers takes the next splat it meets as
opaque, so it stops where the rasterizer's transmittance has long run out. Geometry nodes cannot read the
render size, so it is a modifier input (``apply_display`` fills it in). Everything the display adds
lives on the evaluated mesh; the point cloud, and so every export, keeps only its PLY attributes.

Colour: the rasterizer composites display values (0.5 + SH_C0 · f_dc) as they are; Blender composites
scene-linear light and encodes it for display, so the emission is the sRGB-decoded colour and, under the
Standard view transform, one opaque splat renders to the rasterizer's value. Partly transparent
overlaps blend in linear light (a small difference from the rasterizer's display-space blending).
"""

from __future__ import annotations

import bpy

from ..core.raster_rules import ALPHA_MAX, ALPHA_MIN, EPS2D
from ..core.scene.inria import SH_C0
from . import compat, views

GROUP_NAME = "GT2GS Splats v2"
MATERIAL_NAME = "GT2GS Splat Display v2"
MODIFIER_NAME = "GT2GS Splats"
TAG = "gt2gs_display"
VERSION = 2
OPAQUE_AFTER = 128
"""Splat layers a Cycles ray crosses before the next splat it meets is drawn opaque (the Light Path node's
transparent depth; EEVEE reports 0 and is unaffected). A ray behind the donut's front surface still crosses
hundreds of quads whose light no longer reaches the camera (the rasterizer stops at transmittance 1e-4); Cycles
cannot see the transmittance, so it pays for them all. Donut, 256 px, 32 samples, view 0, 2 cores: 64 layers
36 s / object SSIM 0.921, 128: 70 s / 0.961, 256: 139 s / 0.971; no cut (1024 bounces) 340 s / 0.972."""
TRANSPARENT_BOUNCES = 1024
"""Cycles transparent bounces (max = min, no Russian roulette, whose rare survivors speckle): only rays that keep
passing through quad corners (alpha 0) after ``OPAQUE_AFTER`` layers get this far; the limit ends them (black)."""
PREFIX = "gt2gs_"

Socket = bpy.types.NodeSocket


# -- small node-building helpers -------------------------------------------------------------------------


class _Nodes:
    """Adds nodes to a tree and wires their inputs from sockets or constants."""

    def __init__(self, tree: bpy.types.NodeTree) -> None:
        """Build into ``tree``."""
        self.tree = tree

    def add(self, kind: str, inputs: dict | None = None, **props) -> bpy.types.Node:
        """A new node of ``kind`` with properties set and inputs (name or index -> socket or value) fed."""
        node = self.tree.nodes.new(kind)
        for key, value in props.items():
            setattr(node, key, value)
        for key, value in (inputs or {}).items():
            self.feed(_socket(node.inputs, key), value)
        return node

    def feed(self, socket: Socket, value) -> None:
        """Link ``value`` into ``socket`` if it is a socket, else set it as the default."""
        if isinstance(value, bpy.types.NodeSocket):
            self.tree.links.new(value, socket)
        else:
            socket.default_value = value

    def math(self, op: str, a, b=0.0, c=0.0) -> Socket:
        """A scalar Math node's result."""
        return self.add("ShaderNodeMath", {0: a, 1: b, 2: c}, operation=op).outputs[0]

    def vec(self, op: str, a, b=(0.0, 0.0, 0.0), scale=1.0) -> Socket:
        """A Vector Math node's result (the scalar output for DOT_PRODUCT and LENGTH)."""
        node = self.add("ShaderNodeVectorMath", {0: a, 1: b, 3: scale}, operation=op)
        return node.outputs[1] if op in ("DOT_PRODUCT", "LENGTH", "DISTANCE") else node.outputs[0]


def _socket(sockets, key) -> Socket:
    """The socket by index, or the first available one by name."""
    if isinstance(key, int):
        return sockets[key]
    return next(s for s in sockets if s.name == key and not s.is_unavailable)


# -- the geometry-nodes group -------------------------------------------------------------------------------


def ensure_node_group() -> bpy.types.GeometryNodeTree:
    """The shared display node group of this version; built once per file."""
    group = bpy.data.node_groups.get(GROUP_NAME)
    if group is not None and group.get(TAG) == VERSION and group.library is None:
        return group
    group = bpy.data.node_groups.new(GROUP_NAME, "GeometryNodeTree")
    try:
        group[TAG] = VERSION
        _build_group(group, ensure_material())
    except BaseException:
        bpy.data.node_groups.remove(group)
        raise
    return group


def _interface(group: bpy.types.GeometryNodeTree) -> None:
    """The group's sockets: geometry in and out, and the modifier's inputs."""
    add = group.interface.new_socket
    add("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    density = add("Density", in_out="INPUT", socket_type="NodeSocketFloat")
    density.default_value, density.min_value, density.max_value = 1.0, 0.0, 1.0
    density.description = "Fraction of the splats drawn in the viewport (renders draw all)"
    points = add("Points in Viewport", in_out="INPUT", socket_type="NodeSocketBool")
    points.description = "Show the plain point cloud in the viewport instead of the splats"
    size = add("Render Size", in_out="INPUT", socket_type="NodeSocketInt")
    size.default_value, size.min_value = 1920, 1
    size.description = "Pixels across the camera's sensor width (the larger render side for Auto sensor fit)"
    camera = add("Camera", in_out="INPUT", socket_type="NodeSocketObject")
    camera.description = "The camera the splats face; empty: the scene's active camera"
    add("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")


def _build_group(group: bpy.types.GeometryNodeTree, material: bpy.types.Material) -> None:
    """Points -> camera-facing quads carrying the Gaussian's frame, colour and opacity."""
    _interface(group)
    n = _Nodes(group)
    inp = n.add("NodeGroupInput").outputs
    out = n.add("NodeGroupOutput")
    viewport = n.add("GeometryNodeIsViewport").outputs[0]

    given = inp["Camera"]
    has_given = n.math("GREATER_THAN", n.add("GeometryNodeCameraInfo", {"Camera": given}).outputs["Focal Length"])
    active = n.add("GeometryNodeInputActiveCamera").outputs[0]
    camera = n.add("GeometryNodeSwitch", {0: has_given, 1: active, 2: given}, input_type="OBJECT").outputs[0]
    info = n.add("GeometryNodeObjectInfo", {"Object": camera}, transform_space="RELATIVE").outputs
    lens = n.add("GeometryNodeCameraInfo", {"Camera": camera}).outputs
    sensor_width = n.add("ShaderNodeSeparateXYZ", {0: lens["Sensor"]}).outputs[0]
    focal_px = n.math("MULTIPLY", n.math("DIVIDE", lens["Focal Length"], sensor_width), inp["Render Size"])

    def axis(v) -> Socket:
        return n.add("FunctionNodeRotateVector", {"Vector": v, "Rotation": info["Rotation"]}).outputs[0]

    right, up, forward = axis((1.0, 0.0, 0.0)), axis((0.0, 1.0, 0.0)), axis((0.0, 0.0, -1.0))

    def attr(name: str) -> Socket:
        return n.add("GeometryNodeInputNamedAttribute", {"Name": name}, data_type="FLOAT").outputs["Attribute"]

    centre = n.add("GeometryNodeInputPosition").outputs[0]
    depth = n.vec("DOT_PRODUCT", n.vec("SUBTRACT", centre, info["Location"]), forward)
    dilation = n.math("MULTIPLY", n.math("POWER", n.math("DIVIDE", depth, focal_px), 2.0), EPS2D)
    rotation = n.add("FunctionNodeQuaternionToRotation", {i: attr(f"rot_{i}") for i in range(4)}).outputs[0]
    sigmas = [n.math("SQRT", n.math("ADD", n.math("EXPONENT", n.math("MULTIPLY", attr(f"scale_{i}"), 2.0)), dilation))
              for i in range(3)]  # fmt: skip
    axes = [n.add("FunctionNodeRotateVector", {"Vector": e, "Rotation": rotation}).outputs[0]
            for e in ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))]  # fmt: skip
    whitening = [n.vec("SCALE", a, scale=n.math("DIVIDE", 1.0, s)) for a, s in zip(axes, sigmas)]
    opacity = n.math("DIVIDE", 1.0, n.math("ADD", 1.0, n.math("EXPONENT", n.math("MULTIPLY", attr("opacity"), -1.0))))
    log_reach = n.math("LOGARITHM", n.math("MULTIPLY", opacity, 255.0), 2.718281828459045)
    reach = n.math("SQRT", n.math("MAXIMUM", n.math("MULTIPLY", log_reach, 2.0), 0.0))  # alpha >= 1/255 within

    def extent(direction: Socket) -> Socket:  # the footprint's half-width along an image axis
        parts = [n.math("MULTIPLY", s, n.vec("DOT_PRODUCT", a, direction)) for a, s in zip(axes, sigmas)]
        squares = [n.math("MULTIPLY", p, p) for p in parts]
        squared = n.math("ADD", n.math("ADD", squares[0], squares[1]), squares[2])
        return n.math("MULTIPLY", n.math("SQRT", squared), reach)

    colour = n.add("ShaderNodeCombineXYZ", {i: _srgb_to_linear(n, attr(f"f_dc_{i}")) for i in range(3)}).outputs[0]

    # Viewport density: keep a seeded random fraction; drop splats that can never reach alpha 1/255.
    keep = n.add("FunctionNodeRandomValue", {"Probability": inp["Density"], "Seed": 7}, data_type="BOOLEAN")
    kept = _socket(keep.outputs, "Value")  # the Boolean one: 5.2 has one output, earlier versions one per type
    thin = n.add("FunctionNodeBooleanMath", {0: viewport, 1: kept}, operation="NIMPLY").outputs[0]
    faint = n.math("LESS_THAN", opacity, ALPHA_MIN)
    drop = n.add("FunctionNodeBooleanMath", {0: thin, 1: faint}, operation="OR").outputs[0]
    points = n.add("GeometryNodeDeleteGeometry", {"Geometry": inp["Geometry"], "Selection": drop}, domain="POINT")

    # Far to near: EEVEE blends an object's faces in index order.
    far_first = n.add(
        "GeometryNodeSortElements", {0: points.outputs[0], "Sort Weight": n.math("MULTIPLY", depth, -1.0)}
    )
    capture = n.add("GeometryNodeCaptureAttribute", domain="POINT")
    values = {"center": centre, "w0": whitening[0], "w1": whitening[1], "w2": whitening[2], "color": colour}
    values |= {"opacity": opacity, "sx": extent(right), "sy": extent(up)}
    for name, value in values.items():
        capture.capture_items.new("FLOAT" if name in ("opacity", "sx", "sy") else "VECTOR", name)
        n.feed(capture.inputs[name], value)
    n.feed(capture.inputs[0], far_first.outputs[0])
    wildcard, mode = compat.wildcard_removal()
    bare = n.add("GeometryNodeRemoveAttribute", {0: capture.outputs[0], **wildcard, "Name": "*"}, **mode)
    quad = n.add("GeometryNodeMeshGrid", {"Size X": 2.0, "Size Y": 2.0, "Vertices X": 2, "Vertices Y": 2})
    scale = n.add("ShaderNodeCombineXYZ", {0: capture.outputs["sx"], 1: capture.outputs["sy"], 2: 1.0}).outputs[0]
    inst = n.add(
        "GeometryNodeInstanceOnPoints",
        {"Points": bare.outputs[0], "Instance": quad.outputs[0], "Rotation": info["Rotation"], "Scale": scale},
    )
    geometry = n.add("GeometryNodeRealizeInstances", {0: inst.outputs[0]}).outputs[0]
    for name in values:
        if name not in ("sx", "sy"):
            kind = "FLOAT" if name == "opacity" else ("FLOAT_COLOR" if name == "color" else "FLOAT_VECTOR")
            store = n.add("GeometryNodeStoreNamedAttribute", {0: geometry, "Name": PREFIX + name}, data_type=kind)
            n.feed(_socket(store.inputs, "Value"), capture.outputs[name])
            geometry = store.outputs[0]
    splats = n.add("GeometryNodeSetMaterial", {0: geometry, "Material": material}).outputs[0]
    plain = n.add("FunctionNodeBooleanMath", {0: viewport, 1: inp["Points in Viewport"]}, operation="AND").outputs[0]
    shown = n.add("GeometryNodeSwitch", {0: plain, 1: splats, 2: inp["Geometry"]}, input_type="GEOMETRY")
    n.feed(out.inputs[0], shown.outputs[0])


def _srgb_to_linear(n: _Nodes, f_dc: Socket) -> Socket:
    """Scene-linear value of the display colour 0.5 + SH_C0·f_dc (clamped at 0 like the rasterizer)."""
    c = n.math("MAXIMUM", n.math("MULTIPLY_ADD", f_dc, SH_C0, 0.5), 0.0)
    low = n.math("DIVIDE", c, 12.92)
    high = n.math("POWER", n.math("DIVIDE", n.math("ADD", c, 0.055), 1.055), 2.4)
    return n.add("ShaderNodeMix", {0: n.math("GREATER_THAN", c, 0.04045), 2: low, 3: high}, data_type="FLOAT").outputs[
        0
    ]


# -- the material -------------------------------------------------------------------------------------------


def ensure_material() -> bpy.types.Material:
    """The shared display material of this version; built once per file."""
    material = bpy.data.materials.get(MATERIAL_NAME)
    if material is not None and material.get(TAG) == VERSION and material.library is None:
        return material
    material = bpy.data.materials.new(MATERIAL_NAME)
    try:
        material[TAG] = VERSION
        _build_material(material)
    except BaseException:
        bpy.data.materials.remove(material)
        raise
    return material


def _build_material(material: bpy.types.Material) -> None:
    """Transparent + Emission mixed by opacity · exp(−d²/2), d² along the pixel's ray in the Gaussian's frame."""
    material.surface_render_method = "BLENDED"
    material.use_transparency_overlap = True
    material.use_transparent_shadow = True
    material.diffuse_color = (0.8, 0.8, 0.8, 1.0)
    compat.use_nodes(material)
    tree = material.node_tree
    tree.nodes.clear()
    n = _Nodes(tree)

    def attr(name: str) -> bpy.types.NodeSocketStandard:
        return n.add("ShaderNodeAttribute", attribute_type="GEOMETRY", attribute_name=PREFIX + name).outputs

    position = n.add("ShaderNodeTexCoord").outputs["Object"]
    incoming = n.add("ShaderNodeNewGeometry").outputs["Incoming"]
    view = n.add("ShaderNodeVectorTransform", {0: incoming}, vector_type="VECTOR", convert_from="WORLD",
                 convert_to="OBJECT").outputs[0]  # fmt: skip
    offset = n.vec("SUBTRACT", position, attr("center")["Vector"])
    frame = [attr(f"w{i}")["Vector"] for i in range(3)]
    p = n.add("ShaderNodeCombineXYZ", {i: n.vec("DOT_PRODUCT", offset, w) for i, w in enumerate(frame)}).outputs[0]
    v = n.add("ShaderNodeCombineXYZ", {i: n.vec("DOT_PRODUCT", view, w) for i, w in enumerate(frame)}).outputs[0]
    along = n.vec("DOT_PRODUCT", p, v)
    along2 = n.math("DIVIDE", n.math("MULTIPLY", along, along), n.vec("DOT_PRODUCT", v, v))
    d2 = n.math("SUBTRACT", n.vec("DOT_PRODUCT", p, p), along2)
    falloff = n.math("EXPONENT", n.math("MULTIPLY", d2, -0.5))
    alpha = n.math("MINIMUM", n.math("MULTIPLY", attr("opacity")["Fac"], falloff), ALPHA_MAX)
    alpha = n.math("MULTIPLY", alpha, n.math("GREATER_THAN", alpha, ALPHA_MIN))
    alpha = n.math("MAXIMUM", alpha, _opaque_after(n, alpha))
    emission = n.add("ShaderNodeEmission", {"Color": attr("color")["Color"], "Strength": 1.0})
    transparent = n.add("ShaderNodeBsdfTransparent")
    mix = n.add("ShaderNodeMixShader", {0: alpha, 1: transparent.outputs[0], 2: emission.outputs[0]})
    n.feed(n.add("ShaderNodeOutputMaterial").inputs["Surface"], mix.outputs[0])


def _opaque_after(n: _Nodes, alpha: Socket) -> Socket:
    """1 where the ray has crossed ``OPAQUE_AFTER`` splat layers and meets a visible splat, else 0."""
    layers = n.add("ShaderNodeLightPath").outputs["Transparent Depth"]
    deep = n.math("GREATER_THAN", layers, OPAQUE_AFTER - 0.5)
    return n.math("MULTIPLY", deep, n.math("GREATER_THAN", alpha, 0.0))


def remove_unused() -> None:
    """Remove the display node group and material when nothing uses them (after a cancelled import)."""
    group = bpy.data.node_groups.get(GROUP_NAME)
    if group is not None and group.users == 0:
        bpy.data.node_groups.remove(group)
    material = bpy.data.materials.get(MATERIAL_NAME)
    if material is not None and material.users == 0:
        bpy.data.materials.remove(material)


# -- objects and scenes --------------------------------------------------------------------------------------


def apply_display(
    obj: bpy.types.Object,
    *,
    density: float = 1.0,
    render_size: int | None = None,
    camera: bpy.types.Object | None = None,
    scene: bpy.types.Scene | None = None,
) -> bpy.types.NodesModifier:
    """Give a splat object the display modifier (or update it); render size from ``scene`` when not given."""
    modifier = display_modifier(obj)
    if modifier is None:
        modifier = obj.modifiers.new(MODIFIER_NAME, "NODES")
        modifier.node_group = ensure_node_group()
    if render_size is None:
        render_size = max(views.render_size(scene or bpy.context.scene))
    set_input(modifier, "Density", float(density))
    set_input(modifier, "Render Size", int(render_size))
    set_input(modifier, "Camera", camera)
    _drive_render_size(obj, modifier, scene or bpy.context.scene)
    obj.update_tag()
    return modifier


def _drive_render_size(obj: bpy.types.Object, modifier: bpy.types.NodesModifier, scene: bpy.types.Scene) -> None:
    """Keep Render Size equal to the scene's larger output side (a simple-expression driver, no Python)."""
    path = compat.modifier_input_path(modifier, _identifier(modifier, "Render Size"))
    obj.driver_remove(path)
    driver = obj.driver_add(path).driver
    driver.type = "SCRIPTED"
    for name, prop in (
        ("x", "render.resolution_x"),
        ("y", "render.resolution_y"),
        ("p", "render.resolution_percentage"),
    ):
        var = driver.variables.new()
        var.name, var.type = name, "SINGLE_PROP"
        var.targets[0].id_type, var.targets[0].id, var.targets[0].data_path = "SCENE", scene, prop
    driver.expression = "max(x, y) * p / 100"


def display_modifier(obj: bpy.types.Object) -> bpy.types.NodesModifier | None:
    """The object's display modifier (one using a GT2GS display group), if any."""
    for modifier in obj.modifiers:
        if modifier.type == "NODES" and modifier.node_group is not None and modifier.node_group.get(TAG):
            return modifier
    return None


def _identifier(modifier: bpy.types.NodesModifier, name: str) -> str:
    """The identifier of the modifier's group input ``name``."""
    items = modifier.node_group.interface.items_tree
    return next(i.identifier for i in items if i.item_type == "SOCKET" and i.in_out == "INPUT" and i.name == name)


def set_input(modifier: bpy.types.NodesModifier, name: str, value) -> None:
    """Set the modifier's group input ``name``."""
    compat.set_modifier_input(modifier, _identifier(modifier, name), value)


def get_input(modifier: bpy.types.NodesModifier, name: str):
    """The modifier's value for group input ``name``."""
    return compat.get_modifier_input(modifier, _identifier(modifier, name))


def setup_scene(scene: bpy.types.Scene) -> None:
    """Settings faithful splats need: Standard view transform, Cycles transparent bounces, EEVEE blending."""
    view = scene.view_settings
    view.view_transform, view.look, view.exposure, view.gamma = "Standard", "None", 0.0, 1.0
    scene.cycles.transparent_max_bounces = max(scene.cycles.transparent_max_bounces, TRANSPARENT_BOUNCES)
    scene.cycles.min_transparent_bounces = scene.cycles.transparent_max_bounces
    scene.eevee.use_taa_reprojection = False  # reprojection smears blended surfaces between samples
    scene.display.shading.color_type = "OBJECT"  # Workbench: each splat object in its mean colour
