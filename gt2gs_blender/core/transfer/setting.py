"""What a transfer setting means to a user: its label, help, unit, range, choices and the part of the method
it belongs to (the metadata ``config.TransferConfig``'s fields carry), and the typed choices of the settings
that take one of a few words."""

from __future__ import annotations

import math
import types
from dataclasses import dataclass, field
from typing import Any, Literal, Union, get_args, get_origin

Switch = Literal["auto", "on", "off"]
"""A setting whose automatic value depends on the scene's views."""
Projection = Literal["auto", "box", "view"]
"""How Lay Out Texture puts the texture on the scene."""
FeatureNetwork = Literal["auto", "vgg16_relu3", "vgg19_norm_relu3"]
Device = Literal["auto", "cpu", "cuda"]
Rasterizer = Literal["auto", "torch", "cpu", "numba", "gsplat"]
UpAxis = Literal["+z", "-z", "+y", "-y", "+x", "-x", "auto"]
"""The scene's up direction for automatic views (``cameras.axes.axis_vector``'s names, or estimated)."""
ViewKind = Literal["auto", "orbit", "front", "inside"]
"""Where automatic views stand: from inside where the splats say the cameras stood within the capture, else a ring
(auto); a ring all round; an arc on the side the capture's cameras stood; a ring looking out from within."""

PARTS = {
    "views": "Views",
    "texture": "Texture",
    "stylise": "Stylisation",
    "gt2": "GT² Orientation",
    "afcm": "Adaptive Control (AFCM)",
    "gpb": "Geometry Preservation",
    "speed": "Speed",
    "machine": "Machine",
}
"""The parts of a run the settings belong to, in the order the CLI's help and Blender's panels show them."""

IN_SCENE, IN_PREFERENCES = "scene", "preferences"
DEGREES = "°"
"""The unit of angle settings (Blender shows them as angle properties, which hold radians)."""


@dataclass(frozen=True)
class Setting:
    """What a setting means to a user, and where the front ends offer it."""

    label: str
    help: str
    part: str
    unit: str = ""
    min: float | None = None
    max: float | None = None
    soft_max: float | None = None
    choices: tuple[str, ...] = ()
    """The allowed values of a choice setting (its ``Literal`` type's words); a config refuses any other."""
    flag: str | None = None
    """The CLI flag when it is not ``--field-name``."""
    switch: tuple[str, Any, str] | None = None
    """An extra CLI switch (flag, value it sets, help), kept for a common use of the setting."""
    blender: str = IN_SCENE
    """Where Blender offers it: the scene's GT² settings, or the add-on preferences (machine settings)."""
    internal: bool = False
    """Set by the program, not by users: no CLI flag, no Blender property."""

    def problem(self, value: Any) -> str | None:
        """Why ``value`` cannot be this setting's (not one of its choices, not finite, outside its range),
        else None; a colour's components are checked one by one."""
        if self.choices:
            return None if value in self.choices else f"must be one of {', '.join(self.choices)}, got {value!r}"
        for number in value if isinstance(value, tuple) else (value,):
            if isinstance(number, bool) or not isinstance(number, (int, float)):
                continue
            if not math.isfinite(number):
                return f"must be a finite number, got {value!r}"
            if (self.min is not None and number < _slack(self.min, -1)) or (
                self.max is not None and number > _slack(self.max, 1)
            ):
                return f"must be {self.range_text()}, got {value!r}"
        return None

    def range_text(self) -> str:
        """The allowed range in words: 'between 0 and 1', 'at least 1', 'at most 4'."""
        if self.min is not None and self.max is not None:
            return f"between {self.min:g} and {self.max:g}"
        return f"at least {self.min:g}" if self.min is not None else f"at most {self.max:g}"


FLOAT32_SLACK = 1e-6
"""Relative room at a range's ends: a value read back from Blender's float32 property may sit an ulp outside."""


def _slack(bound: float, direction: int) -> float:
    """``bound`` widened by ``FLOAT32_SLACK`` of itself in ``direction`` (-1 below, +1 above)."""
    return bound + direction * FLOAT32_SLACK * abs(bound)


def setting(default: Any, label: str, help: str, part: str, **meta: Any) -> Any:
    """A dataclass field with its :class:`Setting` (``help`` is the one-line tooltip)."""
    return field(default=default, metadata={"setting": Setting(label, help, part, **meta)})


def value_type(annotation: Any) -> type:
    """The value type of a setting's type hint: a choice's word type, an optional path's str, a generic's origin."""
    if get_origin(annotation) is Literal:
        return type(get_args(annotation)[0])
    if get_origin(annotation) in (Union, types.UnionType):  # an optional path: str | None
        annotation = next(arg for arg in get_args(annotation) if arg is not type(None))
    return get_origin(annotation) or annotation
