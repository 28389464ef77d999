"""Form factors as Warp functions (shared by direct light and the solvers).

All form factors here are point-to-area: the fraction of a Lambertian receiver's cosine-weighted
hemisphere (normal ``n`` at ``p``) covered by the sender, so ``lighting = radiance × F``.
"""
import warp as wp

wp.set_module_options({"enable_backward": False})  # no gradients: halves compile time

INV_TWO_PI = 0.15915494309189535
# A corner counts as above the receiver's horizon only if it is higher than this fraction of its
# distance: a sender in the receiver's own plane (a neighbouring triangle of a flat wall) is seen
# edge-on and contributes nothing.
HORIZON_EPS = 1.0e-5
# A triangle counts for a point only if the point lies off its plane by more than this fraction of
# the triangle's size plus their distance: a point on the triangle itself, on its edge or at its
# corner (a receiver on its own surface or on a neighbour's, up to rounding) sees it edge-on,
# whichever side the rounding puts it. Measured from the triangle's size, not only from the
# distance, which vanishes at its corners.
PLANE_EPS = 1.0e-5
# Outline shapes (outline_point); rectangle and ellipse match core.scene's SHAPE_* codes.
OUTLINE_RECTANGLE, OUTLINE_ELLIPSE, OUTLINE_TRIANGLE = 0, 1, 2


@wp.func
def arc_term(a: wp.vec3, b: wp.vec3, n: wp.vec3) -> float:
    """γ·(n·ĝ) for the great-circle arc from direction a to b (Lambert's contour integral term)."""
    c = wp.cross(a, b)
    lc = wp.length(c)
    if lc < 1.0e-30:
        return 0.0
    return arc_angle(lc, wp.dot(a, b)) * wp.dot(n, c) / lc


@wp.func
def arc_angle(y: float, x: float) -> float:
    """atan2(y, x) for y ≥ 0 (rad): the angle between two directions from its sine and cosine
    parts. atan(t) = t·P(t²) on t ∈ [0, 1], reflected about π/4 and π/2; P's coefficients were
    fitted for this project (reweighted least squares towards the minimax: 6·10⁻⁹ rad in double).
    In float32 it is within float32 rounding of the angle (worst 2.9·10⁻⁷ rad, mean 5.5·10⁻⁸:
    1.2 and 0.23 float32 spacings at π; numpy's float32 atan2 gave 3.1·10⁻⁷ and 5.5·10⁻⁸ on one
    CPU, 2.4·10⁻⁷ and 3.8·10⁻⁸ on an AMD EPYC) at a quarter of libm's atan2f's time
    (measured on the 2-core VM: 25.5 → 5.8 ns), which was most of an exact form factor's."""
    ax = wp.abs(x)
    t = wp.min(ax, y) / wp.max(wp.max(ax, y), 1.0e-30)
    u = t * t
    r = t * (0.9999998863863333 + u * (-0.33332597036353173 + u * (0.19985906826156927 + u * (
        -0.141612293487496 + u * (0.10498946064208735 + u * (-0.0723485657338098 + u * (
            0.03978120832226929 + u * (-0.014401346016367165 + u * 0.0024567211422100266))))))))
    if y > ax:
        r = 1.5707963267948966 - r
    if x < 0.0:
        r = 3.141592653589793 - r
    return r


@wp.func
def horizon_height(a: wp.vec3, n: wp.vec3) -> float:
    """How far point a (relative to the receiver) lies above the horizon of normal n, less
    HORIZON_EPS of its distance: > 0 counts as above."""
    return wp.dot(a, n) - HORIZON_EPS * wp.length(a)


@wp.func
def clip_edge_term(a: wp.vec3, b: wp.vec3, ha: float, hb: float, n: wp.vec3):
    """Contour term of edge a→b clipped to the horizon of normal n (a, b relative to the receiver;
    ha, hb their ``horizon_height``).

    Returns (term, event, point): event 1 when the edge leaves the upper hemisphere at ``point``,
    2 when it enters there, 0 otherwise.
    """
    term = float(0.0)
    event = int(0)
    x = wp.vec3(0.0)
    if ha > 0.0 and hb > 0.0:
        term = arc_term(a, b, n)
    elif ha > 0.0:
        x = a + (b - a) * (ha / (ha - hb))
        term = arc_term(a, x, n)
        event = 1
    elif hb > 0.0:
        x = a + (b - a) * (ha / (ha - hb))
        term = arc_term(x, b, n)
        event = 2
    return term, event, x


@wp.func
def plane_side(p: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3) -> float:
    """The side of triangle abc's plane point p lies on: 1 along its winding's normal (b−a)×(c−a),
    −1 against it, 0 in the plane up to rounding (PLANE_EPS of the triangle's size plus p's
    distance): there the triangle is seen edge-on and sends nothing to p."""
    nt = wp.cross(b - a, c - a)
    lnt = wp.length(nt)
    return side_of(wp.dot(p - a, nt), PLANE_EPS * lnt * (wp.length(p - a) + wp.sqrt(lnt)))


@wp.func
def side_of(h: float, tol: float) -> float:
    """1 for a height h over a plane above tol, −1 below −tol, 0 between (in the plane)."""
    if h > tol:
        return 1.0
    if h < -tol:
        return -1.0
    return 0.0


@wp.func
def triangle_ff(p: wp.vec3, n: wp.vec3, v0: wp.vec3, v1: wp.vec3, v2: wp.vec3) -> float:
    """Exact unoccluded form factor from point p (normal n) to triangle v0 v1 v2, either side facing,
    clipped to p's horizon; 0 where p lies in its plane (``plane_side``: on the triangle, its edge
    or corner, where the contour integral's limit depends on the side rounding puts p)."""
    if plane_side(p, v0, v1, v2) == 0.0:
        return 0.0
    return outline_ff(p, n, OUTLINE_TRIANGLE, 3, v0, v1, v2, 0.0, 0.0)


# A triangle at least FAR_REACH times its reach (the farthest corner from its centroid) from a
# receiver, wholly above the receiver's horizon, has its form factor from a 3-point quadrature
# (``far_triangle_ff``): over random triangles and receivers (4–8 reaches away) its relative error
# was 0.017 % on average and 0.19 % at worst, against 1 % and 6.5 % for the centroid alone.
FAR_REACH = wp.constant(4.0)


@wp.func
def far_triangle_ff(p: wp.vec3, n: wp.vec3, v0: wp.vec3, v1: wp.vec3, v2: wp.vec3, centre: wp.vec3,
                    normal: wp.vec3, area: float) -> float:
    """Form factor from p (normal n) to a triangle seen from afar (see FAR_REACH), either side
    facing: area × the mean of the point kernel |h|·(n·d)/(π r⁴) at the three points halfway from
    the centroid to each corner (a rule exact for quadratics), where h = (p − centroid)·normal is
    p's height over the triangle's plane (unit normal), d the offset to the point, r its length."""
    h = wp.abs(wp.dot(p - centre, normal))
    s = float(0.0)
    for k in range(3):
        corner = v0
        if k == 1:
            corner = v1
        if k == 2:
            corner = v2
        d = 0.5 * (centre + corner) - p
        r2 = wp.dot(d, d)
        s += wp.max(wp.dot(n, d), 0.0) / (r2 * r2)
    return area * h * s / (3.0 * 3.141592653589793)


@wp.func
def triangle_view(p: wp.vec3, n: wp.vec3, centre: wp.vec3, reach: float) -> int:
    """How a triangle (its centre, and reach: its farthest corner's distance from the centre, m)
    stands to point p with normal n: −1 wholly below p's horizon (it sends nothing), 1 far
    (FAR_REACH) and wholly above (``far_triangle_ff`` holds), 0 otherwise (exact)."""
    d = centre - p
    up = wp.dot(n, d)
    if up < -reach:
        return -1
    if up > reach and wp.dot(d, d) > (FAR_REACH * FAR_REACH) * (reach * reach):
        return 1
    return 0


@wp.func
def outline_point(shape: int, k: int, count: int, a: wp.vec3, u: wp.vec3, v: wp.vec3, hx: float,
                  hy: float) -> wp.vec3:
    """Corner k (cyclic) of a planar outline: OUTLINE_RECTANGLE / OUTLINE_ELLIPSE (a ``count``-gon)
    centred at a with half sizes hx, hy along the unit axes u, v; OUTLINE_TRIANGLE: corners a, u, v."""
    if shape == OUTLINE_TRIANGLE:
        kk = k % 3
        if kk == 0:
            return a
        if kk == 1:
            return u
        return v
    if shape == OUTLINE_RECTANGLE:
        sx = float(1.0)
        sy = float(1.0)
        kk = k % 4
        if kk == 1 or kk == 2:
            sx = -1.0
        if kk >= 2:
            sy = -1.0
        return a + u * (sx * hx) + v * (sy * hy)
    ang = 6.283185307179586 * float(k % count) / float(count)
    return a + u * (hx * wp.cos(ang)) + v * (hy * wp.sin(ang))


@wp.func
def outline_ff(p: wp.vec3, n: wp.vec3, shape: int, count: int, a: wp.vec3, u: wp.vec3, v: wp.vec3,
               hx: float, hy: float) -> float:
    """Exact unoccluded form factor from p (normal n) to a convex planar outline (see
    outline_point), either side facing: Lambert's contour integral of the outline clipped to p's
    horizon, the clipped part closed along the horizon."""
    nv = 4
    if shape == OUTLINE_ELLIPSE:
        nv = count
    if shape == OUTLINE_TRIANGLE:
        nv = 3
    s = float(0.0)
    exit_pt = wp.vec3(0.0)
    entry_pt = wp.vec3(0.0)
    has_exit = int(0)
    has_entry = int(0)
    # each corner relative to p, with its height over the horizon, is made once and passed on to
    # the next edge (the last edge's end, corner nv, is corner 0 again)
    c0 = outline_point(shape, 0, count, a, u, v, hx, hy) - p
    h0 = horizon_height(c0, n)
    for k in range(nv):
        c1 = outline_point(shape, k + 1, count, a, u, v, hx, hy) - p
        h1 = horizon_height(c1, n)
        t, e, x = clip_edge_term(c0, c1, h0, h1, n)
        c0 = c1
        h0 = h1
        s += t
        if e == 1:
            exit_pt = x
            has_exit = 1
        if e == 2:
            entry_pt = x
            has_entry = 1
    if has_exit == 1 and has_entry == 1:
        s += arc_term(exit_pt, entry_pt, n)
    return wp.abs(s) * INV_TWO_PI


@wp.func
def disk_ff(p: wp.vec3, n: wp.vec3, q: wp.vec3, nq: wp.vec3, area: float) -> float:
    """Disk approximation A·sat(cos_E)·sat(cos_R)/(π d² + A) from p (normal n) to the front face of
    a disk at q (normal nq, area A); exact on the disk's axis."""
    d = q - p
    d2 = wp.dot(d, d)
    if d2 <= 0.0:
        return 0.0
    inv = 1.0 / wp.sqrt(d2)
    cos_r = wp.max(wp.dot(n, d) * inv, 0.0)
    cos_e = wp.max(-wp.dot(nq, d) * inv, 0.0)
    return area * cos_e * cos_r / (3.141592653589793 * d2 + area)


@wp.func
def tangent_frame(w: wp.vec3):
    """Two unit vectors perpendicular to unit w and to each other."""
    a = wp.vec3(1.0, 0.0, 0.0)
    if wp.abs(w[0]) > 0.9:
        a = wp.vec3(0.0, 1.0, 0.0)
    t = wp.normalize(wp.cross(w, a))
    return t, wp.cross(w, t)


@wp.func
def cluster_ff(p: wp.vec3, n: wp.vec3, q: wp.vec3, nq: wp.vec3, area: float, spread: float,
               leaves: float) -> float:
    """Form factor of a cluster of ``leaves`` disks: as many disks of its mean area at its centre
    (their sum, not one disk of the whole area, whose π d² + A denominator would be too large) for
    aligned normals (spread 1); an isotropic blob of projected area A/4 (a closed convex surface's
    mean) where they cancel (spread 0); linearly between."""
    d = q - p
    d2 = wp.dot(d, d)
    if d2 <= 0.0:
        return 0.0
    cos_r = wp.max(wp.dot(n, d) / wp.sqrt(d2), 0.0)
    each = area / leaves
    iso = 0.25 * area * cos_r / (3.141592653589793 * d2 + 0.25 * each)
    return spread * leaves * disk_ff(p, n, q, nq, each) + (1.0 - spread) * iso
