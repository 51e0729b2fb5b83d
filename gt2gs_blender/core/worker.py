"""The worker process: one texture transfer (or orientation preview) described by a JSON job file.

``python -m gt2gs_blender.core.worker JOB.json`` runs it outside Blender (DESIGN §7: torch never
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
``{"event": "done", "output", "report"}``, ``{"event": "cancelled"}`` or
``{"event": "error", "message"}``. Exit status: 0 done, 1 internal error, 2 unusable input,
3 cancelled (a cancel file appeared or SIGTERM arrived), 4 out of memory (an allocation failed; the
message says what to lower). Outputs are written atomically and only on success, so a cancelled or
failed run leaves no result behind.
"""
from __future__ import annotations

import json
import os
import signal
import sys
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any, Callable

import numpy as np

from .atomic import atomic_write
from .errors import GT2GSError, InputFileError, out_of_memory_message

EXIT_DONE, EXIT_INTERNAL, EXIT_INPUT, EXIT_CANCELLED, EXIT_MEMORY = 0, 1, 2, 3, 4
KINDS = ("transfer", "preview")


@dataclass(frozen=True)
class JobSpec:
    """A parsed job file; paths are absolute or relative to the job file's folder."""

    kind: str
    input: Path
    texture: Path
    output: Path
    views: Path | int | None = None
    preset: str = "fast"
    config: dict[str, Any] | None = None
    region: Path | None = None
    report: Path | None = None
    preview_dir: Path | None = None
    cancel_file: Path | None = None
    preview_size: int = 256
    input_name: str | None = None
    views_name: str | None = None

    @classmethod
    def load(cls, path: str | os.PathLike) -> "JobSpec":
        """Read and check a job file; any problem is an InputFileError naming it."""
        path = Path(path)
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise InputFileError(path, f"cannot read the job file ({exc})") from None
        if not isinstance(data, dict):
            raise InputFileError(path, "the job file must hold a JSON object")
        missing = [key for key in ("kind", "input", "texture", "output") if not data.get(key)]
        if missing:
            raise InputFileError(path, f"the job lacks {', '.join(missing)}")
        if data["kind"] not in KINDS:
            raise InputFileError(path, f"unknown job kind {data['kind']!r}; expected one of {', '.join(KINDS)}")
        unknown = set(data) - {f for f in cls.__dataclass_fields__}
        if unknown:
            raise InputFileError(path, f"unknown job keys: {', '.join(sorted(unknown))}")
        base = path.parent

        def resolve(value: Any) -> Path | None:
            return None if value in (None, "") else base / Path(value)

        views = data.get("views")
        if isinstance(views, bool) or (views is not None and not isinstance(views, (int, str))):
            raise InputFileError(path, f"views must be a cameras file path or a count, got {views!r}")
        return cls(
            kind=data["kind"], input=resolve(data["input"]), texture=resolve(data["texture"]),
            output=resolve(data["output"]), views=resolve(views) if isinstance(views, str) else views,
            preset=data.get("preset") or "fast", config=dict(data.get("config") or {}),
            region=resolve(data.get("region")), report=resolve(data.get("report")),
            preview_dir=resolve(data.get("preview_dir")), cancel_file=resolve(data.get("cancel_file")),
            preview_size=int(data.get("preview_size") or 256),
            input_name=data.get("input_name") or None, views_name=data.get("views_name") or None,
        )


class Events:
    """Writes one JSON object per line to the event stream, flushed at once."""

    def __init__(self, stream: IO[str]) -> None:
        self.stream = stream

    def __call__(self, event: str, **fields: Any) -> None:
        self.stream.write(json.dumps({"event": event, **fields}) + "\n")
        self.stream.flush()


class CancelFlag:
    """True once the cancel file exists or SIGTERM arrived; polled by the transfer between steps."""

    def __init__(self, cancel_file: Path | None) -> None:
        self.cancel_file = cancel_file
        self.signalled = False

    def on_signal(self, signum: int, frame: Any) -> None:
        self.signalled = True

    def __call__(self) -> bool:
        return self.signalled or (self.cancel_file is not None and self.cancel_file.exists())


def write_png(path: Path, rgb: np.ndarray) -> None:
    """An (H,W,3) uint8 RGB image as a PNG, atomically."""
    import cv2

    ok, data = cv2.imencode(".png", np.ascontiguousarray(rgb[..., ::-1]))
    if not ok:
        raise OSError(f"{path}: could not encode the PNG")
    atomic_write(path, data.tobytes())


def load_region(path: Path) -> np.ndarray:
    """Gaussian indices from a .npy file (the transfer checks them against the scene)."""
    try:
        indices = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise InputFileError(path, f"cannot read the region mask ({exc})") from None
    if indices.ndim != 1 or indices.dtype.kind not in "iu":
        raise InputFileError(path, f"the region mask must be a 1-D array of integer indices, got {indices.dtype} "
                                   f"{indices.shape}")
    return indices.astype(np.int64)


def _texture(spec: JobSpec) -> np.ndarray | str:
    """The texture: an image file's path, or an (H,W,3) float array in [0,1] saved as .npy (Blender's pixels)."""
    if spec.texture.suffix.lower() != ".npy":
        return str(spec.texture)
    try:
        image = np.load(spec.texture, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise InputFileError(spec.texture, f"cannot read the texture pixels ({exc})") from None
    if image.ndim != 3 or image.shape[2] < 3 or not np.isfinite(image).all():
        raise InputFileError(spec.texture, f"texture pixels must be a finite (H, W, 3) array, got {image.shape}")
    return np.clip(image[..., :3], 0.0, 1.0).astype(np.float32)


def _views(spec: JobSpec):
    if isinstance(spec.views, Path):
        from .cameras import load_views

        return load_views(spec.views)
    return spec.views


def _config(spec: JobSpec):
    from .config import preset

    overrides = dict(spec.config or {})
    if isinstance(overrides.get("background"), list):
        overrides["background"] = tuple(overrides["background"])
    try:
        return preset(spec.preset, **overrides)
    except ValueError as exc:
        raise GT2GSError(f"job settings: {exc}") from None


def run_transfer(spec: JobSpec, events: Events, cancel: Callable[[], bool]) -> None:
    """Run the texture transfer and write the result PLY and the report (atomically)."""
    from .ply import read_ply, write_ply
    from .transfer import Progress, transfer
    from .visibility import require_visible

    scene = read_ply(spec.input)
    config = _config(spec)
    views = _views(spec)
    region = None if spec.region is None else load_region(spec.region)
    views_name = spec.views_name or (str(spec.views) if isinstance(spec.views, Path) else None)
    require_visible(scene, views, config, spec.input_name or spec.input, views_name, region)
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
        events("progress", stage=p.stage, step=p.step, total=p.total, fraction=p.fraction, eta_s=p.eta_s,
               message=p.message, preview=None if frame is None else str(frame))

    result = transfer(scene, _texture(spec), views, config, region=region, progress=progress, cancel=cancel)
    write_ply(spec.output, result.scene)
    if spec.report is not None:
        atomic_write(spec.report, json.dumps(result.report, indent=1, default=str))
    events("done", output=str(spec.output), report=None if spec.report is None else str(spec.report))


def run_preview(spec: JobSpec, events: Events) -> None:
    """Render the orientation preview of the first view as a PNG."""
    from .cameras import auto_views
    from .orientation_preview import orientation_preview
    from .ply import read_ply

    scene = read_ply(spec.input)
    config = _config(spec)
    views = _views(spec)
    camera = views[0] if isinstance(views, list) else auto_views(scene, views or config.n_views, width=spec.preview_size,
                                                                 height=spec.preview_size)[0]
    image = orientation_preview(scene, _texture(spec), camera, config.angle, size=spec.preview_size,
                                resolution=config.resolution, texture_height=config.texture_height,
                                n_groups=config.n_scales if config.depth_groups else 1, depth_ratio=config.depth_ratio,
                                background=config.background, backend=config.backend)
    write_png(spec.output, image)
    events("done", output=str(spec.output), report=None)


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
            run_preview(spec, events)
        return EXIT_DONE
    except GT2GSError as exc:
        if _is_cancelled(exc):
            events("cancelled")
            return EXIT_CANCELLED
        events("error", message=str(exc))
        return EXIT_INPUT
    except ImportError as exc:
        events("error", message=f"the Python package {exc.name or exc} is missing in the worker's Python: "
                                "install the dependencies (add-on preferences, or pip install -r requirements.txt)")
        return EXIT_INTERNAL
    except Exception as exc:
        traceback.print_exc()
        memory = out_of_memory_message(exc)
        if memory is not None:
            events("error", message=memory)
            return EXIT_MEMORY
        events("error", message=f"internal error: {type(exc).__name__}: {exc}")
        return EXIT_INTERNAL


def _is_cancelled(exc: BaseException) -> bool:
    """Whether ``exc`` is the transfer's Cancelled (only possible once the transfer module was loaded)."""
    module = sys.modules.get(f"{__package__}.transfer")
    return module is not None and isinstance(exc, module.Cancelled)


def main(argv: list[str] | None = None) -> int:
    """Entry point: the event stream takes the real stdout; anything else printed goes to stderr."""
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        sys.stderr.write("usage: python -m gt2gs_blender.core.worker JOB.json\n")
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
