"""Write ``docs/img/threejs_screenshot.png`` (manual, docs/engines.md): the sample Cornell box baked
at the defaults (hierarchical radiosity) into an RGBM lightmap, exported as a GLB and shown by this folder's three.js page in headless
Chromium (``headless``). Run by hand; needs what the browser test needs (``npm ci`` here, Debian's
chromium):

    .venv/bin/python examples/threejs/screenshot.py [--size 360]
"""
import argparse
import os
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="rb-screenshot-"))

import OpenImageIO as oiio  # noqa: E402

import headless  # noqa: E402
from radiosity_baker.addon import cli  # noqa: E402

HERE = Path(__file__).resolve().parent
CORNELL = HERE.parents[1] / "sample_blends" / "cornell_box.blend"
OUT = HERE.parents[1] / "docs" / "img" / "threejs_screenshot.png"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=360, help="picture width and height (pixels)")
    size = parser.parse_args().size
    if headless.missing():
        print("screenshot.py needs " + " and ".join(headless.missing()), file=sys.stderr)
        return 1
    with tempfile.TemporaryDirectory(prefix="rb-screenshot-") as temp:
        site = headless.make_site(Path(temp) / "site")
        if cli.main(["bake", str(CORNELL), "--target", "lightmap", "--output", str(Path(temp) / "maps"),
                     "--lightmap-format", "rgbm", "--gltf", str(site / "cornell_box.glb")]) != 0:
            return 1
        shot = headless.screenshot(site, Path(temp) / "shot.png", size)
        canvas = oiio.ImageBufAlgo.cut(oiio.ImageBuf(str(shot)), oiio.ROI(0, size, 0, size))
        canvas = oiio.ImageBufAlgo.channels(canvas, (0, 1, 2))  # no alpha
        if not canvas.write(str(OUT), "uint8"):
            print(f"cannot write {OUT}: {canvas.geterror()}", file=sys.stderr)
            return 1
    print(f"wrote {OUT} ({OUT.stat().st_size // 1024} KiB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
