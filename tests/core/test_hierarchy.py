"""The disk tree: every element is one leaf, nodes bound and summarise their subtrees (their normal
cones and planes too), the escape pointers give a complete depth-first traversal, refit tracks
moved vertices like a rebuild."""
import numpy as np

import shapes
from radiosity_baker.core import Settings, gather, hierarchy
from radiosity_baker.core.problem import Problem

CPU = Settings(device="cpu")


def _wavy_sheet(amplitude: float, n: int = 30):
    """A 3 m square sheet of n×n quads displaced by a sine wave of ``amplitude`` (m) along z."""
    p, nrm, t = shapes.grid(3.0, n)
    p = p.copy()
    p[:, 2] = amplitude * np.sin(2.0 * p[:, 0]) * np.cos(1.5 * p[:, 1])
    # shading normals of the displaced surface (gradient of the height field)
    dzdx = amplitude * 2.0 * np.cos(2.0 * p[:, 0]) * np.cos(1.5 * p[:, 1])
    dzdy = -amplitude * 1.5 * np.sin(2.0 * p[:, 0]) * np.sin(1.5 * p[:, 1])
    nrm = np.stack([-dzdx, -dzdy, np.ones_like(dzdx)], 1)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    return p.astype(np.float32), nrm.astype(np.float32), t


def _scene(amplitude: float):
    """The wavy sheet under a closed box lid (a cube-ish shell), so there is occlusion to get right."""
    cover = shapes.grid(3.0, 12, z=1.2, flip=True)
    ball = shapes.icosphere(0.4, 2, inward=False)
    ball = (ball[0] + np.array([0.3, -0.2, 0.6], np.float32), ball[1], ball[2])
    return shapes.scene([(*_wavy_sheet(amplitude), (0.5,) * 3, (0,) * 3), (*cover, (0.5,) * 3, (0,) * 3),
                         (*ball, (0.5,) * 3, (0,) * 3)])


def _tree(scene):
    problem = Problem(scene, CPU)
    return problem.elements, problem, problem.tree


def _children(h):
    """Per node, its child range [first, end) (empty for leaves)."""
    first = h.nodes.first_child.numpy()
    end = np.full(h.count, -1)
    offs = h.level_offsets
    for lv in range(1, h.levels):
        g = np.arange(offs[lv], offs[lv + 1])
        end[g] = np.append(first[g[1:]], offs[lv])
    return first, end


def _leaf_ranges(h):
    """Per node, the range of leaf slots [lo, hi) below it."""
    first, end = _children(h)
    offs = h.level_offsets
    lo = np.arange(h.count)
    hi = lo + 1
    for lv in range(1, h.levels):
        g = np.arange(offs[lv], offs[lv + 1])
        lo[g], hi[g] = lo[first[g]], hi[end[g] - 1]
    return lo, hi


def test_every_element_is_one_leaf_and_the_root_holds_all_area():
    els, _, h = _tree(_scene(0.2))
    n = els.count
    leaves = h.nodes.element.numpy()[:n]
    assert np.array_equal(np.sort(leaves), np.arange(n))
    assert (h.nodes.element.numpy()[n:] == -1).all()
    first = h.nodes.first_child.numpy()
    assert (first[:n] == -1).all() and (first[n:] >= 0).all()
    assert h.nodes.root == h.root
    np.testing.assert_allclose(h.nodes.area.numpy()[h.root], els.area.sum(), rtol=1e-5)
    assert h.levels <= hierarchy.MAX_LEVELS
    first, end = _children(h)
    above = np.arange(h.level_offsets[2], h.count)  # octree cells: 1 to 8 children each
    assert ((end[above] - first[above] >= 1) & (end[above] - first[above] <= 8)).all()
    lo, hi = _leaf_ranges(h)
    assert lo[h.root] == 0 and hi[h.root] == n


def test_nodes_bound_and_summarise_their_subtrees():
    els, _, h = _tree(_scene(0.2))
    n = els.count
    leaf_el = h.nodes.element.numpy()[:n]
    pos, area = els.position[leaf_el].astype(np.float64), els.area[leaf_el].astype(np.float64)
    nrm = els.normal[leaf_el].astype(np.float64)
    lo, hi = _leaf_ranges(h)
    npos, nnrm, narea = h.nodes.position.numpy(), h.nodes.normal.numpy(), h.nodes.area.numpy()
    nrad, nspread = h.nodes.radius.numpy(), h.nodes.spread.numpy()
    for node in np.linspace(n, h.count - 1, 60).astype(int):  # a sample of inner nodes, root included
        s = slice(lo[node], hi[node])
        np.testing.assert_allclose(narea[node], area[s].sum(), rtol=1e-4)
        centre = (pos[s] * area[s, None]).sum(0) / area[s].sum()
        np.testing.assert_allclose(npos[node], centre, atol=1e-4)
        mean_n = (nrm[s] * area[s, None]).sum(0) / area[s].sum()
        np.testing.assert_allclose(nspread[node], np.linalg.norm(mean_n), atol=1e-4)
        np.testing.assert_allclose(nnrm[node], mean_n / np.linalg.norm(mean_n), atol=1e-3)
        reach = np.linalg.norm(pos[s] - npos[node], axis=1) + np.sqrt(area[s] / np.pi)
        assert reach.max() <= nrad[node] * (1 + 1e-5) + 1e-6


def test_node_cones_hold_their_subtrees_normals_and_planes_their_surfaces():
    """Each node's normal cone (``Tree.cone``) holds the normals of the leaves below it, and its
    (thickness, extent) bounds the corners of their fan triangles around its plane and position;
    a leaf's are exactly its fan's."""
    els, problem, h = _tree(_scene(0.2))
    n = els.count
    leaf_el = h.nodes.element.numpy()[:n]
    lo, hi = _leaf_ranges(h)
    cone, plane = h.cone.numpy().astype(np.float64), h.plane.numpy().astype(np.float64)
    npos, nnrm = h.nodes.position.numpy().astype(np.float64), h.nodes.normal.numpy().astype(np.float64)
    angle = np.arctan2(np.abs(cone[:, 1]), cone[:, 0])
    np.testing.assert_allclose(cone[:, 2], np.sqrt(2 * (1 - cone[:, 0])), atol=1e-6)
    assert (angle[:n] == 0).all()
    corners = problem.scene.positions[problem.scene.triangles].astype(np.float64)  # [T, 3, 3]
    offsets, fans = els.fan_offsets, els.fan_triangles
    thick_seen = 0.0
    for node in np.concatenate([np.arange(0, n, 97), np.linspace(n, h.count - 1, 60).astype(int)]):
        elements = leaf_el[lo[node]:hi[node]]
        leaf_n = nnrm[lo[node]:hi[node]]  # the leaves' own normals
        tilt = np.arctan2(np.linalg.norm(np.cross(leaf_n, nnrm[node]), axis=1), leaf_n @ nnrm[node])
        assert tilt.max() <= angle[node] + 1e-5
        tris = np.concatenate([fans[offsets[e]:offsets[e + 1]] for e in elements])
        x = corners[tris].reshape(-1, 3) - npos[node]
        thick, extent = np.abs(x @ nnrm[node]).max(), np.linalg.norm(x, axis=1).max()
        assert thick <= plane[node, 0] + 1e-5 and extent <= plane[node, 1] + 1e-5
        if node < n:  # a leaf's are its own fan's
            np.testing.assert_allclose(plane[node], [thick, extent], rtol=1e-5, atol=1e-6)
        thick_seen = max(thick_seen, thick)
    assert thick_seen > 0.01  # the wavy sheet and the ball are not flat: the test can fail
    assert angle[h.root] > 1.0


def test_escape_pointers_give_a_complete_depth_first_traversal():
    _, _, h = _tree(_scene(0.2))
    first, nxt = h.nodes.first_child.numpy(), h.nodes.next.numpy()
    seen = np.zeros(h.count, int)
    order = []
    node = h.root
    while node >= 0:  # always descending: must visit every node once, parents before children
        seen[node] += 1
        order.append(node)
        node = first[node] if first[node] >= 0 else nxt[node]
    assert (seen == 1).all()
    position = np.empty(h.count, int)
    position[order] = np.arange(h.count)
    inner = np.flatnonzero(first >= 0)
    assert (position[first[inner]] == position[inner] + 1).all()


def _world(problem, points):
    """Points of ``problem``'s frame in world coordinates."""
    return points + problem.scene.origin


def _local(problem, world):
    return (world - problem.scene.origin).astype(np.float32)


def test_refit_after_moving_vertices_equals_a_rebuild():
    flat, moved = _scene(0.05), _scene(0.3)
    els, problem, h = _tree(flat)
    problem.move(moved)
    rebuilt = Problem(moved, CPU)
    nodes, fresh_nodes = h.nodes, rebuilt.tree.nodes
    np.testing.assert_allclose(nodes.area.numpy()[h.root], fresh_nodes.area.numpy()[rebuilt.tree.root], rtol=1e-5)
    np.testing.assert_allclose(_world(problem, nodes.position.numpy()[h.root]),
                               _world(rebuilt, fresh_nodes.position.numpy()[rebuilt.tree.root]), atol=1e-5)
    world = _world(rebuilt, rebuilt.elements.position)
    normals = rebuilt.elements.normal
    refitted = gather.gather(problem, _local(problem, world), normals, 10.0).accessibility
    fresh = gather.gather(rebuilt, _local(rebuilt, world), normals, 10.0).accessibility
    stale_problem = Problem(flat, CPU)
    stale = gather.gather(stale_problem, _local(stale_problem, world), normals, 10.0).accessibility
    # The two trees cluster differently (refit keeps the old Morton order), so they agree within
    # the tree's own approximation (test_ao: tree vs all pairs), not bit for bit.
    assert np.abs(refitted - fresh).mean() < 0.005
    assert np.abs(refitted - fresh).max() < 0.05
    assert np.abs(stale - fresh).mean() > 0.02  # the motion matters: the test can fail


def test_refit_keeps_exact_node_values_for_a_translation():
    """A rigid translation keeps the Morton order: refit and rebuild give the same nodes."""
    sc = _scene(0.2)
    _, problem, h = _tree(sc)
    shift = np.array([0.5, -1.0, 2.0], np.float32)
    sc.positions = sc.positions + shift
    problem.move(sc)
    rebuilt = Problem(sc, CPU)
    assert np.array_equal(h.nodes.element.numpy(), rebuilt.tree.nodes.element.numpy())
    np.testing.assert_allclose(_world(problem, h.nodes.position.numpy()),
                               _world(rebuilt, rebuilt.tree.nodes.position.numpy()), atol=1e-5)
    np.testing.assert_allclose(h.nodes.radius.numpy(), rebuilt.tree.nodes.radius.numpy(), atol=1e-5)
    np.testing.assert_allclose(h.cone.numpy(), rebuilt.tree.cone.numpy(), atol=1e-5)
    np.testing.assert_allclose(h.plane.numpy(), rebuilt.tree.plane.numpy(), atol=1e-5)
