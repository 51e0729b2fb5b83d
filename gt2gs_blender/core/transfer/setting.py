"""What a transfer setting means to a user: its label, help, unit, range, choices and the part of the method
it belongs to (the metadata ``config.TransferConfig``'s fields carry), and the typed choices of the settings
that take one of a few words."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

Switch = Literal["auto", "on", "off"]
"""A setting whose automatic value depends on the scene's views."""
Projection = Literal["auto", "box", "view"]
"""How Lay Out Texture puts the texture on the scene."""
FeatureNetwork = Literal["auto", "vgg16_relu3", "vgg19_norm_relu3"]
Device = Literal["auto", "cpu", "cuda"]
Rasterizer = Literal["auto", "torch", "cpu", "gsplat"]

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


def setting(default: Any, label: str, help: str, part: str, **meta: Any) -> Any:
    """A dataclass field with its :class:`Setting` (``help`` is the one-line tooltip)."""
    return field(default=default, metadata={"setting": Setting(label, help, part, **meta)})
