"""Command line: ``python -m radiosity_baker bake FILE.blend [options]`` (bpy module) and
``blender -c radiosity_baker bake FILE.blend [options]`` (register_cli_command); ``export FILE.blend
OUT.glb`` writes a baked file's scene as glTF with its lightmaps.

Settings start from core ``Settings`` defaults; the options below override them. The input file
is never written: results reach disk only through ``--save`` (which may name the input on purpose).
Every output is written under a temporary name beside its target, checked, and moved into place
with the others at the end, so a failed bake or a full disk leaves the targets as they were.
Exit status: 0 done, 1 the bake failed, 2 bad arguments or unreadable input / unwritable output,
130 cancelled (Ctrl-C), 143 stopped by SIGTERM (cleaned up as after Ctrl-C).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import signal
import sys
import threading
import time
import traceback
from contextlib import contextmanager
from dataclasses import fields
from pathlib import Path

import bpy

from ..core import BakeCancelled, Settings, device
from ..core import settings as core_settings
from ..core.errors import SettingsError
from ..core.lightmap import files
from . import gltf, lightmap
from .job import USER_ERRORS, BakeJob
from .outputs import OutputError, Staging, check_file, same_file

PROG = "radiosity_baker"
_ROOT = Path(__file__).resolve().parent.parent  # the repository / extension folder


class UsageError(Exception):
    """Bad arguments, unreadable input or unwritable output (exit status 2)."""


class _Parser(argparse.ArgumentParser):
    # argparse exits the process on errors, which would close Blender under `blender -c`.
    def error(self, message):
        raise UsageError(message)


def _bounded(kind, low, high):
    """An argparse type: ``kind`` (int or float) within [low, high] (None: open)."""
    def convert(text: str):
        value = kind(text)
        if low is not None and not value >= low:
            raise argparse.ArgumentTypeError(f"must be at least {low:g}, not {value}")
        if high is not None and not value <= high:
            raise argparse.ArgumentTypeError(f"must be at most {high:g}, not {value}")
        return value
    return convert


def _add_setting(group, f) -> None:
    """The command-line option of Settings field ``f``, from its metadata (core.settings.Option)."""
    opt = core_settings.option(f.name)
    flag = core_settings.flag(f.name)
    text = core_settings.describe(f.name).replace("%", "%%")
    if isinstance(f.default, bool):
        group.add_argument(flag, dest=f.name, action="store_true", help=text)
        return
    kwargs = dict(dest=f.name, default=f.default, help=text + " (default: %(default)s)",
                  metavar=core_settings.metavar(f.name))
    if opt.choices is not None:
        kwargs["choices"] = opt.choices
        if f.name == "hookup":  # `--hookup` alone asks for the node pair
            kwargs["nargs"], kwargs["const"] = "?", "node"
    elif isinstance(f.default, (int, float)):
        kwargs["type"] = _bounded(type(f.default), opt.low, opt.high)
    group.add_argument(flag, **kwargs)


def _parser() -> argparse.ArgumentParser:
    parser = _Parser(prog=PROG, description="Bake global illumination into Blender meshes. "
                                            "(`build-extension --help`: build the extension zips.)")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    bake = commands.add_parser("bake", help="bake FILE.blend (the file itself is left unchanged)")
    bake.add_argument("blend", metavar="FILE.blend", help="the .blend file to bake")
    bake.add_argument("--objects", metavar="A,B", type=lambda s: [n for n in s.split(",") if n],
                      help="names of the objects to write (default: every mesh); all objects "
                           "still cast and reflect light")
    groups = {"solver": bake.add_argument_group("light transport"),
              "output": bake.add_argument_group("what is baked and written"),
              "lightmap": bake.add_argument_group("lightmaps (--target lightmap or both)")}
    for f in fields(Settings):
        _add_setting(groups[core_settings.option(f.name).group], f)
    bake.add_argument("--save", metavar="OUT.blend", type=Path,
                      help="save the baked scene here (nothing is saved without it)")
    bake.add_argument("--report", metavar="REPORT.json", type=Path,
                      help="write timings, counts, device, settings and versions as JSON")
    bake.add_argument("--preview", metavar="OUT.png", type=Path,
                      help="render the camera view of the baked attribute to a PNG (Cycles)")
    bake.add_argument("--gltf", metavar="OUT.glb", type=Path,
                      help="export the baked scene as a GLB with its lightmaps (MOZ_lightmap, "
                           "encoded as --lightmap-format says) and the color attribute (COLOR_0)")
    export = commands.add_parser("export", help="export FILE.blend as a GLB with the lightmaps "
                                                "of its baked objects (the file is left unchanged)")
    export.add_argument("blend", metavar="FILE.blend", help="a .blend file baked with lightmaps")
    export.add_argument("gltf", metavar="OUT.glb", type=Path, help="the GLB file to write")
    export.add_argument("--lightmap-format", dest="lightmap_format", choices=gltf.ENCODINGS,
                        default="rgbm", help="how the lightmap textures are stored "
                                             "(default: %(default)s)")
    export.add_argument("--color-attribute", metavar="NAME",
                        help="also export this color attribute as COLOR_0")
    export.add_argument("--no-lightmaps", action="store_true",
                        help="leave the lightmaps out (the Lightmap UV maps stay)")
    warm = commands.add_parser("compile-kernels", help="compile the Warp kernels now (kept in "
                                                       "Warp's cache), so the first bake is not slow")
    warm.add_argument("--device", choices=core_settings.DEVICES, default="auto")
    return parser


def main(argv: list[str]) -> int:
    """Run the command line with ``argv`` (without the program name); returns the exit status.

    ``build-extension …`` is handed to ``addon.build`` (the extension zips).
    """
    if argv[:1] == ["build-extension"]:
        from . import build
        try:
            return build.main(argv[1:])
        except SystemExit as exc:  # its argparse: --help or bad arguments; keep Blender open
            return exc.code if isinstance(exc.code, int) else 2
    try:
        args = _parser().parse_args(argv)
    except UsageError as exc:
        return _error(str(exc), 2)
    except SystemExit as exc:  # --help
        return exc.code or 0
    try:
        run = {"compile-kernels": _compile_kernels, "export": _export}.get(args.command, _bake)
        return run(args)
    except (UsageError, SettingsError, OutputError) as exc:
        return _error(str(exc), 2)
    except Terminated as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)  # outputs were left as they were
        return 143
    except (BakeCancelled, KeyboardInterrupt):
        print(f"{PROG}: bake cancelled", file=sys.stderr)  # outputs were left as they were
        return 130
    except USER_ERRORS as exc:
        return _error(str(exc), 1)
    except Exception as exc:  # noqa: BLE001 - a bug: its traceback, then one line; Blender stays open
        traceback.print_exc()
        return _error(f"internal error: {type(exc).__name__}: {exc}", 1)


def _compile_kernels(args) -> int:
    from ..core import device

    dev = device.select(args.device)
    t0 = time.perf_counter()
    compiled = device.load_kernels(dev)
    print(f"{PROG}: {compiled} of {len(device.KERNEL_MODULES)} kernel modules compiled for "
          f"{dev.description} in {time.perf_counter() - t0:.1f} s (the others were cached)")
    return 0


def _bake(args) -> int:
    settings = Settings(**{f.name: getattr(args, f.name) for f in fields(Settings)})
    settings.validate()
    if args.objects is not None and not args.objects:
        raise UsageError("--objects names no object")
    blend = Path(args.blend).resolve()
    if not blend.is_file():
        raise UsageError(f"no such .blend file: {args.blend}")
    given = {name: getattr(args, name) for name in ("save", "report", "preview", "gltf")
             if getattr(args, name) is not None}
    _check_distinct(Path(args.blend), given)
    outputs = {name: path.resolve() for name, path in given.items()}
    if "gltf" in outputs:
        _check_glb(outputs["gltf"])
        if settings.frame_list() is not None and "lightmap" in settings.targets:
            raise UsageError(f"--gltf with --frames and --target {settings.target}: an "
                             f"animation's lightmaps are image sequences and glTF holds one image "
                             f"per lightmap; bake one frame (--frames left out) for the GLB")
    for path in outputs.values():
        check_file(path)
    # --device cuda without a GPU: a bad argument, said now; else the one line naming the device
    print(f"{PROG}: baking on {device.select(settings.device).description}", flush=True)
    try:
        bpy.ops.wm.open_mainfile(filepath=str(blend))
    except RuntimeError as exc:
        raise UsageError(f"cannot open {blend}: {_first_line(exc)}") from None
    if settings.target != "vertex_colors":  # the folder is known once the file is open ('//')
        _check_lightmap_folder(lightmap.output_folder(settings), blend, outputs)

    told = set()

    def warn(message: str) -> None:
        if message not in told:
            told.add(message)
            print(f"{PROG}: warning: {message}", file=sys.stderr, flush=True)

    job = BakeJob(settings, args.objects, progress=_Progress(), notify=warn)
    with _ctrl_c_stops(job), Staging() as staging:
        for message in job.run_sync(bpy.context):
            warn(message)
        if "save" in outputs:
            _save(staging, outputs["save"])
        if "gltf" in outputs:
            _write_gltf(staging, outputs["gltf"], settings.lightmap_format,
                        settings.attribute if "vertices" in settings.targets else None)
        if "preview" in outputs:  # after saving: the file never holds the preview's temporary data
            from .preview import render_preview
            with staging.writing(outputs["preview"]) as temp:
                render_preview(bpy.context.scene, settings.attribute, temp)
                files.verify(temp)
        if "report" in outputs:
            report = _report(job, settings, str(blend), {k: str(v) for k, v in outputs.items()})
            with staging.writing(outputs["report"]) as temp:
                _write_verified(temp, (json.dumps(report, indent=2) + "\n").encode())
        if job.stopping:  # Ctrl-C after the bake's last check: still nothing is written
            raise BakeCancelled("bake cancelled")
        staging.commit()
    result = job.result
    print(f"{PROG}: baked {result.counts.get('elements', 0)} elements on {result.device} "
          f"in {job.seconds:.2f} s")
    return 0


class Terminated(BakeCancelled):
    """The bake stopped because the process was sent SIGTERM (exit status 143)."""


@contextmanager
def _ctrl_c_stops(job: BakeJob):
    """The first Ctrl-C (SIGINT) asks ``job`` to stop at its next check, which raises
    BakeCancelled; a second one interrupts at once. A KeyboardInterrupt raised wherever the main
    thread happens to be can land in a finaliser (a Warp array's ``__del__``), where Python prints
    and drops it, and the bake then ran to its end and exited 0 (seen in CI). SIGTERM stops the
    bake the same way (its temporary files and xatlas workers cleaned up) and raises Terminated; a
    second SIGTERM ends the process at once. Where SIGINT is not Python's default handler
    (Blender's own, under ``blender -c``), nothing changes."""
    if (threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler):
        yield
        return
    terminated = []

    def stop(signum, frame):
        job.stop_soon()
        signal.signal(signal.SIGINT, signal.default_int_handler)

    def term(signum, frame):
        terminated.append(signum)
        job.stop_soon()
        signal.signal(signal.SIGTERM, signal.SIG_DFL)

    handle_term = signal.getsignal(signal.SIGTERM) == signal.SIG_DFL
    signal.signal(signal.SIGINT, stop)
    if handle_term:
        signal.signal(signal.SIGTERM, term)
    try:
        yield
    except BakeCancelled:
        if terminated:
            raise Terminated("bake stopped (SIGTERM)") from None
        raise
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
        if handle_term:
            signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _check_distinct(blend: Path, outputs: dict) -> None:
    """Raise UsageError when an output ({option name: path as given}) names the input ``blend``
    (only ``--save`` may: Blender's ``.blend1`` keeps the original) or the same file as another
    output. The message names the paths as the user gave them."""
    for name, path in outputs.items():
        if name != "save" and same_file(path, blend):
            raise UsageError(f"--{name} {path} names the input file {blend}: it would be "
                             f"overwritten; choose another path")
    names = list(outputs)
    for i, first in enumerate(names):
        for second in names[i + 1:]:
            if same_file(outputs[first], outputs[second]):
                raise UsageError(f"--{first} and --{second} both name {outputs[first]}: choose "
                                 f"different files")


def _check_lightmap_folder(folder: Path, blend: Path, outputs: dict) -> None:
    """Raise UsageError when the input or an output ({option name: path}) is a file the lightmaps
    written into ``folder`` may replace (``lightmap.may_replace``)."""
    for name, path in {"input": blend, **outputs}.items():
        if lightmap.may_replace(folder, path):
            what = "the input file" if name == "input" else f"--{name}"
            raise UsageError(f"{what} {path} lies in the lightmap folder {folder} under a name "
                             f"the lightmap files take: choose another --output or file name")


def _export(args) -> int:
    blend = Path(args.blend).resolve()
    if not blend.is_file():
        raise UsageError(f"no such .blend file: {args.blend}")
    target = args.gltf.resolve()
    _check_glb(target)
    check_file(target)
    try:
        bpy.ops.wm.open_mainfile(filepath=str(blend))
    except RuntimeError as exc:
        raise UsageError(f"cannot open {blend}: {_first_line(exc)}") from None
    _check_baked(blend, args.color_attribute)
    with Staging() as staging:
        _write_gltf(staging, target, args.lightmap_format, args.color_attribute,
                    lightmaps=not args.no_lightmaps)
        staging.commit()
    print(f"{PROG}: exported {target}")
    return 0


def _check_baked(blend: Path, color_attribute) -> None:
    """Raise UsageError unless the open file holds what ``export`` is asked to carry: the color
    attribute named (on some mesh of the scene), or, without one, meshes a bake lightmapped (their
    lightmaps, or with ``--no-lightmaps`` their ``Lightmap`` UV maps)."""
    meshes = [ob for ob in bpy.context.scene.objects if ob.type == "MESH"]
    if color_attribute:
        if not any(ob.data.color_attributes.get(color_attribute) is not None for ob in meshes):
            raise UsageError(f"--color-attribute {color_attribute}: no mesh of {blend.name} has a "
                             f"color attribute of that name (a bake writes the one --attribute "
                             f"names, 'Lighting' by default); bake it first or name another")
    elif not any(gltf.lightmap_image(ob) is not None for ob in meshes):
        raise UsageError(f"{blend.name} holds nothing baked to export: no mesh has a lightmap from "
                         f"a bake, and no --color-attribute was named; bake it first (bake "
                         f"{blend.name} --target lightmap --save OUT.blend) or name a color attribute")


def _check_glb(path: Path) -> None:
    if path.suffix.lower() != ".glb":
        raise UsageError(f"the glTF output must be a .glb file, not {path.name}")


def _write_gltf(staging: Staging, target: Path, encoding: str, color_attribute,
                lightmaps: bool = True) -> None:
    """Export the open scene to the GLB ``target`` through Blender's glTF exporter with our
    MOZ_lightmap extension (``addon.gltf``) and, when named, ``color_attribute`` as COLOR_0."""
    colors = dict(export_vertex_color="NAME", export_vertex_color_name=color_attribute) \
        if color_attribute else dict(export_vertex_color="NONE")
    with staging.writing(target) as temp, gltf.found_by_gltf(encoding, lightmaps):
        try:
            bpy.ops.export_scene.gltf(filepath=str(temp), export_format="GLB",
                                      export_texcoords=True, export_cameras=True, **colors)
        except RuntimeError as exc:  # the operator's error report (our hooks' failures too)
            reason = _first_line(exc).removeprefix("Error: ")
            raise OutputError(f"cannot write {target}: {reason}") from None


# A whole .blend file ends with an ENDB block (its code, then a header of zeros: 16 bytes or more)
# or, compressed (zstd, as Blender writes by default), with the magic number of its seek table.
_BLEND_START, _ZSTD_START, _ZSTD_END = b"BLENDER", b"\x28\xb5\x2f\xfd", b"\xb1\xea\x92\x8f"


def _save(staging: Staging, target: Path) -> None:
    """Save the open file as a copy at ``target`` (the session keeps its own path) through a
    temporary file that is checked before it replaces ``target``; the file replaced is kept as
    ``target1`` … as Blender's Save Versions preference says."""
    with staging.writing(target, versions=bpy.context.preferences.filepaths.save_version) as temp:
        try:
            bpy.ops.wm.save_as_mainfile(filepath=str(temp), copy=True)
        except RuntimeError as exc:
            raise OutputError(f"cannot save {target}: {_first_line(exc)}") from None
        if not _whole_blend(temp):  # Blender reports success even when the disk filled up
            raise OutputError(f"cannot save {target}: the file written is incomplete "
                              f"(is the disk full?)")


def _whole_blend(path: Path) -> bool:
    """Whether ``path`` is a whole .blend file: its first and last bytes, then a read of its block
    list (what Blender does to link from it, without touching the open file)."""
    size = path.stat().st_size
    with open(path, "rb") as f:
        head = f.read(len(_BLEND_START))
        f.seek(max(0, size - 64))
        tail = f.read()
    if head == _BLEND_START:
        end = tail.rfind(b"ENDB")
        whole = end >= 0 and len(tail) - end - 4 >= 16 and not tail[end + 4:].strip(b"\0")
    else:
        whole = head.startswith(_ZSTD_START) and tail.endswith(_ZSTD_END)
    if not whole:
        return False
    try:
        with bpy.data.libraries.load(str(path)):
            pass
    except OSError:
        return False
    return True


def _write_verified(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path``, flushed to the disk, and check its size (OSError on failure)."""
    with open(path, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    if path.stat().st_size != len(data):
        raise OSError(f"{path.stat().st_size} of {len(data)} bytes written")


def _first_line(exc: BaseException) -> str:
    return str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__


class _Progress:
    """Prints ``stage NN%`` lines to stdout: on each new stage and at most once a second."""

    def __init__(self, interval: float = 1.0):
        self._interval = interval
        self._stage = None
        self._last = 0.0

    def __call__(self, stage: str, fraction: float) -> None:
        now = time.monotonic()
        if stage == self._stage and now - self._last < self._interval:
            return
        self._stage, self._last = stage, now
        print(f"{PROG}: {stage} {fraction:4.0%}", flush=True)


def _report(job: BakeJob, settings: Settings, blend: str, outputs: dict) -> dict:
    """The --report JSON: versions, device, settings, seconds per stage, counts, memory, warnings."""
    import numpy
    import warp

    result = job.result
    return {
        "blender_version": bpy.app.version_string,
        "radiosity_baker_version": package_version(),
        "python_version": platform.python_version(),
        "numpy_version": numpy.__version__,
        "warp_version": warp.__version__,
        "device": result.device,
        "settings": settings.as_dict(),
        "seconds": {"total": job.seconds, **job.timings},
        "counts": result.counts,
        "peak_memory_bytes": result.peak_memory_bytes,
        "warnings": job.warnings,
        "frames": job.frames,
        "input": blend,
        "outputs": outputs,
        "lightmaps": {page: str(path) for page, path in job.files.items()},
    }


def package_version() -> str:
    """Version from blender_manifest.toml, else pyproject.toml, else the installed metadata."""
    import tomllib

    for name, keys in (("blender_manifest.toml", ("version",)),
                       ("pyproject.toml", ("project", "version"))):
        try:
            data = tomllib.loads((_ROOT / name).read_text())
        except (OSError, tomllib.TOMLDecodeError):
            continue
        for key in keys:
            data = data.get(key, {}) if isinstance(data, dict) else {}
        if isinstance(data, str):
            return data
    from importlib import metadata
    try:
        return metadata.version("radiosity_baker")
    except metadata.PackageNotFoundError:
        return "unknown"


def _error(message: str, status: int) -> int:
    print(f"{PROG}: error: {message}", file=sys.stderr)
    return status
