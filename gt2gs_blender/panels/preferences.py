"""The extension's preferences: dependency status and install, what a run would use on this machine (weights,
rasterizer, compiler, CUDA, kernel cache) with Download Weights, and the machine settings (device, threads,
weights, rasterizer, caches) generated from the transfer settings' metadata.

What the machine box shows comes from ``machine_rows`` and ``weights_offer``, plain functions the tests
check; ``draw`` only lays them out.
"""

from __future__ import annotations

import bpy
from bpy.props import EnumProperty

from ..app import deps
from ..blender import addon, machine, properties
from ..core.features.specs import VGG16_RELU3
from ..core.transfer.config import user_settings
from ..core.transfer.setting import IN_PREFERENCES
from ..operators import dependencies
from ..operators import machine as machine_ops
from .sections import draw_setting

WEIGHTS_FILE = VGG16_RELU3.weight_files[0]


def _machine_changed(self, context) -> None:
    """Check the machine again when a setting that changes what it finds changes."""
    machine_ops.check(context)


def dependency_rows(deps_dir: str | None, state: machine.MachineState) -> list[tuple[str, str, bool]]:
    """(package, what is installed, ok) per required package: the version the worker's search path holds and,
    once a machine check has run, whether it loads in the worker's Python (one built for another does not)."""
    rows = []
    for dep in deps.dependency_status(deps_dir):
        loaded = (state.packages or {}).get(dep.module)
        if loaded is not None and loaded["error"]:
            missing = loaded["error"] == f"ModuleNotFoundError: No module named '{dep.module}'"
            rows.append((dep.module, "missing" if missing else f"does not load: {loaded['error']}", False))
            continue
        version = dep.version or (loaded or {}).get("version")
        found = version or "missing"
        if dep.version and not dep.matches_pin:
            found += f" (tested: {dep.pinned})"
        rows.append((dep.module, found, version is not None))
    return rows


def machine_rows(state: machine.MachineState) -> list[tuple[str, str, str]]:
    """(label, value, icon) rows of what a transfer would use here, from the last machine check."""
    if state.info is None:
        if state.running is not None:
            return [("Machine", "checking…", "TIME")]
        return [("Machine", state.error or "not checked yet", "ERROR" if state.error else "INFO")]
    info = state.info
    weights = info.get("weights") or {}
    if weights.get("fallback"):
        shown = "none found: a RANDOM network would stand in (results look wrong)"
    else:
        shown = f"{weights.get('spec')} from {weights.get('weights_file')}"
    cuda = info.get("cuda_device") or ("found" if info.get("cuda") else "not found")
    built = "built" if info.get("kernel_built") else "not built yet"
    return [
        ("Weights", shown, "ERROR" if weights.get("fallback") else "CHECKMARK"),
        ("Rasterizer", f"{info.get('rasterizer_label')} ({info.get('rasterizer_note')})", "CHECKMARK"),
        ("C++ Compiler", info.get("compiler") or "not found", "CHECKMARK" if info.get("compiler") else "ERROR"),
        ("Numba", numba_text(info), "CHECKMARK" if info.get("numba") else "INFO"),
        ("CUDA", f"{cuda} (torch {info.get('torch')})", "CHECKMARK" if info.get("cuda") else "INFO"),
        ("Precision", f"{info.get('precision')} with Mixed Precision ({info.get('precision_note')})", "INFO"),
        ("Kernel Cache", f"{info.get('kernel_cache')} ({built})", "FILE_FOLDER"),
    ]


def numba_text(info: dict) -> str:
    """The Numba row: its version and whether the kernel is compiled, or that it is missing."""
    if not info.get("numba"):
        return "not installed (without a C++ compiler the slower portable rasterizer runs)"
    return f"{info['numba']} (kernel {'compiled' if info.get('numba_compiled') else 'compiled at its first run'})"


def weights_offer(state: machine.MachineState, online: bool) -> tuple[bool, str]:
    """(offer the Download Weights button, advice line) for the weights the last check found."""
    info = state.info or {}
    weights = info.get("weights") or {}
    if not weights.get("fallback"):
        return False, ""
    folders = info.get("weights_folders") or []
    where = f"put {WEIGHTS_FILE} in {folders[-1]}" if folders else f"set Weights to a folder with {WEIGHTS_FILE}"
    if state.running == "download":
        return False, "Downloading the VGG-16 weights…"
    if online:
        return True, f"Download them from {info.get('download_url')}, or {where}"
    return False, f"{addon.ONLINE_ACCESS} to download them, or {where}"


class GT2GS_AP_preferences(bpy.types.AddonPreferences):
    """Dependencies, and the machine settings every transfer of this Blender uses (device, threads, weights)."""

    bl_idname = addon.ADDON_ID
    __annotations__ = {
        "build": EnumProperty(
            name="Torch Build",
            description="Which torch Install Dependencies downloads",
            default="CPU",
            items=(
                ("CPU", "CPU", "The CPU-only torch (smaller download, any machine)"),
                ("CUDA", "CUDA", "torch for NVIDIA GPUs (CUDA 12.8, a large download)"),
            ),
        ),
        **properties.annotations(IN_PREFERENCES, dict.fromkeys(machine.MACHINE_SETTINGS, _machine_changed)),
    }

    def draw(self, context):
        layout = self.layout
        box = layout.box()
        box.label(text="Python Dependencies (used by the transfer worker)")
        folder = addon.deps_dir()
        column = box.column(align=True)
        for module, found, ok in dependency_rows(folder, machine.current()):
            row = column.split(factor=0.3)
            row.label(text=module, icon="CHECKMARK" if ok else "ERROR")
            row.label(text=found)
        box.label(text=f"Install folder: {folder or 'not an installed extension'}")
        row = box.row()
        row.prop(self, "build", expand=True)
        row.operator(dependencies.GT2GS_OT_install_dependencies.bl_idname, icon="IMPORT")
        if not bpy.app.online_access:
            box.label(text=f"{addon.ONLINE_ACCESS} to download packages", icon="INFO")
        box = layout.box()
        box.label(text="What a Transfer Uses on This Machine")
        column = box.column(align=True)
        for label, value, icon in machine_rows(machine.current()):
            row = column.split(factor=0.3)
            row.label(text=label, icon=icon)
            row.label(text=value)
        offer, advice = weights_offer(machine.current(), bpy.app.online_access)
        if advice:
            box.label(text=advice, icon="INFO")
        row = box.row()
        row.operator(machine_ops.GT2GS_OT_check_machine.bl_idname, icon="FILE_REFRESH")
        if offer:
            row.operator(machine_ops.GT2GS_OT_download_weights.bl_idname, icon="IMPORT")
        column = layout.column()
        column.use_property_split = True
        info = machine.current().info
        for name, _, _ in user_settings(IN_PREFERENCES):
            draw_setting(column, self, name, info)


classes = (GT2GS_AP_preferences,)

register, unregister = bpy.utils.register_classes_factory(classes)
