"""Build the linux-x64 extension zip, install it into a fresh Blender user folder and bake with the
INSTALLED copy (``bl_ext.user_default.radiosity_baker``), not the source tree.

The install and bake run in a child Python (this file run as a script): the test process has
already registered the source tree under the same operator ids, and a child starts from a clean
Blender. The wheels must have been fetched by the README set-up command (no network in tests).
"""
import json
import math
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
REPO_NAME = "user_default"  # the user repository Blender's factory preferences come with
ATTRIBUTE = "InstalledBake"
SUN_STRENGTH = 3.0  # W/m², straight down onto a lone plane: lighting S/π everywhere


def _build_linux_zip(output: Path) -> Path:
    sys.path.insert(0, str(REPO / "addon"))
    try:
        import build  # addon/build.py imports nothing from the package: loadable on its own
    finally:
        sys.path.pop(0)
    missing = build.missing_wheels(("linux-x64",))
    if missing:
        pytest.fail("wheels missing from ./wheels: " + ", ".join(Path(w).name for w in missing)
                    + "\nrun the README set-up command first: bash .ci/setup")
    (zip_path,) = build.build(("linux-x64",), output)
    return zip_path


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="builds the linux-x64 package")
def test_installed_extension_bakes(tmp_path):
    zip_path = _build_linux_zip(tmp_path / "dist")
    # only what runs in Blender: no tests, benchmarks, the Cycles harness or the engine examples
    names = zipfile.ZipFile(zip_path).namelist()
    sources = {n for n in names if n.endswith(".py")}
    assert "core/pipeline.py" in sources and "addon/writers.py" in sources
    assert not [n for n in names if n.startswith("examples/")]  # three.js: 24 MB after npm ci
    assert not [n for n in sources if n.split("/")[0] in ("tests", "bench")
                or Path(n).stem in ("cycles_ref", "compare", "metrics", "cycles", "harness")]
    user = tmp_path / "blender_user"
    env = {**os.environ, "BLENDER_USER_RESOURCES": str(user), "RB_INSTALL_REPORT": str(tmp_path / "r.json")}
    env.pop("WARP_CACHE_PATH", None)
    proc = subprocess.run([sys.executable, __file__, str(zip_path)], env=env, capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, f"child failed:\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    report = json.loads((tmp_path / "r.json").read_text())
    # The bake ran through the installed copy, from the user folder, whose bundled wheels Blender
    # installed there too.
    assert report["module"] == f"bl_ext.{REPO_NAME}.radiosity_baker"
    assert Path(report["module_file"]).is_relative_to(user)
    assert list(user.glob("**/site-packages/warp_lang-1.19.0.dist-info"))
    assert list(user.glob("**/site-packages/xatlas-0.0.11.dist-info"))
    assert Path(report["warp_cache"]).is_relative_to(user)
    assert report["vertices"] == 81
    assert report["finite"]
    assert report["min"] == pytest.approx(SUN_STRENGTH / math.pi, rel=0.01)
    assert report["max"] == pytest.approx(SUN_STRENGTH / math.pi, rel=0.01)


def _install_and_bake(zip_path: str, report_path: str) -> None:
    """Child process: install ``zip_path``, bake a plane under a sun, write facts to ``report_path``."""
    import bpy  # BLENDER_USER_RESOURCES comes from the parent: a fresh, temporary user folder
    import numpy as np

    bpy.ops.extensions.package_install_files(filepath=zip_path, repo=REPO_NAME, enable_on_install=True)
    module_name = f"bl_ext.{REPO_NAME}.radiosity_baker"
    module = sys.modules[module_name]

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=False)
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=8, y_subdivisions=8, size=2.0)
    plane = bpy.context.object
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy = SUN_STRENGTH
    bpy.context.scene.collection.objects.link(sun)
    bpy.context.scene.radiosity_baker.attribute = ATTRIBUTE
    for ob in bpy.context.view_layer.objects:
        ob.select_set(ob == plane)
    result = bpy.ops.object.radiosity_bake()
    assert result == {"FINISHED"}, result

    values = np.empty(len(plane.data.vertices) * 4, np.float32)
    plane.data.color_attributes[ATTRIBUTE].data.foreach_get("color", values)
    rgb = values.reshape(-1, 4)[:, :3]
    Path(report_path).write_text(json.dumps({
        "module": module.__name__, "module_file": module.__file__,
        "warp_cache": os.environ.get("WARP_CACHE_PATH", ""), "vertices": int(rgb.shape[0]),
        "finite": bool(np.isfinite(rgb).all()), "min": float(rgb.min()),
        "max": float(rgb.max()),
    }))


if __name__ == "__main__":
    _install_and_bake(sys.argv[1], os.environ["RB_INSTALL_REPORT"])
    sys.stdout.flush()
    os._exit(0)  # skip bpy's interpreter shutdown: only the bake's outcome matters here
