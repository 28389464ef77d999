"""Everything that imports bpy: properties, operator, panel, extraction, writing, command line."""
from __future__ import annotations

import os
import threading

import bpy

from . import cli, gltf, live, operator, panel, props

_cli_handle = None


def _use_extension_warp_cache() -> None:
    """Installed as an extension, keep Warp's kernel cache in the extension's user folder."""
    package = __package__.rpartition(".")[0]  # bl_ext.<repo>.radiosity_baker
    if not package.startswith("bl_ext."):
        return  # a plain Python package: Warp's default cache (or the user's WARP_CACHE_PATH)
    path = bpy.utils.extension_path_user(package, path="warp_cache", create=True)
    # Warp reads this when it initialises (at the first bake); a user's own setting wins.
    os.environ.setdefault("WARP_CACHE_PATH", path)


def _compile_kernels_ahead() -> None:
    """Compile the Warp kernels in a background thread when the extension is enabled, so the first
    Bake press does not wait for it (~20 s on a 2-core CPU; later loads come from the cache). A
    bake meanwhile waits for the modules being compiled; a failure here only means the first bake
    compiles them."""
    def work():
        from ..core import device
        try:
            device.load_kernels(device.select("auto"))
        except Exception:  # noqa: BLE001 - the bake compiles (and reports) what is missing
            pass

    threading.Thread(target=work, name="radiosity_baker kernels", daemon=True).start()


def register() -> None:
    global _cli_handle
    _use_extension_warp_cache()
    _compile_kernels_ahead()
    props.register()
    gltf.register()
    live.register()
    for cls in operator.classes + panel.classes:
        bpy.utils.register_class(cls)
    try:
        _cli_handle = bpy.utils.register_cli_command("radiosity_baker", cli.main)
    except (AttributeError, RuntimeError, ValueError):
        _cli_handle = None  # the bpy module has no `-c`: `python -m radiosity_baker` serves instead


def unregister() -> None:
    global _cli_handle
    if _cli_handle is not None:
        bpy.utils.unregister_cli_command(_cli_handle)
        _cli_handle = None
    for cls in reversed(operator.classes + panel.classes):
        bpy.utils.unregister_class(cls)
    live.unregister()
    gltf.unregister()
    props.unregister()
