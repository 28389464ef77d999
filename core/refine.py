"""Finer elements where surfaces nearly touch (issue 21: contacts).

Where two surfaces come within a triangle's size of each other — an object standing on a floor,
shelves 5 cm from a wall, a chin over a neck — the light on each changes many times over inside
one element: the floor under a capsule is dark within millimetres of the contact and in full sun
a hand's width away. An element sends and receives one value, so both sides of the gap see each
other's average and light the gap from inside (measured on the open scene, a capsule on a floor
under a sun: the capsule's lowest ring 6× and the floor under it 10× too bright; refining the
floor alone there, in Blender, moved the whole scene's error 0.85 → 0.67 %, and with finer links
0.27 %).

So the solver works on a copy of the scene whose triangles near a contact are split: a
triangle is *near* when a ray along its normal from one of POINTS of it meets another surface's
front closer than REACH × its longest edge, and that surface's triangles are no finer (only the
coarser side of a gap is split: the finer side's light varies less across one of its triangles,
and splitting both sides of the open scene's contact cost twice the time for no gain) — but not
closer than TOUCH × it: faces pressed together, the floor under a box, see nothing and gain
nothing from splitting. Near triangles are split into four at their edges' midpoints, the
nearest first and at most BUDGET added; a neighbour sharing one split edge is split in two, one
sharing two or three in four (conforming: no vertex of one triangle lies on another's edge, so
surfaces stay closed). This repeats ``levels`` times on the triangles made. The links of
clusters holding a split element are refined further (``links.CONTACT_WEIGHT``). The scene's own
vertices and triangles are untouched: results are wanted there (``Problem.shading``), and the
refinement is a fixed map from them (``Refinement.apply``), so a deforming mesh keeps it.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import warp as wp

from . import device as device_mod
from .elements import ShadingVertices
from .rays import lift
from .scene import SceneData

wp.set_module_options({"enable_backward": False})  # no gradients: halves compile time

# A surface met along a triangle's normal closer than REACH × its longest edge makes it near.
REACH = 1.0
# ... unless closer than TOUCH × that edge: pressed against it, unseen.
TOUCH = 0.01
# Where a triangle looks from, barycentric: its centre and halfway from there to each corner.
POINTS = np.array([[1 / 3, 1 / 3, 1 / 3], [2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6],
                   [1 / 6, 1 / 6, 2 / 3]], np.float64)
# At most this many triangles are added in all, as a fraction of the scene's: the nearest
# contacts (the smallest gap against the triangle's size) are split first.
BUDGET = 0.5


@dataclass
class Refinement:
    """A scene's triangles near contacts, split (see the module).

    pairs: int32[M,2] the two vertices each new vertex is the midpoint of (vertex V + k for row
    k); starts: int32[L+1] where each level's rows begin (a row names vertices of earlier levels
    only); triangles: int32[T',3] the split triangles over the V + M vertices, counter-clockwise
    as their parents; parent: int32[T'] the scene triangle each lies in; bary: float64[T',3,3]
    its corners' barycentric coordinates in that parent.
    """

    pairs: np.ndarray
    starts: np.ndarray
    triangles: np.ndarray
    parent: np.ndarray
    bary: np.ndarray

    @property
    def split(self) -> np.ndarray:
        """bool[T']: the triangles that are part of a split scene triangle."""
        return np.bincount(self.parent)[self.parent] > 1

    def apply(self, scene: SceneData) -> SceneData:
        """``scene`` (the one refined, or it deformed: same vertices and triangles) with its
        near triangles split; its own vertices come first, in order."""
        if not len(self.pairs):
            return scene
        p = np.empty((scene.num_vertices + len(self.pairs), 3), np.float64)
        p[:scene.num_vertices] = scene.positions
        v = scene.num_vertices
        for lo, hi in zip(self.starts[:-1], self.starts[1:]):
            p[v + lo:v + hi] = 0.5 * (p[self.pairs[lo:hi, 0]] + p[self.pairs[lo:hi, 1]])
        corner_normals = np.asarray(scene.corner_normals, np.float64)[self.parent]
        normals = np.einsum("tck,tkd->tcd", self.bary, corner_normals)
        length = np.linalg.norm(normals, axis=2, keepdims=True)
        normals = np.where(length > 0, normals / np.where(length > 0, length, 1.0), normals)
        # a corner on one of the parent's corners keeps that corner's normal exactly
        own = (self.bary == 1.0).any(axis=2)
        which = self.bary.argmax(axis=2)
        kept = np.asarray(scene.corner_normals)[self.parent[:, None], which]
        normals = np.where(own[..., None], kept, normals)
        return replace(scene, positions=p.astype(np.float32), triangles=self.triangles,
                       corner_normals=normals.astype(np.float32), tri_object=scene.tri_object[self.parent],
                       albedo=scene.albedo[self.parent], emission=scene.emission[self.parent])


@wp.kernel
def _hit_kernel(offset: int, mesh: wp.uint64, points: wp.array(dtype=wp.vec3),
                normals: wp.array(dtype=wp.vec3), edge: wp.array(dtype=wp.float32),
                distance: wp.array(dtype=wp.float32), face: wp.array(dtype=wp.int32)):
    i = offset + wp.tid()
    face[i] = -1
    distance[i] = 0.0
    q = wp.mesh_query_ray(mesh, lift(points[i], normals[i], edge[i]), normals[i], REACH * edge[i])
    # only a surface's front counts: a ray that starts inside a closed object (a floor point
    # under a box resting on it, lifted through the box's bottom) sees its inside
    if q.result and q.sign > 0.0:
        distance[i] = q.t
        face[i] = q.face


def gaps(positions: np.ndarray, triangles: np.ndarray, mesh: wp.Mesh, sizes: np.ndarray,
         device) -> np.ndarray:
    """float64[T]: for each triangle, the nearest surface met along its normal from its POINTS,
    in its longest edges — of the surfaces no finer than it: ``sizes`` float[F] the longest edge
    of each of ``mesh``'s triangles now (of a contact, only the coarser side is split, the side
    whose light varies the more across one triangle). 2 × REACH where there is none within
    REACH, or only one pressed against it (closer than TOUCH)."""
    p = np.asarray(positions, np.float64)[triangles]  # [T,3,3]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    length = np.linalg.norm(normal, axis=1, keepdims=True)
    normal = normal / np.where(length > 0, length, 1.0)
    edge = np.linalg.norm(p - np.roll(p, 1, axis=1), axis=2).max(axis=1)
    points = np.einsum("sk,tkc->tsc", POINTS, p).reshape(-1, 3)
    n, d = len(points), device.name
    distance = wp.empty(n, dtype=wp.float32, device=d)
    face = wp.empty(n, dtype=wp.int32, device=d)
    device_mod.launch(_hit_kernel, n, [mesh.id, wp.array(points.astype(np.float32), dtype=wp.vec3, device=d),
                                       wp.array(np.repeat(normal, len(POINTS), axis=0).astype(np.float32),
                                                dtype=wp.vec3, device=d),
                                       wp.array(np.repeat(edge, len(POINTS)).astype(np.float32),
                                                dtype=wp.float32, device=d), distance, face], device)
    t = distance.numpy().astype(np.float64).reshape(-1, len(POINTS))
    f = face.numpy().reshape(-1, len(POINTS))
    e = edge[:, None]
    near = (f >= 0) & (t > TOUCH * e) & (sizes[np.maximum(f, 0)] <= e) & (length > 0)
    return np.where(near, t / np.where(e > 0, e, 1.0), 2.0 * REACH).min(axis=1)


def contacts(scene: SceneData, mesh: wp.Mesh, levels: int, device) -> Refinement:
    """The ``Refinement`` of ``scene`` (its BVH ``mesh``, on ``device``) over ``levels`` levels."""
    t0 = scene.num_triangles
    if levels <= 0:  # nothing split: the scene's own triangles, each its own parent
        return Refinement(pairs=np.zeros((0, 2), np.int32), starts=np.zeros(1, np.int32),
                          triangles=np.asarray(scene.triangles, np.int32),
                          parent=np.arange(t0, dtype=np.int32), bary=np.broadcast_to(np.eye(3), (t0, 3, 3)))
    tris = np.asarray(scene.triangles, np.int64)
    positions = np.asarray(scene.positions, np.float64)
    parent = np.arange(t0)
    bary = np.broadcast_to(np.eye(3), (t0, 3, 3)).copy()
    pairs, starts = np.zeros((0, 2), np.int64), [0]
    # each scene triangle's longest edge, halved each level it is split at: the size of the
    # finest triangles the BVH's (unsplit) triangle stands for
    p = positions[tris]
    sizes = np.linalg.norm(p - np.roll(p, 1, axis=1), axis=2).max(axis=1)
    for _ in range(levels):
        budget = int(BUDGET * t0) - (len(tris) - t0)
        g = gaps(positions, tris, mesh, sizes, device)
        near = np.flatnonzero(g <= REACH)
        if not len(near) or budget <= 0:
            break
        near = near[np.argsort(g[near], kind="stable")][:max(1, budget // 3)]
        split = _closure(tris, near)
        sizes[np.unique(parent[split.any(axis=1)])] *= 0.5
        tris, parent, bary, new_pairs = _split(tris, parent, bary, split, len(positions))
        middle = 0.5 * (positions[new_pairs[:, 0]] + positions[new_pairs[:, 1]])
        positions = np.concatenate([positions, middle])
        pairs = np.concatenate([pairs, new_pairs])
        starts.append(len(pairs))
    return Refinement(pairs=pairs.astype(np.int32), starts=np.asarray(starts, np.int32),
                      triangles=tris.astype(np.int32), parent=parent.astype(np.int32), bary=bary)


def _edges(tris: np.ndarray):
    """int64[T,3] a key per triangle edge (corner k to corner k+1, either direction) and the
    number of vertices it is keyed over."""
    a, b = tris, np.roll(tris, -1, axis=1)
    v = int(tris.max(initial=0)) + 1
    return np.minimum(a, b) * v + np.maximum(a, b), v


def _closure(tris: np.ndarray, near: np.ndarray) -> np.ndarray:
    """bool[T,3]: the edges split when triangles ``near`` are split in four: theirs, and every
    edge of a triangle with two of its edges split, until none is left with exactly two."""
    keys, _ = _edges(tris)
    marked = np.zeros(keys.shape, bool)
    marked[near] = True
    while True:
        chosen = np.unique(keys[marked])
        marked = np.isin(keys, chosen)
        two = marked.sum(axis=1) == 2
        if not two.any():
            return marked
        marked[two] = True


def _split(tris, parent, bary, marked, vertices):
    """Split each triangle at its ``marked`` edges (bool[T,3]: none, one, or all three): the new
    (tris, parent, bary, pairs), new vertices numbered from ``vertices`` in order of their
    edges' keys."""
    keys, _ = _edges(tris)
    chosen, first = np.unique(keys[marked], return_index=True)
    rows, cols = np.nonzero(marked)
    pairs = np.stack([tris[rows[first], cols[first]], tris[rows[first], (cols[first] + 1) % 3]], axis=1)
    mid = np.full(tris.shape, -1, np.int64)
    mid[marked] = vertices + np.searchsorted(chosen, keys[marked])
    count = marked.sum(axis=1)
    out_t, out_p, out_b = [tris[count == 0]], [parent[count == 0]], [bary[count == 0]]
    # one edge: (a, b, c) with edge a→b split at m → (a, m, c), (m, b, c)
    one = np.flatnonzero(count == 1)
    j = marked[one].argmax(axis=1)
    r = (j[:, None] + np.arange(3)) % 3  # corners rotated so the split edge is the first
    a, b, c = (tris[one, r[:, k]] for k in range(3))
    ba, bb, bc = (bary[one, r[:, k]] for k in range(3))
    m, bm = mid[one, j], 0.5 * (ba + bb)
    out_t += [np.stack([a, m, c], 1), np.stack([m, b, c], 1)]
    out_p += [parent[one]] * 2
    out_b += [np.stack([ba, bm, bc], 1), np.stack([bm, bb, bc], 1)]
    # three edges: corners and the medial triangle
    red = np.flatnonzero(count == 3)
    a, b, c = (tris[red, k] for k in range(3))
    m0, m1, m2 = (mid[red, k] for k in range(3))
    ba, bb, bc = (bary[red, k] for k in range(3))
    b0, b1, b2 = 0.5 * (ba + bb), 0.5 * (bb + bc), 0.5 * (bc + ba)
    out_t += [np.stack(x, 1) for x in ((a, m0, m2), (m0, b, m1), (m2, m1, c), (m0, m1, m2))]
    out_p += [parent[red]] * 4
    out_b += [np.stack(x, 1) for x in ((ba, b0, b2), (b0, bb, b1), (b2, b1, bc), (b0, b1, b2))]
    return np.concatenate(out_t), np.concatenate(out_p), np.concatenate(out_b), pairs


def shading(refinement: Refinement, source: ShadingVertices, split: ShadingVertices,
            vertices: int) -> ShadingVertices:
    """The shading vertices ``split`` of the refined scene (``Refinement.apply``), renumbered so
    that those on the source's ``vertices`` vertices come first, as ``source`` numbers them
    (a source corner's normal is kept exactly, so each is one of ``source``'s), then the new
    ones in their order."""
    corners = refinement.triangles < vertices  # [T',3] corners on a source vertex
    t, k = np.nonzero(corners)
    own = source.corner[refinement.parent[t], refinement.bary[t, k].argmax(axis=1)]
    rank = np.full(split.count, -1, np.int64)
    rank[split.corner[t, k]] = own
    new = rank < 0
    rank[new] = source.count + np.arange(int(new.sum()))
    order = np.argsort(rank)
    return ShadingVertices(position=split.position[order], normal=split.normal[order],
                           vertex=split.vertex[order],
                           corner=rank[split.corner].astype(np.int32))
