"""A texture transfer or orientation preview run from Blender: inputs out to a worker job, result back in.

``start`` exports the target's splats, texture, views and region into a ``Job`` folder and launches
the worker; ``tick`` polls it (never blocks), shows new preview frames and, when the worker is done,
applies the result as a new object or in place. Until then nothing in the scene changes, so a
cancelled or failed run leaves it exactly as it was. The modal operator calls ``tick`` on its timer,
the headless operator in a loop, tests directly. One run of each kind at a time (``ACTIVE``: a new
preview replaces a running one, a second transfer is refused); the panel reads them and how the
last run of each kind ended (``OUTCOMES``).
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import bpy
import bpy.utils.previews
import numpy as np

from ..app.protocol import JobSpec
from ..core.cameras.axes import up_from_rotation
from ..core.progress import format_eta
from ..core.transfer.presets import GPU_PRESETS
from ..core.transfer.setting import IN_PREFERENCES, IN_SCENE
from . import addon, machine, properties, splats, textures, views
from .job import CANCELLED, DONE, ERROR, Job, JobStatus

SELECTION_ATTRIBUTE = ".selection"
"""The point selection of a point cloud's Edit Mode."""
PREVIEW_KEY = "preview"
RESULT_SUFFIX = " GT²"
RESULT_OF = "gt2gs_result_of"
"""A new result object's property holding its original (a datablock reference: it follows renames)."""


STAGE_NAMES = {
    "starting": "Starting",
    "compile": "Compiling the CPU rasterizer (first run only)",
    "prepare": "Preparing views",
    "bank": "Texture bank",
    "stylise": "Stylising",
    "finish": "Finishing",
}
"""What the panel and headless runs call each stage of a run."""


def eta_text(seconds: float | None) -> str:
    """``ETA 1:05`` (empty while unknown)."""
    if seconds is None:
        return ""
    return f"ETA {format_eta(seconds)}"


def progress_text(status: JobStatus) -> str:
    """``Stylising 12/40 · 45% · ETA 0:41``."""
    parts = [STAGE_NAMES.get(status.stage, status.stage.title() or "Working")]
    if status.total > 1:
        parts[0] += f" {status.step}/{status.total}"
    parts.append(f"{status.fraction:.0%}")
    eta = eta_text(status.eta_s)
    if eta:
        parts.append(eta)
    return " · ".join(parts)


class RunError(Exception):
    """A run cannot start; the message is meant for the user."""


@dataclass
class Outcome:
    """How the last run ended, for the panel: state, a message (which says where a new result's hidden original
    is), the report, the result object's name and how the result was applied (``NEW`` or ``IN_PLACE``)."""

    state: str
    message: str
    report: dict[str, Any] | None = None
    result: str | None = None
    seconds: float = 0.0
    mode: str = "NEW"


ACTIVE: dict[str, TransferRun] = {}
OUTCOMES: dict[str, Outcome] = {}
_previews: dict[str, Any] = {}


NO_TARGET = "Select a Gaussian splat object"
"""What the panels and the greyed-out operators say when there is no splat object to act on."""


def target_object(context: bpy.types.Context) -> bpy.types.Object | None:
    """The splat object a run acts on: the panel's target, else the active object (None if not a splat)."""
    settings = context.scene.gt2gs
    obj = settings.target or context.active_object
    return obj if splats.is_splat_object(obj) else None


def original_of(obj: bpy.types.Object) -> bpy.types.Object | None:
    """The splat object a New Object result was made from, if it is still in a collection (deleting an object the
    property holds leaves it in the file, unlinked)."""
    original = obj.get(RESULT_OF)
    if not isinstance(original, bpy.types.Object) or not original.users_collection:
        return None
    return original if splats.is_splat_object(original) else None


def result_target_hint(context: bpy.types.Context) -> str | None:
    """What the panel says under an empty *Target* when the active object is a previous run's result (as it is after
    a New Object run, so a second run would restyle the result): whose result it is, and how to start from it."""
    obj = None if context.scene.gt2gs.target else target_object(context)
    original = None if obj is None else original_of(obj)
    if original is None:
        return None
    return f"Restyles {obj.name}, a result; set Target to {original.name} to start from the original"


def polled_target(cls: type[bpy.types.Operator], context: bpy.types.Context) -> bpy.types.Object | None:
    """:func:`target_object` for an operator's poll, which says why it is greyed out when there is none."""
    obj = target_object(context)
    if obj is None:
        cls.poll_message_set(NO_TARGET)
    return obj


def config_overrides(context: bpy.types.Context, overrides: dict[str, Any]) -> tuple[str, dict[str, Any]]:
    """(preset, TransferConfig settings): the panel's settings (none when a script names a preset: then the
    preset's), the preferences' machine settings, and the operator's keywords."""
    settings = context.scene.gt2gs
    prefs = addon.preferences(context)
    config = {} if "preset" in overrides else properties.config_values(settings, IN_SCENE)
    if prefs is not None:
        config.update(properties.config_values(prefs, IN_PREFERENCES))
    if "angle" in overrides:
        config["angle"] = float(overrides["angle"])
    return overrides.get("preset") or settings.preset, {k: v for k, v in config.items() if v is not None}


def with_object_up(config: dict[str, Any], obj: bpy.types.Object) -> dict[str, Any]:
    """``config`` with Up Axis Auto resolved from ``obj``'s own transform when the artist turned it to stand on
    an axis (:func:`up_from_rotation`); left to the splats otherwise."""
    if config.get("up", "auto") != "auto":
        return config
    up = up_from_rotation(np.array(obj.matrix_world.to_3x3()))
    return config if up is None else {**config, "up": up}


def machine_settings(context: bpy.types.Context) -> dict[str, Any]:
    """The preferences' settings that decide what the machine check finds (none set: the engine's defaults)."""
    prefs = addon.preferences(context)
    if prefs is None:
        return {}
    values = properties.config_values(prefs, IN_PREFERENCES)
    return {name: values[name] for name in machine.MACHINE_SETTINGS if values.get(name) is not None}


def gpu_preset_check(context: bpy.types.Context, preset: str) -> None:
    """RunError when ``preset`` needs a CUDA GPU this machine lacks (asks the machine first if not known yet)."""
    settings = machine_settings(context)
    device = settings.get("device", "auto")
    if preset in GPU_PRESETS and device != "cpu" and machine.current().info is None:
        machine.probe(settings, addon.deps_dir())
    problem = machine.gpu_problem(preset, device, machine.current())
    if problem:
        raise RunError(problem)


def first_view_label(context: bpy.types.Context) -> str:
    """Which view is the first one, the view the texture's angle is measured in."""
    settings = context.scene.gt2gs
    if settings.view_source == "AUTO" and settings.view_kind == "inside":
        return "automatic view 1, from inside, looking as Blender's Front view does (towards +Y), a little down"
    if settings.view_source == "AUTO":
        return "automatic view 1, in front (Blender's Front view, from -Y), 20° above"
    if settings.view_source == "CAMERAS_JSON":
        return f"the first camera of {os.path.basename(settings.cameras_json) or 'cameras.json'}"
    collection = settings.camera_collection if settings.view_source == "COLLECTION" else None
    objects = collection.all_objects if collection is not None else context.scene.objects
    names = sorted(o.name for o in objects if o.type == "CAMERA")
    return f"camera {names[0]!r} (first by name)" if names else "no camera yet"


def views_label(settings: bpy.types.PropertyGroup) -> str | None:
    """What messages call the views when they come from the Blender scene (None: automatic views or a
    cameras.json the user picked, which messages name by its path)."""
    if settings.view_source == "SCENE_CAMERAS":
        return "the scene's cameras"
    if settings.view_source == "COLLECTION" and settings.camera_collection is not None:
        return f"the cameras of collection {settings.camera_collection.name!r}"
    return None


def view_spec(
    context: bpy.types.Context, obj: bpy.types.Object, job: Job, overrides: dict[str, Any]
) -> str | int | None:
    """The job's ``views``: a count of automatic views (or None: the preset's) or a cameras.json path."""
    settings = context.scene.gt2gs
    if "n_views" in overrides:
        return int(overrides["n_views"])
    if settings.view_source == "AUTO":
        return settings.n_views or None
    if settings.view_source == "CAMERAS_JSON":
        path = os.path.abspath(bpy.path.abspath(settings.cameras_json))
        if not os.path.isfile(path):
            raise RunError(f"cameras.json not found: {path}")
        return path
    if settings.view_source == "COLLECTION":
        if settings.camera_collection is None:
            raise RunError("choose a camera collection for the views")
        objects = settings.camera_collection.all_objects
    else:
        objects = context.scene.objects
    cameras = sorted((o for o in objects if o.type == "CAMERA"), key=lambda o: o.name)
    try:
        entries = views.camera_entries(cameras, context.scene, np.array(obj.matrix_world))
    except views.ViewError as exc:
        raise RunError(str(exc)) from None
    job.path("cameras.json").write_text(json.dumps(entries, indent=1), encoding="utf-8")
    return "cameras.json"


def texture_missing(settings: bpy.types.PropertyGroup) -> str | None:
    """Why a transfer has no texture yet (the panel disables Transfer with it), None once one is chosen."""
    if settings.texture_source == "FILE" and not settings.texture_path:
        return "choose a texture file (or an image) first"
    if settings.texture_source == "IMAGE" and settings.texture_image is None:
        return "choose a texture image"
    return None


def texture_spec(context: bpy.types.Context, job: Job, override: str | None) -> str:
    """The job's texture: a file on disk, or an image datablock's pixels saved as .npy in the job folder."""
    settings = context.scene.gt2gs
    missing = None if override else texture_missing(settings)
    if missing:
        raise RunError(missing)
    if override or settings.texture_source == "FILE":
        chosen = override or settings.texture_path
        path = os.path.abspath(bpy.path.abspath(chosen))
        if os.path.isdir(path):
            raise RunError(f"{path}: the texture is a folder; choose an image file in it")
        if not os.path.isfile(path):
            raise RunError(f"texture file not found: {path}")
        problem = textures.texture_problem(path)
        if problem:
            raise RunError(problem)
        return path
    image = settings.texture_image
    source = os.path.abspath(bpy.path.abspath(image.filepath_from_user())) if image.filepath else ""
    if source and os.path.isfile(source) and not image.is_dirty and image.packed_file is None:
        return source
    width, height = image.size
    if width == 0 or height == 0:
        raise RunError(f"image {image.name!r} has no pixels")
    pixels = np.empty(width * height * image.channels, np.float32)
    image.pixels.foreach_get(pixels)
    rgb = pixels.reshape(height, width, image.channels)[::-1, :, :3]
    if image.is_float:  # float buffers are scene-linear: back to display sRGB, as photos are
        rgb = np.where(rgb <= 0.0031308, rgb * 12.92, 1.055 * np.power(np.clip(rgb, 0, None), 1 / 2.4) - 0.055)
    if rgb.shape[2] == 1:
        rgb = np.repeat(rgb, 3, axis=2)
    np.save(job.path("texture.npy"), np.ascontiguousarray(np.clip(rgb, 0.0, 1.0), np.float32))
    return "texture.npy"


def selection_mask(obj: bpy.types.Object) -> np.ndarray | None:
    """(N,) bool: the points selected in Edit Mode, or None when the object has no point selection."""
    attribute = obj.data.attributes.get(SELECTION_ATTRIBUTE)
    if attribute is None or attribute.domain != "POINT":
        return None
    values = np.empty(len(obj.data.points), bool if attribute.data_type == "BOOLEAN" else np.float32)
    attribute.data.foreach_get("value", values)
    return values > 0


def selected_points(obj: bpy.types.Object) -> np.ndarray:
    """Indices of the points selected in Edit Mode; RunError when none are."""
    mask = selection_mask(obj)
    if mask is None:
        raise RunError(f"{obj.name!r} has no point selection: select points in Edit Mode first")
    indices = np.flatnonzero(mask)
    if indices.size == 0:
        raise RunError(f"no points of {obj.name!r} are selected")
    return indices


def show_preview(
    path: str,
    first_view: str,
    splats: tuple[int, int] | None = None,
    views: tuple[int, int, int, int] | None = None,
) -> None:
    """Load a PNG frame of ``first_view`` into the panel's preview image (an ImagePreview, not a datablock of
    the file); ``splats``: the finished preview's counts (the run's start, the object's); ``views``: the run's
    (count, width, height, Resolution asked for)."""
    image = bpy.data.images.load(path, check_existing=False)
    try:
        width, height = image.size
        pixels = np.empty(width * height * 4, np.float32)
        image.pixels.foreach_get(pixels)
    finally:
        bpy.data.images.remove(image)
    if "collection" not in _previews:
        _previews["collection"] = bpy.utils.previews.new()
    collection = _previews["collection"]
    preview = collection.get(PREVIEW_KEY) or collection.new(PREVIEW_KEY)
    preview.image_size = (width, height)
    preview.image_pixels_float.foreach_set(pixels)
    _previews["first_view"] = first_view
    _previews["splats"] = splats
    _previews["views"] = views


def preview_icon() -> int:
    """The icon id of the panel's preview image, 0 when there is none."""
    collection = _previews.get("collection")
    preview = collection.get(PREVIEW_KEY) if collection is not None else None
    return preview.icon_id if preview is not None else 0


def preview_caption() -> str:
    """What the preview image shows: the first view of its run, the view the Orientation angle is measured in."""
    shown = _previews.get("first_view")
    return f"First view: {shown}; the Orientation angle is measured here" if shown else ""


def preview_splats_text() -> str:
    """How many splats the previewed run will save (the detail split makes the file grow), or "" when unknown."""
    counts = _previews.get("splats")
    if not counts:
        return ""
    start, scene = counts
    if start == scene:
        return f"The result keeps about {scene:,} splats"
    return f"The result will have about {start:,} splats, {start / scene:.1f}x the object's {scene:,}"


def preview_views_text() -> str:
    """The views the previewed run will work at, and why when larger than *Resolution*, or "" when unknown."""
    views = _previews.get("views")
    if not views:
        return ""
    count, width, height, asked = views
    text = f"The run works {count} views at {width}×{height}"
    return text if max(width, height) <= asked else f"{text}: a dense capture, above Resolution's {asked}"


def release_previews() -> None:
    """Free the preview images (at unregister)."""
    collection = _previews.pop("collection", None)
    _previews.pop("first_view", None)
    _previews.pop("splats", None)
    _previews.pop("views", None)
    if collection is not None:
        bpy.utils.previews.remove(collection)


@dataclass
class TransferRun:
    """One worker job started from Blender and what to do with its result: the object it restyles is known by its
    ``session_uid`` (kept across renames), its name only for messages."""

    job: Job
    kind: str
    object_name: str
    object_uid: int
    result_mode: str = "NEW"
    first_view: str = ""
    shown_preview: str | None = None
    cancel_requested: bool = False
    result_name: str | None = None
    started: float = field(default_factory=time.monotonic)

    @classmethod
    def start(
        cls, context: bpy.types.Context, overrides: dict[str, Any] | None = None, kind: str = "transfer"
    ) -> TransferRun:
        """Export the target and start the worker; RunError (nothing started, nothing left) when it cannot."""
        overrides = overrides or {}
        if kind == "transfer" and kind in ACTIVE:
            raise RunError("a texture transfer is already running; cancel it first")
        if kind in ACTIVE:  # a newer preview supersedes the running one
            ACTIVE[kind].cancel()
            ACTIVE[kind].finish()
        obj = target_object(context)
        if obj is None:
            raise RunError("select a Gaussian splat object (import a .ply first)")
        settings = context.scene.gt2gs
        if kind == "transfer":
            gpu_preset_check(context, overrides.get("preset") or settings.preset)
        job = Job(deps_dir=addon.deps_dir())
        try:
            from ..core.scene.ply_write import write_ply

            scene, _ = splats.object_to_scene(obj)
            write_ply(job.path("input.ply"), scene)
            preset, config = config_overrides(context, overrides)
            config = with_object_up(config, obj)
            chosen = view_spec(context, obj, job, overrides)
            spec = JobSpec(
                kind=kind,
                input=Path("input.ply"),
                texture=Path(texture_spec(context, job, overrides.get("texture_path"))),
                output=Path("result.ply" if kind == "transfer" else "orientation.png"),
                views=Path(chosen) if isinstance(chosen, str) else chosen,
                preset=preset,
                config=config,
                report=Path("report.json"),
                input_name=f"object {obj.name!r}",
                views_name=views_label(settings),
            )
            if settings.region_only:  # the preview lays the texture on the region as the run will
                np.save(job.path("region.npy"), selected_points(obj))
                spec = replace(spec, region=Path("region.npy"))
            job.start(spec)
        except BaseException as exc:
            job.cleanup()
            if isinstance(exc, (splats.SplatObjectError, OSError, ValueError)):
                raise RunError(str(exc)) from None
            raise
        run = cls(job, kind, obj.name, obj.session_uid, settings.result_mode, first_view_label(context))
        ACTIVE[kind] = run
        return run

    def tick(self, context: bpy.types.Context) -> JobStatus:
        """Poll the worker, show a new preview frame, apply the result once it is done."""
        status = self.job.poll()
        if status.preview and status.preview != self.shown_preview and os.path.isfile(status.preview):
            show_preview(status.preview, self.first_view)
            self.shown_preview = status.preview
        if status.state == DONE and self.kind == "preview" and self.shown_preview != status.output:
            show_preview(status.output, self.first_view, status.splats, status.views)
            self.shown_preview = status.output
        if status.state == DONE and self.kind == "transfer" and self.result_name is None:
            try:
                source = self.source_object()
                if source is None:
                    raise RunError(f"the object {self.object_name!r} was deleted")
                self.result_name = apply_result(context, source, status.output, self.result_mode).name
            except Exception as exc:  # whatever stops it (an operator's poll too), the run ends and says why
                status.state, status.error = ERROR, f"the result could not be applied: {exc}"
        return status

    def source_object(self) -> bpy.types.Object | None:
        """The object the run restyles, whatever it is called now (None: deleted, or no longer splats)."""
        found = next((o for o in bpy.data.objects if o.session_uid == self.object_uid), None)
        return found if found is not None and splats.is_splat_object(found) else None

    def cancel(self) -> JobStatus:
        """Ask the worker to stop; the scene is left as it was."""
        return self.job.cancel()

    def finish(self) -> Outcome:
        """Remove the job's files, record the outcome in ``OUTCOMES`` and leave ``ACTIVE``."""
        status = self.job.status
        self.job.cleanup()
        seconds = time.monotonic() - self.started
        if status.state == DONE:
            outcome = Outcome(DONE, f"done in {seconds:.0f} s", status.report, self.result_name, seconds)
        elif status.state == CANCELLED:
            outcome = Outcome(CANCELLED, "cancelled; the scene is unchanged", seconds=seconds)
        else:
            outcome = Outcome(ERROR, status.error or "the transfer failed", seconds=seconds)
        outcome.mode = self.result_mode
        if status.state == DONE and self.result_mode == "NEW" and self.result_name:
            source = self.source_object()
            name = source.name if source is not None else self.object_name
            outcome.message += f"; the original {name!r} is hidden (Alt+H shows it)"
        if ACTIVE.get(self.kind) is self:
            del ACTIVE[self.kind]
        OUTCOMES[self.kind] = outcome
        return outcome


def apply_result(context: bpy.types.Context, source: bpy.types.Object, path: str, mode: str) -> bpy.types.Object:
    """Add the result PLY as a new splat object beside ``source``, or in place, remembering the source's file. In
    Edit Mode (Select Part's) the source goes back to Object Mode first, keeping its selection: the new object is made
    by operators that need it."""
    from ..core.scene.ply import read_ply_arrays

    if source.mode != "OBJECT":
        with context.temp_override(active_object=source, object=source):
            bpy.ops.object.mode_set(mode="OBJECT")
    collection = source.users_collection[0] if source.users_collection else context.scene.collection
    arrays = read_ply_arrays(path)
    made = splats.scene_to_object(
        arrays,
        source.name + RESULT_SUFFIX,
        collection,
        source_path=splats.get_meta(source.data).get("source"),
        source_format="binary_little_endian",
        with_material=bool(source.data.materials),
    )
    if mode == "NEW":
        made[RESULT_OF] = source
        made.matrix_world = source.matrix_world.copy()
        for obj in context.view_layer.objects.selected:
            obj.select_set(False)
        if context.view_layer.objects.get(source.name) is not None:
            source.hide_set(True)  # the result takes its place on screen; Alt+H shows it again
        if made.visible_get():
            made.select_set(True)
        context.view_layer.objects.active = made
        return made
    old, cloud = source.data, made.data
    source.color = made.color[:]  # the restyled splats' mean colour (Solid mode's Object colour)
    bpy.data.objects.remove(made)
    source.data = cloud
    if old.users == 0:
        name = old.name
        bpy.data.pointclouds.remove(old)
        cloud.name = name
    return source
