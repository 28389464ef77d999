"""Build the Blender extension zips: fetch the wheels the manifest lists, then run Blender's own
extension builder and validator (shipped inside the bpy module, no Blender binary needed).

    python -m radiosity_baker.addon.build [--fetch-wheels] [--platform linux-x64|windows-x64|macos-arm64|all]
                                          [--output DIR]

Wheels go to ``<repo>/wheels`` (never committed; files already there are kept), zips to ``DIR``
(default ``<repo>/dist``), one per platform, named ``radiosity_baker-<version>-<platform>.zip``.
This module imports neither bpy nor anything else from the package, so it runs in any Python ≥ 3.11
that has the bpy module installed (it only locates the builder script inside it).
"""
from __future__ import annotations

import argparse
import importlib.util
import re
import shutil
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
MANIFEST = REPO / "blender_manifest.toml"
PLATFORMS = ("linux-x64", "windows-x64", "macos-arm64")

# Blender platform -> a pip ``--platform`` tag family prefix and machine suffix of the wheel tags.
_WHEEL_PLATFORM = {"linux-x64": ("linux", "x86_64"), "windows-x64": ("win", "amd64"),
                   "macos-arm64": ("macosx", "arm64")}
# Heavy folders never worth copying into the staging tree (Blender's builder excludes the rest
# through the manifest's paths_exclude_pattern).
_STAGE_SKIP = (".git", ".venv", "wheels", "wheels-cache", "dist", "build", "out", "tests", "bench",
               "sample_blends", "examples", ".pytest_cache", "__pycache__", "*.egg-info")


class BuildError(RuntimeError):
    """The extension cannot be built; the message says what to do."""


def manifest_wheels() -> list[str]:
    """Wheel paths of the manifest, relative to the repository (``./wheels/<file>.whl``)."""
    with open(MANIFEST, "rb") as fh:
        return list(tomllib.load(fh).get("wheels", []))


def wheel_platforms(wheel: str) -> set[str]:
    """Blender platforms (e.g. ``linux-x64``) a wheel file name is built for."""
    tags = Path(wheel).stem.split("-")[-1].split(".")
    return {plat for plat, (family, machine) in _WHEEL_PLATFORM.items()
            if any(t.split("_")[0].rstrip("0123456789").endswith(family) and t.endswith(machine)
                   for t in tags)}


def wheels_for(platforms: tuple[str, ...]) -> list[str]:
    """Manifest wheel paths needed by any of ``platforms``."""
    return [w for w in manifest_wheels() if wheel_platforms(w) & set(platforms)]


def missing_wheels(platforms: tuple[str, ...]) -> list[str]:
    """Manifest wheel paths for ``platforms`` that are not yet in ``<repo>/wheels``."""
    return [w for w in wheels_for(platforms) if not (REPO / w).is_file()]


def fetch_wheels(platforms: tuple[str, ...]) -> None:
    """Download the exact wheel files the manifest lists for ``platforms`` into ``<repo>/wheels``.

    Existing files are kept. Raises BuildError when pip cannot fetch one (e.g. no network) or
    fetches a differently named file than the manifest lists.
    """
    for wheel in missing_wheels(platforms):
        target = REPO / wheel
        name, version, python_tag, abi_tag, platform_tags = target.stem.split("-")
        cmd = [sys.executable, "-m", "pip", "download", "--quiet", "--no-deps", "--only-binary=:all:",
               "--retries", "2", "--timeout", "30",
               "--dest", str(target.parent), f"{name}=={version}", "--abi", abi_tag]
        for tag in platform_tags.split("."):
            cmd += ["--platform", tag]
        # ``py3`` wheels install on any Python 3; pip still needs one version to resolve against.
        cmd += ["--python-version", "3.11" if python_tag == "py3" else f"3.{python_tag[3:]}"]
        print(f"fetching {target.name}", flush=True)
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0:
            raise BuildError(f"could not download {target.name} (is the network reachable?):\n"
                             f"{proc.stderr.strip()[-2000:]}")
        if not target.is_file():
            raise BuildError(f"pip fetched something other than {target.name} into {target.parent}; "
                             "update the wheel names in blender_manifest.toml")


def builder_script() -> Path:
    """Blender's extension CLI script ``blender_ext.py`` inside the installed bpy module."""
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        raise BuildError("the bpy module is not installed: pip install bpy (it carries Blender's builder)")
    found = sorted(Path(spec.submodule_search_locations[0]).glob(
        "*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
    if not found:
        raise BuildError("blender_ext.py not found inside the bpy module")
    return found[-1]


def _run_builder(*args: str) -> None:
    proc = subprocess.run([sys.executable, str(builder_script()), *args], capture_output=True, text=True)
    sys.stdout.write(proc.stdout)
    if proc.returncode != 0:
        raise BuildError(f"blender_ext {args[0]} failed:\n{proc.stdout[-2000:]}{proc.stderr[-2000:]}")


def _stage(platforms: tuple[str, ...], stage: Path) -> None:
    """Copy the extension source to ``stage`` with a manifest restricted to ``platforms``.

    Blender's builder wants every wheel of every declared platform present, so building one
    platform needs a manifest that declares only that one.
    """
    shutil.copytree(REPO, stage, ignore=shutil.ignore_patterns(*_STAGE_SKIP))
    text = MANIFEST.read_text(encoding="utf-8")
    wheels = wheels_for(platforms)
    text = re.sub(r"^platforms = \[.*?\]", "platforms = [" + ", ".join(f'"{p}"' for p in platforms) + "]",
                  text, count=1, flags=re.M | re.S)
    text = re.sub(r"^wheels = \[.*?\]", "wheels = [\n" + "".join(f'  "{w}",\n' for w in wheels) + "]",
                  text, count=1, flags=re.M | re.S)
    (stage / MANIFEST.name).write_text(text, encoding="utf-8")
    (stage / "wheels").mkdir()
    for wheel in wheels:
        (stage / wheel).symlink_to(REPO / wheel)


def build(platforms: tuple[str, ...], output: Path) -> list[Path]:
    """Validate the manifest, build one zip per platform into ``output``, validate each zip.

    The wheels must already be in ``<repo>/wheels`` (see fetch_wheels). Returns the zip paths.
    """
    missing = missing_wheels(platforms)
    if missing:
        raise BuildError("missing wheels: " + ", ".join(Path(w).name for w in missing)
                         + "\nfetch them first: python -m radiosity_baker.addon.build --fetch-wheels"
                         " (or run `bash .ci/setup`)")
    _run_builder("validate", str(REPO))
    output.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="rb_stage_") as tmp:
        stage = Path(tmp) / "radiosity_baker"
        _stage(platforms, stage)
        _run_builder("build", "--source-dir", str(stage), "--output-dir", str(output.resolve()),
                     "--split-platforms")
    version = tomllib.loads(MANIFEST.read_text(encoding="utf-8"))["version"]
    zips = [output / f"radiosity_baker-{version}-{p.replace('-', '_')}.zip" for p in platforms]
    for zip_path in zips:
        _run_builder("validate", str(zip_path))
    return zips


def main(argv: list[str] | None = None) -> int:
    """Command line entry (``build-extension``); returns the exit code."""
    parser = argparse.ArgumentParser(prog="radiosity_baker build-extension",
                                     description="Build the Blender extension zips.")
    parser.add_argument("--fetch-wheels", action="store_true",
                        help="download the manifest's wheels into ./wheels first (needs network)")
    parser.add_argument("--platform", choices=(*PLATFORMS, "all"), default="all")
    parser.add_argument("--output", type=Path, default=REPO / "dist", help="folder for the zips")
    parser.add_argument("--fetch-only", action="store_true", help="fetch the wheels, build nothing")
    args = parser.parse_args(argv)
    platforms = PLATFORMS if args.platform == "all" else (args.platform,)
    try:
        if args.fetch_wheels or args.fetch_only:
            fetch_wheels(platforms)
        if not args.fetch_only:
            for zip_path in build(platforms, args.output):
                print(f"built {zip_path} ({zip_path.stat().st_size / 1e6:.1f} MB)")
    except BuildError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
