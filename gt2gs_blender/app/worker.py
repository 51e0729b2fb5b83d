"""The worker process: one texture transfer (or orientation preview) described by a JSON job file.

``python -m gt2gs_blender.app.worker JOB.json`` runs it outside Blender (docs/architecture.md, "The worker": torch never
loads into Blender, a crash cannot take Blender down, Cancel can always stop it). The job file:

    {"kind": "transfer" | "preview", "input": "scene.ply", "texture": "texture.png" (or pixels.npy),
     "views": "cameras.json" | 8 | null, "preset": "fast", "config": {TransferConfig overrides},
     "region": "mask.npy" | null, "output": "out.ply" (preview: out.png), "report": "report.json",
     "preview_dir": "previews", "cancel_file": "cancel", "preview_size": 256,
     "input_name": "object 'Donut'", "views_name": "the scene's cameras"}

``input_name`` / ``views_name`` are what error messages call the input and the views when the files
are a caller's temporary exports (default: the file paths).

Events go to stdout as JSON lines (stray prints of libraries are sent to stderr instead):
``{"event": "progress", "stage", "step", "total", "fraction", "eta_s", "message", "preview"}`` (the
preview is the path of a PNG frame, written atomically, or null), then exactly one of
``{"event": "done", "output", "report"}`` (a preview adds ``"splats"``, what the run will start from,
``"scene_splats"``, the input's, ``"views"``, the run's [count, width, height], and ``"resolution"``, the
*Resolution* asked for: a dense capture is worked larger), ``{"event": "cancelled"}`` or
``{"event": "error", "message"}``. Exit status: 0 done, 1 internal error, 2 unusable input,
3 cancelled (a cancel file appeared or SIGTERM arrived), 4 out of memory (an allocation failed; the
message says what to lower). Outputs are written atomically and only on success, so a cancelled or
failed run leaves no result behind.
"""

from __future__ import annotations

import os
import signal
import sys
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..core.errors import GT2GSError, out_of_memory_message
from ..core.progress import Cancelled, Progress, Tracker
from .protocol import EXIT_CANCELLED, EXIT_DONE, EXIT_INPUT, EXIT_INTERNAL, EXIT_MEMORY, Event, Events, JobSpec

if TYPE_CHECKING:
    from ..core.transfer.config import TransferConfig

COMPILE_STAGE = "compile"
"""The stage that builds the CPU rasterizer before a run's first render (only when it is not built yet)."""


class CancelFlag:
    """True once the cancel file exists or SIGTERM arrived; polled by the transfer between steps."""

    def __init__(self, cancel_file: Path | None) -> None:
        self.cancel_file = cancel_file
        self.signalled = False

    def on_signal(self, signum: int, frame: Any) -> None:
        self.signalled = True

    def __call__(self) -> bool:
        return self.signalled or (self.cancel_file is not None and self.cancel_file.exists())


def _views(spec: JobSpec):
    if isinstance(spec.views, Path):
        from ..core.cameras.files import load_views

        return load_views(spec.views)
    return spec.views


def _config(spec: JobSpec):
    from ..core.transfer.presets import preset

    overrides = dict(spec.config or {})
    if isinstance(overrides.get("background"), list):
        overrides["background"] = tuple(overrides["background"])
    try:
        return preset(spec.preset, **overrides)
    except ValueError as exc:
        raise GT2GSError(f"job settings: {exc}") from None


def _send(events: Events, p: Progress, frame: Path | None = None) -> None:
    """One progress event (``frame``: the PNG of its preview image, if any)."""
    events(
        Event.PROGRESS,
        stage=p.stage,
        step=p.step,
        total=p.total,
        fraction=p.fraction,
        eta_s=p.eta_s,
        message=p.message,
        preview=None if frame is None else str(frame),
    )


def _prepare_kernel(config: TransferConfig, progress: Callable[[Progress], None], cancel: Callable[[], bool]) -> None:
    """Build the CPU rasterizer first, as a ``compile`` stage, when the run will use it and it is not built
    yet (once per kernel version: the UI shows a stage, not a run stuck at 0 %): the C++ kernel where a
    compiler is found, else its numba port (JIT-compiled and cached)."""
    from ..core.device import resolve_device
    from ..core.render import cpu_backend, kernel_cache, numba_backend
    from .machine import compiler_found

    if config.backend not in ("auto", "cpu", "numba") or resolve_device(config.device).type != "cpu":
        return
    if config.backend != "numba" and (kernel_cache.is_built() or compiler_found() is not None):
        if not kernel_cache.is_built():
            message = "compiling the CPU rasterizer (first run only, about a minute)"
            _compile_stage(progress, cancel, message, cpu_backend.load_kernel)
        return
    if numba_backend.installed() and not numba_backend.is_compiled():
        message = "compiling the CPU rasterizer with numba (no C++ compiler here; first run only, about a minute)"
        _compile_stage(progress, cancel, message, numba_backend.warm_up)


def _compile_stage(
    progress: Callable[[Progress], None], cancel: Callable[[], bool], message: str, build: Callable[[], object]
) -> None:
    """Run ``build`` as the ``compile`` stage, telling ``message``."""
    tracker = Tracker(progress, cancel, {COMPILE_STAGE: 1.0}, what="compile")
    tracker.begin(COMPILE_STAGE)
    tracker.tell(0, 1, message)
    build()
    tracker.end()


def run_transfer(spec: JobSpec, events: Events, cancel: Callable[[], bool]) -> None:
    """Run the texture transfer (``jobs.run_transfer``), sending progress and preview frames as events."""
    from ..core.scene.files import read_scene
    from .images import write_png
    from .jobs import load_region, read_texture, run_transfer

    scene = read_scene(spec.input)
    texture, config, views = read_texture(spec.texture), _config(spec), _views(spec)
    region = None if spec.region is None else load_region(spec.region, len(scene))
    views_name = spec.views_name or (str(spec.views) if isinstance(spec.views, Path) else None)
    if spec.preview_dir is not None:
        spec.preview_dir.mkdir(parents=True, exist_ok=True)
    frames = 0

    def progress(p: Progress) -> None:
        nonlocal frames
        frame = None
        if p.preview is not None and spec.preview_dir is not None:
            frame = spec.preview_dir / f"preview_{frames:04d}.png"
            write_png(frame, p.preview)
            frames += 1
        _send(events, p, frame)

    _prepare_kernel(config, progress, cancel)
    run_transfer(
        scene,
        texture,
        views,
        config,
        spec.output,
        report=spec.report,
        region=region,
        progress=progress,
        cancel=cancel,
        scene_name=spec.input_name or spec.input,
        views_name=views_name,
    )
    events(Event.DONE, output=str(spec.output), report=None if spec.report is None else str(spec.report))


def run_preview(spec: JobSpec, events: Events, cancel: Callable[[], bool]) -> None:
    """Render the preview of the first view (what the run will lay on the scene, or on its region) as a PNG,
    from the run's own plan."""
    from ..core.scene.files import read_scene
    from ..core.transfer.orientation_preview import preview
    from .images import write_png
    from .jobs import load_region, read_texture

    scene = read_scene(spec.input)
    config = _config(spec)
    region = None if spec.region is None else load_region(spec.region, len(scene))
    _prepare_kernel(config, lambda p: _send(events, p), cancel)
    shown = preview(scene, read_texture(spec.texture), _views(spec), config, size=spec.preview_size, region=region)
    write_png(spec.output, shown.image)
    events(
        Event.DONE,
        output=str(spec.output),
        report=None,
        splats=shown.splats,
        scene_splats=len(scene),
        views=[shown.views, *shown.size],
        resolution=config.resolution,
    )


def run(job_file: str | os.PathLike, events: Events) -> int:
    """Run one job; report the outcome as an event and return the exit status."""
    try:
        spec = JobSpec.load(job_file)
        cancel = CancelFlag(spec.cancel_file)
        if hasattr(signal, "SIGTERM"):
            signal.signal(signal.SIGTERM, cancel.on_signal)
        if spec.kind == "transfer":
            run_transfer(spec, events, cancel)
        else:
            run_preview(spec, events, cancel)
        return EXIT_DONE
    except GT2GSError as exc:
        if isinstance(exc, Cancelled):
            events(Event.CANCELLED)
            return EXIT_CANCELLED
        events(Event.ERROR, message=str(exc))
        return EXIT_INPUT
    except ImportError as exc:
        events(
            Event.ERROR,
            message=f"the Python package {exc.name or exc} is missing in the worker's Python: "
            "install the dependencies (add-on preferences, or pip install -r requirements.txt)",
        )
        return EXIT_INTERNAL
    except Exception as exc:
        traceback.print_exc()
        memory = out_of_memory_message(exc)
        if memory is not None:
            events(Event.ERROR, message=memory)
            return EXIT_MEMORY
        events(Event.ERROR, message=f"internal error: {type(exc).__name__}: {exc}")
        return EXIT_INTERNAL


def main(argv: list[str] | None = None) -> int:
    """Entry point: the event stream takes the real stdout; anything else printed goes to stderr."""
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        sys.stderr.write("usage: python -m gt2gs_blender.app.worker JOB.json\n")
        return EXIT_INPUT
    stream = os.fdopen(os.dup(sys.stdout.fileno()), "w", encoding="utf-8")
    sys.stdout.flush()
    os.dup2(sys.stderr.fileno(), sys.stdout.fileno())
    try:
        return run(args[0], Events(stream))
    finally:
        stream.close()


if __name__ == "__main__":
    sys.exit(main())
