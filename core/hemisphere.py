"""Direction cells over a receiver's hemisphere and the bilinear splat into them (Warp functions).

The hemisphere around a normal n is cut into BINS cells of equal cosine-weighted measure: RINGS
rings of equal sin²θ times SECTORS sectors of equal azimuth, so each cell holds CELL = 1/BINS of a
Lambertian receiver's view. A contribution arriving from direction d is spread bilinearly over the
four cells around it (``splat_of``: four cells and their weights, which a gather applies to each
of its tables).
"""
import warp as wp

from .formfactor import tangent_frame

wp.set_module_options({"enable_backward": False})  # no gradients: halves compile time

RINGS = 4
SECTORS = 8
BINS = RINGS * SECTORS
CELL = 1.0 / BINS

bins_vec = wp.types.vector(length=BINS, dtype=wp.float32)


@wp.struct
class Frame:
    """A receiver's hemisphere: normal n and tangents tu, tv."""

    n: wp.vec3
    tu: wp.vec3
    tv: wp.vec3


@wp.struct
class Splat:
    """Four cells and their bilinear weights."""

    cells: wp.vec4i
    weights: wp.vec4


@wp.func
def frame_of(n: wp.vec3) -> Frame:
    f = Frame()
    f.n = n
    tu, tv = tangent_frame(n)
    f.tu = tu
    f.tv = tv
    return f


@wp.func
def splat_of(f: Frame, d: wp.vec3) -> Splat:
    """The four cells around unit direction d and their weights."""
    z = wp.dot(d, f.n)
    fr = wp.clamp(1.0 - z * z, 0.0, 1.0) * float(RINGS) - 0.5
    phi = wp.atan2(wp.dot(d, f.tv), wp.dot(d, f.tu))
    fs = (phi * 0.15915494309189535 + 0.5) * float(SECTORS) - 0.5
    r0 = int(wp.floor(fr))
    wr = fr - float(r0)
    s0 = int(wp.floor(fs))
    ws = fs - float(s0)
    r1 = wp.min(r0 + 1, RINGS - 1)
    r0 = wp.max(r0, 0)
    s1 = (s0 + 1 + SECTORS) % SECTORS
    s0 = (s0 + SECTORS) % SECTORS
    s = Splat()
    s.cells = wp.vec4i(r0 * SECTORS + s0, r0 * SECTORS + s1, r1 * SECTORS + s0, r1 * SECTORS + s1)
    s.weights = wp.vec4((1.0 - wr) * (1.0 - ws), (1.0 - wr) * ws, wr * (1.0 - ws), wr * ws)
    return s
