"""The extension's identity in Blender: its add-on id, its preferences and its per-user folders."""

from __future__ import annotations

import bpy

ADDON_ID = __package__.rpartition(".")[0]
"""``gt2gs_blender`` from the source tree, ``bl_ext.<repository>.gt2gs_blender`` when installed."""
ONLINE_ACCESS = "Allow Online Access (Preferences ▸ System ▸ Network)"
"""Where Blender 4.2+ lets an extension reach the internet, for every message that needs it."""


def preferences(context=None):
    """The add-on preferences, or None when the package was registered without being enabled as an add-on."""
    addon = (context or bpy.context).preferences.addons.get(ADDON_ID)
    return None if addon is None else addon.preferences


def deps_dir(create: bool = False) -> str | None:
    """The folder pip installs the engine's packages into (the extension's user folder), None outside an extension."""
    try:
        return bpy.utils.extension_path_user(ADDON_ID, path="deps", create=create)
    except ValueError:  # not installed as an extension (e.g. registered from a source checkout)
        return None
