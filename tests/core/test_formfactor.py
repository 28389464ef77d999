"""Form factor functions against exact values and numerical integration."""
import numpy as np
import pytest
import warp as wp

import shapes
from radiosity_baker.core import Settings, device
from radiosity_baker.core.elements import FAN_OPEN_IN, FAN_OPEN_OUT, FAN_TANGLED, fan_outline
from radiosity_baker.core.formfactor import (FAR_REACH, arc_angle, disk_ff, far_triangle_ff, outline_ff,
                                             triangle_ff)
from radiosity_baker.core.problem import Problem
from radiosity_baker.core.surfels import Surfels, outline_fan_ff

device.init_warp()


@wp.kernel
def _tri_kernel(p: wp.array(dtype=wp.vec3), n: wp.array(dtype=wp.vec3), v: wp.array(dtype=wp.vec3),
                out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = triangle_ff(p[i], n[i], v[3 * i], v[3 * i + 1], v[3 * i + 2])


@wp.kernel
def _far_kernel(p: wp.array(dtype=wp.vec3), n: wp.array(dtype=wp.vec3), v: wp.array(dtype=wp.vec3),
                out: wp.array(dtype=float)):
    i = wp.tid()
    a, b, c = v[3 * i], v[3 * i + 1], v[3 * i + 2]
    out[i] = far_triangle_ff(p[i], n[i], a, b, c, (a + b + c) / 3.0, wp.normalize(wp.cross(b - a, c - a)),
                             0.5 * wp.length(wp.cross(b - a, c - a)))


@wp.kernel
def _disk_kernel(p: wp.vec3, n: wp.vec3, q: wp.vec3, nq: wp.vec3, area: float, out: wp.array(dtype=float)):
    out[0] = disk_ff(p, n, q, nq, area)


@wp.kernel
def _outline_kernel(p: wp.vec3, n: wp.vec3, hx: float, hy: float, ellipse: int, count: int,
                    out: wp.array(dtype=float)):
    out[0] = outline_ff(p, n, ellipse, count, wp.vec3(0.0, 0.0, 1.0), wp.vec3(1.0, 0.0, 0.0),
                        wp.vec3(0.0, 1.0, 0.0), hx, hy)


def triangles_ff(p, n, tris):
    """Sum of triangle_ff from point p (normal n) over float[k,3,3] triangles."""
    k = len(tris)
    out = wp.zeros(k, dtype=float, device="cpu")
    wp.launch(_tri_kernel, dim=k, inputs=[wp.array(np.tile(p, (k, 1)).astype(np.float32), dtype=wp.vec3),
                                          wp.array(np.tile(n, (k, 1)).astype(np.float32), dtype=wp.vec3),
                                          wp.array(np.asarray(tris, np.float32).reshape(-1, 3), dtype=wp.vec3), out])
    return float(out.numpy().sum())


def quad(c0, c1, c2, c3):
    return [[c0, c1, c2], [c0, c2, c3]]


def numeric_ff(p, n, corner, e1, e2, res=800):
    """Point-to-parallelogram form factor by midpoint quadrature (cosines clamped at 0 on the receiver)."""
    s = (np.arange(res) + 0.5) / res
    u, v = np.meshgrid(s, s)
    q = corner + u[..., None] * e1 + v[..., None] * e2
    d = q - p
    r2 = (d ** 2).sum(-1)
    nq = np.cross(e1, e2)
    area = np.linalg.norm(nq)
    nq = nq / area
    cos_r = np.clip((d @ n) / np.sqrt(r2), 0, None)
    cos_e = np.abs(d @ nq) / np.sqrt(r2)
    return float((cos_r * cos_e / (np.pi * r2)).sum() * area / res ** 2)


def test_point_under_unit_square_at_height_one_is_exact():
    tris = quad([-0.5, -0.5, 1], [0.5, -0.5, 1], [0.5, 0.5, 1], [-0.5, 0.5, 1])
    assert triangles_ff(np.zeros(3), np.array([0, 0, 1.0]), tris) == pytest.approx(0.23946, rel=1e-3)


def test_triangle_form_factor_does_not_depend_on_winding():
    tris = quad([-0.5, -0.5, 1], [0.5, -0.5, 1], [0.5, 0.5, 1], [-0.5, 0.5, 1])
    flipped = [t[::-1] for t in tris]
    n = np.array([0, 0, 1.0])
    assert triangles_ff(np.zeros(3), n, flipped) == pytest.approx(triangles_ff(np.zeros(3), n, tris), rel=1e-6)


def test_square_crossing_the_horizon_is_clipped_like_numerical_integration():
    # A vertical unit square straddling the receiver's tangent plane, off to one side.
    corner, e1, e2 = np.array([1.0, -0.5, -0.4]), np.array([0, 1.0, 0]), np.array([0, 0, 1.0])
    n = np.array([0, 0, 1.0])
    tris = quad(corner, corner + e1, corner + e1 + e2, corner + e2)
    exact = numeric_ff(np.zeros(3), n, corner, e1, e2)
    assert exact > 0.01
    assert triangles_ff(np.zeros(3), n, tris) == pytest.approx(exact, rel=5e-3)


def test_square_below_the_horizon_contributes_nothing():
    tris = quad([-0.5, -0.5, -1], [0.5, -0.5, -1], [0.5, 0.5, -1], [-0.5, 0.5, -1])
    assert triangles_ff(np.zeros(3), np.array([0, 0, 1.0]), tris) == 0.0


def test_coplanar_neighbour_triangle_is_seen_edge_on():
    tris = [[[0, 0, 0], [1, 0, 0], [0, 1, 0]]]
    assert triangles_ff(np.array([0.0, 0, 0]), np.array([0, 0, 1.0]), tris) == 0.0


@pytest.mark.parametrize("h, radius", [(1.0, 1.0), (2.0, 0.5), (0.5, 3.0)])
def test_disk_approximation_is_exact_on_axis(h, radius):
    out = wp.zeros(1, dtype=float, device="cpu")
    wp.launch(_disk_kernel, dim=1, inputs=[wp.vec3(0, 0, 0), wp.vec3(0, 0, 1), wp.vec3(0, 0, h),
                                           wp.vec3(0, 0, -1), float(np.pi * radius ** 2), out])
    assert out.numpy()[0] == pytest.approx(radius ** 2 / (h ** 2 + radius ** 2), rel=1e-5)


@pytest.mark.parametrize("ellipse, count, expect", [(0, 4, 0.23946), (1, 256, 0.5)])
def test_lamp_outline_matches_exact_values(ellipse, count, expect):
    # unit square 1 m above (F = 0.23946) / disk of radius 1 at height 1 (F = R²/(h²+R²) = 0.5)
    out = wp.zeros(1, dtype=float, device="cpu")
    half = 0.5 if ellipse == 0 else 1.0
    wp.launch(_outline_kernel, dim=1, inputs=[wp.vec3(0, 0, 0), wp.vec3(0, 0, 1), half, half, ellipse, count, out])
    assert out.numpy()[0] == pytest.approx(expect, rel=1e-3)


def contour_ff(p, n, tris):
    """float64[k] exact form factors from points p (float[k,3], normals n) to triangles
    float[k,3,3] wholly above their horizon: Lambert's contour integral in double precision."""
    s = np.zeros(len(tris))
    for k in range(3):
        a = tris[:, k] - p
        b = tris[:, (k + 1) % 3] - p
        a /= np.linalg.norm(a, axis=1, keepdims=True)
        b /= np.linalg.norm(b, axis=1, keepdims=True)
        c = np.cross(a, b)
        lc = np.linalg.norm(c, axis=1)
        s += np.arctan2(lc, (a * b).sum(1)) * (n * c).sum(1) / lc
    return np.abs(s) / (2 * np.pi)


def test_far_triangles_quadrature_matches_the_exact_form_factor():
    """Random triangles FAR_REACH to twice that many reaches (farthest corner from the centroid)
    from random receivers that see them wholly above their horizon: the 3-point quadrature against
    the contour integral in double precision. Bounds: worst 0.5 %, mean 0.05 % (measured 0.19 %
    and 0.017 % in numpy; the centroid alone: 6.5 % and 1 %). The float32 contour integral itself
    is off by up to 5 % on the faintest of these (form factors near 10⁻⁸)."""
    rng = np.random.default_rng(3)
    tris = rng.normal(size=(20000, 3, 3))
    c = tris.mean(axis=1)
    reach = np.linalg.norm(tris - c[:, None], axis=2).max(axis=1)
    w = rng.normal(size=(len(tris), 3))
    p = c + w / np.linalg.norm(w, axis=1, keepdims=True) * (reach * FAR_REACH * (1.0 + rng.random(len(tris))))[:, None]
    n = rng.normal(size=(len(tris), 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    above = ((c - p) * n).sum(axis=1) > reach
    tris, p, n = tris[above], p[above], n[above]
    far = wp.zeros(len(tris), dtype=float, device="cpu")
    wp.launch(_far_kernel, dim=len(tris), inputs=[wp.array(p.astype(np.float32), dtype=wp.vec3),
                                                  wp.array(n.astype(np.float32), dtype=wp.vec3),
                                                  wp.array(tris.astype(np.float32).reshape(-1, 3), dtype=wp.vec3), far])
    rel = np.abs(far.numpy() / contour_ff(p, n, tris) - 1.0)
    assert len(rel) > 4000
    assert rel.max() < 0.005 and rel.mean() < 0.0005


def test_arc_angle_is_within_float32_rounding_of_the_angle():
    """The polynomial atan2 of the contour integral's arcs against the angle in double precision,
    over random directions and the octant edges: worst 1.3 and mean 0.24 float32 spacings at π
    (3.1·10⁻⁷ and 5.7·10⁻⁸ rad; rounding to float32 near π alone is up to half a spacing).
    Measured: 2.9·10⁻⁷ and 5.5·10⁻⁸ rad. (numpy's float32 atan2 is no fixed yardstick: it gave
    3.1·10⁻⁷ and 5.5·10⁻⁸ on one CPU, 2.4·10⁻⁷ and 3.8·10⁻⁸ on an AMD EPYC.)"""
    rng = np.random.default_rng(7)
    y = np.concatenate([rng.random(200000) * 10.0, [0.0, 1.0, 1.0, 1.0, 0.0, 1e-30, 3.0]]).astype(np.float32)
    x = np.concatenate([rng.normal(size=200000) * 10.0, [1.0, 0.0, 1.0, -1.0, -1.0, -2.0, -3.0]]).astype(np.float32)
    out = wp.zeros(len(y), dtype=float, device="cpu")
    wp.launch(_angle_kernel, dim=len(y), inputs=[wp.array(y, dtype=float), wp.array(x, dtype=float), out])
    exact = np.arctan2(y.astype(np.float64), x.astype(np.float64))
    ours = np.abs(out.numpy() - exact)
    spacing = float(np.spacing(np.float32(np.pi)))
    assert ours.max() <= 1.3 * spacing and ours.mean() <= 0.24 * spacing


@wp.kernel
def _angle_kernel(y: wp.array(dtype=float), x: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = arc_angle(y[i], x[i])


@wp.kernel
def _fan_kernel(s: Surfels, p: wp.array(dtype=wp.vec3), n: wp.array(dtype=wp.vec3), j: wp.array(dtype=wp.int32),
                out: wp.array(dtype=wp.vec2)):
    i = wp.tid()
    e = j[i]
    each = float(0.0)
    for k in range(s.fan_offsets[e], s.fan_offsets[e + 1]):
        t = s.fan_triangles[k]
        each += triangle_ff(p[i], n[i], s.points[s.tris[3 * t]], s.points[s.tris[3 * t + 1]], s.points[s.tris[3 * t + 2]])
    out[i] = wp.vec2(outline_fan_ff(s, p[i], n[i], e, 1.0), each / 3.0)


def test_a_fan_seen_whole_from_its_outline_matches_its_triangles_one_by_one():
    """An element's fan from its outer edges and open spokes (``surfels.outline_fan_ff``) against
    its triangles' exact form factors summed one by one, from random points near random elements
    of a bumpy grid (closed, curved fans; open ones on its border) and a box (open fans at every
    edge): equal to 10⁻⁴ wherever the outline applies, which is most points that see the fan."""
    s, pos, nrm = fan_scene()
    rng = np.random.default_rng(11)
    k = 20000
    j = rng.integers(0, len(pos), k)
    p = pos[j] + nrm[j] * rng.uniform(0.02, 0.4, (k, 1)) + rng.normal(scale=0.15, size=(k, 3))
    n = -nrm[j] + rng.normal(scale=0.5, size=(k, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    out = wp.zeros(k, dtype=wp.vec2, device="cpu")
    wp.launch(_fan_kernel, dim=k, inputs=[s, wp.array(p.astype(np.float32), dtype=wp.vec3),
                                          wp.array(n.astype(np.float32), dtype=wp.vec3),
                                          wp.array(j.astype(np.int32), dtype=wp.int32), out])
    whole, each = out.numpy().T
    applies = whole >= 0.0
    assert (applies & (each > 1e-4)).sum() > 0.5 * (each > 1e-4).sum()
    assert np.abs(whole[applies] - each[applies]).max() <= 1e-4 * each[applies].max()
    assert np.allclose(whole[applies], each[applies], rtol=1e-4, atol=1e-7)


def fan_scene():
    """Surfels of a bumpy 12×12 grid and a 0.4 m box beside it, with their element points and
    normals."""
    p, n, t = shapes.grid(2.0, 12)
    p[:, 2] = 0.15 * np.sin(3.0 * p[:, 0]) * np.cos(2.0 * p[:, 1])
    parts = [(p, shapes.flat(p, t), t, (0.5,) * 3, (0,) * 3)]
    parts += [(*face, (0.5,) * 3, (0,) * 3) for face in shapes.box(0.4, 3, (1.4, 0.0, 0.2))]
    problem = Problem(shapes.scene(parts), Settings(device="cpu"))
    return problem.surfels, problem.elements.position.astype(np.float64), problem.elements.normal.astype(np.float64)


def test_fan_outline_flags_the_open_spokes_and_tangled_fans():
    """A square of two triangles around corner 0: the spoke they share cancels, the outer ones are
    open; a triangle listed twice repeats its spokes, so its fan is tangled."""
    tris = np.array([[0, 1, 2], [0, 2, 3]])
    corners = tris.reshape(-1)
    order = np.argsort(corners, kind="stable")
    table = fan_outline(tris, corners, order)
    first = table[corners[order] == 0]
    assert first[:, :2].tolist() == [[1, 2], [2, 3]]
    assert first[:, 2].tolist() == [FAN_OPEN_OUT, FAN_OPEN_IN]
    twice = np.array([[0, 1, 2], [0, 1, 2]])
    order = np.argsort(twice.reshape(-1), kind="stable")
    assert (fan_outline(twice, twice.reshape(-1), order)[:, 2] & FAN_TANGLED).all()
