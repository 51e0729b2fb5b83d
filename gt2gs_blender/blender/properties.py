"""Blender properties generated from the transfer settings' metadata (``core/transfer/config.py``).

Each user setting becomes a property of the scene's GT² settings or of the add-on preferences, with
the setting's label, tooltip, unit and range; its default is the default preset's value. Choosing a
preset writes that preset's values into the scene's properties, so the panel always shows what a run
will use, and ``config_values`` reads them back into the config by the same names.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from typing import Any

import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty, FloatProperty, FloatVectorProperty, IntProperty, StringProperty

from ..core.features.specs import VGG16_RELU3, VGG19_NORM_RELU3
from ..core.transfer.config import FORWARD_SPREAD_DEG, user_settings
from ..core.transfer.presets import DEFAULT_PRESET, PRESETS
from ..core.transfer.setting import DEGREES, IN_SCENE, Setting

DEFAULTS = PRESETS[DEFAULT_PRESET]
FINE_STEP_RANGE = 0.3
"""A float setting whose useful range ends by this steps by Blender's finest increment (0.01 a click)."""
ANGLE_DECIMALS = 4
"""Angles come back from Blender's float32 radians to a ten-thousandth of a degree."""
PATH_SETTINGS = {
    "weights_path": f"Folder with VGG weights ({VGG16_RELU3.weight_files[0]} or {VGG19_NORM_RELU3.weight_files[0]}) "
    "or one such file; empty: $GT2GS_WEIGHTS_DIR, then torch's cache"
}
"""Path settings whose tooltip in Blender says more than the command line's."""
CHOICE_HELP: dict[str, dict[str, str]] = {
    "up": {
        "+z": "+Z is up (Blender's convention)",
        "-z": "-Z is up",
        "+y": "+Y is up",
        "-y": "-Y is up (a capture from a 3DGS trainer, whose cameras have -Y up)",
        "+x": "+X is up",
        "-x": "-X is up",
        "auto": "Estimated from the splats",
    },
    "view_kind": {
        "auto": "Inside when the splats' sizes say the capture was taken from within it (a room), else Orbit",
        "orbit": "A ring all round the object (an object seen from all sides)",
        "front": "A short arc on the side the capture was taken from, read from its splats' sizes, else on "
        "Blender's front (a capture seen from the front, given without its cameras)",
        "inside": "Standing where the cameras stood, read from the splats' sizes (else in the middle), looking out "
        "all round (a room seen from within)",
    },
    "layout_projection": {
        "auto": f"View when every view looks within {FORWARD_SPREAD_DEG:g}° of the views' mean direction, else Box",
        "box": "Wraps the texture around an object seen from all sides",
        "view": "Throws the texture from the first view like a slide projector (a capture seen from the front)",
    },
    "stylise_geometry": {
        "auto": "On for a capture seen from the front, off for an object seen from all sides",
        "on": "The texture loss also moves, scales and turns the splats: bolder texture, looser shape",
        "off": "The splats keep their place, size and turn: the shape is kept",
    },
    "features": {
        "auto": "The best network whose weights are found",
        "vgg16_relu3": f"VGG-16 features (torchvision's ImageNet weights, {VGG16_RELU3.weight_files[0]})",
        "vgg19_norm_relu3": f"The normalised VGG-19 of style transfer ({VGG19_NORM_RELU3.weight_files[0]})",
    },
    "device": {
        "auto": "A CUDA GPU when there is one, else the CPU",
        "cpu": "The CPU",
        "cuda": "An NVIDIA GPU through CUDA",
    },
    "backend": {
        "auto": "The fastest available",
        "torch": "Portable torch rasterizer: runs anywhere, slower",
        "cpu": "Compiled CPU kernel (built once, at the first run)",
        "numba": "The CPU kernel compiled by numba, where there is no C++ compiler",
        "gsplat": "gsplat's CUDA kernels (NVIDIA GPU)",
    },
}
"""What each choice of a choice setting means, for its menu's tooltips (a test checks every choice has one)."""


def annotations(where: str, updates: dict[str, Callable] | None = None) -> dict[str, Any]:
    """Property definitions for the settings Blender offers in ``where`` (IN_SCENE or IN_PREFERENCES);
    ``updates``: a callback per setting name, called when the user changes it."""
    updates = updates or {}
    return {name: _property(name, meta, kind, updates.get(name)) for name, meta, kind in user_settings(where)}


def _property(name: str, meta: Setting, kind: type, update: Callable | None) -> Any:
    """One bpy property for a setting of Python type ``kind``."""
    unit = f" ({meta.unit})" if meta.unit and meta.unit != "steps" else ""
    common: dict[str, Any] = {"name": meta.label, "description": PATH_SETTINGS.get(name, meta.help + unit)}
    if update is not None:
        common["update"] = update
    default = getattr(DEFAULTS, name)
    if kind is bool:
        return BoolProperty(default=default, **common)
    if kind is tuple:
        return FloatVectorProperty(default=default, size=len(default), subtype="COLOR", min=0.0, max=1.0, **common)
    if meta.choices:
        helps = CHOICE_HELP.get(name, {})
        items = tuple((c, c.replace("_", " ").title(), helps.get(c, meta.help)) for c in meta.choices)
        return EnumProperty(items=items, default=default, **common)
    if kind is str:
        return StringProperty(default=default or "", subtype="DIR_PATH", **common)
    if meta.unit == DEGREES:
        limits = {key: math.radians(v) for key, v in (("min", meta.min), ("max", meta.max)) if v is not None}
        return FloatProperty(default=math.radians(default), subtype="ANGLE", **limits, **common)
    return (IntProperty if kind is int else FloatProperty)(default=default, **_limits(name, meta, kind), **common)


def _limits(name: str, meta: Setting, kind: type) -> dict[str, Any]:
    """min / max / soft_max keywords of a number property, and for a float the decimals it shows (2, or 3 where a
    preset's value has a third; Blender shows more for a value smaller than that, such as 0.0005) and the step of
    its arrows: Blender's finest (0.01) where the useful range ends by ``FINE_STEP_RANGE``, else its default (0.03,
    which took Content Strength from 0.005 to 0.035 in one click)."""
    limits = {
        key: kind(value)
        for key, value in (("min", meta.min), ("max", meta.max), ("soft_max", meta.soft_max))
        if value is not None
    }
    if kind is float:
        values = [getattr(preset, name) for preset in PRESETS.values()]
        limits["precision"] = 2 if all(round(v, 2) == v or abs(v) < 0.01 for v in values) else 3
        top = meta.soft_max if meta.soft_max is not None else meta.max
        if top is not None and top <= FINE_STEP_RANGE:
            limits["step"] = 1
    return limits


def config_values(owner: Any, where: str) -> dict[str, Any]:
    """The settings ``owner`` (scene settings or preferences) holds, as the config takes them."""
    return {name: _value(getattr(owner, name), meta, kind) for name, meta, kind in user_settings(where)}


def _value(value: Any, meta: Setting, kind: type) -> Any:
    """A property's value as the config's type: colours as tuples, paths absolute (empty: None), and numbers
    as the decimal the user typed (Blender keeps float32: 0.02 would reach the engine as 0.0199999996)."""
    if kind is tuple:
        return tuple(_decimal(v) for v in value)
    if meta.unit == DEGREES:
        return round(math.degrees(value), ANGLE_DECIMALS)
    if kind is float:
        return _decimal(value)
    if kind is str and not meta.choices:
        return os.path.abspath(bpy.path.abspath(value)) if value else None
    return value


def apply_preset(owner: Any, name: str) -> None:
    """Write preset ``name``'s values into the scene settings ``owner``."""
    values = PRESETS[name]
    for setting, meta, kind in user_settings(IN_SCENE):
        value = getattr(values, setting)
        value = math.radians(value) if meta.unit == DEGREES else value
        setattr(owner, setting, "" if value is None and kind is str else value)


def _decimal(value: float) -> float:
    """The shortest decimal that a float32 property value stands for, as a Python float."""
    return float(str(np.float32(value)))
