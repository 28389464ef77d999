"""Contact refinement (``core.refine``): which triangles are split, that the split surface is the
same surface, that results stay on the scene's own vertices, and that it brings a coarse floor
under a hovering block closer to the same floor tessellated finely."""
import numpy as np
import pytest

import shapes
from radiosity_baker.core import Settings, bake
from radiosity_baker.core.lightmap import LightmapRequest
from radiosity_baker.core.pipeline import Sequence
from radiosity_baker.core.problem import Problem
from radiosity_baker.core.scene import LAMP_SUN

FLOOR_ALBEDO, BOX_ALBEDO = (0.6,) * 3, (0.7,) * 3


def hovering(floor_quads: int, gap: float, size: float = 0.3):
    """A 2 m floor of ``floor_quads``² quads under a sun, and a box of side ``size`` (3×3 quads a
    face) whose bottom hangs ``gap`` above the floor's centre."""
    fp, fn, ft = shapes.grid(2.0, floor_quads)
    parts = [(fp, fn, ft, FLOOR_ALBEDO, (0,) * 3)]
    parts += [(*f, BOX_ALBEDO, (0,) * 3) for f in shapes.box(size, 3, (0.05, 0.05, gap + size / 2))]
    sun = shapes.lamp(LAMP_SUN, direction=(0.4, -0.3, -0.87), power=(3,) * 3)
    return shapes.scene(parts, sun)


def split_parents(problem) -> np.ndarray:
    """The source triangles the refinement split."""
    return np.flatnonzero(np.bincount(problem.refinement.parent, minlength=problem.source.num_triangles) > 1)


def test_the_coarser_side_of_a_gap_is_split_into_the_same_surface_without_cracks():
    """A floor of 0.5 m quads 2 cm under a box of 0.1 m quads: floor triangles under the box are
    split (twice near the gap), the box's finer ones and the floor's far corners are not; each
    split triangle's pieces cover exactly its area, the scene's own vertices come first and
    unmoved, and the floor's border is all that is left open (no edge ends inside another)."""
    scene = hovering(4, 0.02)
    problem = Problem(scene, Settings(contact_levels=2, device="cpu"))
    source, refined = problem.source, problem.scene
    split = split_parents(problem)
    assert len(split) and (source.tri_object[split] == 0).all()
    centre = source.positions[source.triangles[split]].mean(axis=1)
    assert np.abs(centre[:, :2] - 0.05).max() < 0.75  # under the box or next to it
    assert refined.num_triangles > source.num_triangles + 3 * len(split)  # some were split twice
    np.testing.assert_array_equal(refined.positions[:source.num_vertices], source.positions)
    area = np.bincount(problem.refinement.parent, weights=refined.triangle_areas())
    np.testing.assert_allclose(area, source.triangle_areas(), rtol=1e-5)
    floor = refined.triangles[refined.tri_object == 0]
    edges = np.sort(np.concatenate([floor[:, [0, 1]], floor[:, [1, 2]], floor[:, [2, 0]]]), axis=1)
    uniq, uses = np.unique(edges, axis=0, return_counts=True)
    assert uses.max() == 2
    border = refined.positions[uniq[uses == 1]]
    np.testing.assert_allclose(np.linalg.norm(border[:, 0] - border[:, 1], axis=1).sum(), 8.0, rtol=1e-5)
    assert problem.counts["contact_triangles"] == refined.num_triangles - source.num_triangles


def test_split_copy_keeps_the_scenes_shading_vertices_first_across_hard_edges():
    """A flat-shaded 1 m cube of 12 triangles (each corner vertex three shading vertices, one per
    face) 2 cm over a floor of 12.5 cm quads: the cube's bottom is the coarser side and is split,
    the floor is not; the split copy's first elements are the scene's shading vertices — same
    vertex and normal, and points within the 1 % border nudge (``elements.NUDGE``: a face's
    corner moves towards its largest triangle, which the split makes smaller) — and the bake's
    vertex results are per those."""
    corners = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], np.float32)
    cube_p = corners - np.float32([0.5, 0.5, -0.02])
    cube_t = np.array([[0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6], [0, 1, 5], [0, 5, 4],
                       [2, 6, 7], [2, 7, 3], [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5]], np.int32)
    fp, fn, ft = shapes.grid(2.0, 16)
    scene = shapes.scene([(fp, fn, ft, FLOOR_ALBEDO, (0,) * 3),
                          (cube_p, shapes.flat(cube_p, cube_t), cube_t, BOX_ALBEDO, (0,) * 3)],
                         shapes.lamp(LAMP_SUN, direction=(0.4, -0.3, -0.87), power=(3,) * 3))
    problem = Problem(scene, Settings(contact_levels=2, device="cpu"))
    split = split_parents(problem)
    assert len(split) and (problem.source.tri_object[split] == 1).all()
    shading, els = problem.shading, problem.elements
    assert shading.count == len(fp) + 24 and els.count > shading.count
    np.testing.assert_array_equal(els.vertex[:shading.count], shading.vertex)
    np.testing.assert_array_equal(els.normal[:shading.count], shading.normal)
    np.testing.assert_allclose(els.position[:shading.count], shading.position, atol=0.01 * 2 ** 0.5)
    lighting = bake(scene, Settings(contact_levels=2, device="cpu", light_samples=16))["vertices"].lighting
    assert lighting.shape == (shading.count, 3) and np.isfinite(lighting).all()


def test_faces_pressed_together_are_not_split():
    """A box resting on the floor hides the floor under it: nothing there can be seen, so
    nothing is split (the rays meet the box closer than TOUCH × the triangle)."""
    problem = Problem(hovering(4, 0.0), Settings(contact_levels=2, device="cpu"))
    assert not len(split_parents(problem))
    assert problem.scene is problem.source or problem.scene.num_triangles == problem.source.num_triangles


def floor_light(result, quads: int, fine: int) -> np.ndarray:
    """Lighting at the vertices of a ``quads``² floor taken from a bake of a ``fine``² floor
    (its vertices nest: every (fine/quads)-th one)."""
    lighting = result["vertices"].lighting[:(fine + 1) ** 2, 0].reshape(fine + 1, fine + 1)
    step = fine // quads
    return lighting[::step, ::step].ravel()


def test_refined_contact_bakes_the_coarse_floor_as_a_fine_floor_does():
    """The floor of 4×4 quads 2 cm under the box against the same floor of 32×32 quads (its
    vertices include the coarse one's; bakes at leaf-fine links, threshold 0.01): at the coarse
    vertices within 0.6 m of the box, the refined bake is nearer the fine one than the unrefined
    bake is. Results come back on the scene's own shading vertices only. Measured: relative
    RMSE 12.1 % unrefined, 3.4 % refined; bound: below half the unrefined error."""
    common = dict(device="cpu", light_samples=16, link_threshold=0.01)
    fine = bake(hovering(32, 0.02), Settings(**common))
    truth = floor_light(fine, 4, 32)
    scene = hovering(4, 0.02)
    coarse = bake(scene, Settings(contact_levels=0, **common))
    refined = bake(scene, Settings(contact_levels=2, **common))
    assert refined["vertices"].lighting.shape == coarse["vertices"].lighting.shape
    assert refined.counts["contact_triangles"] > 0
    p = scene.positions[:25]
    near = np.linalg.norm(p[:, :2] - 0.05, axis=1) < 0.6
    errors = {}
    for name, r in (("coarse", coarse), ("refined", refined)):
        d = floor_light(r, 4, 4)[near] - truth[near]
        errors[name] = np.sqrt((d ** 2).mean()) / truth[near].mean()
    assert errors["refined"] < 0.5 * errors["coarse"], errors


def test_an_animation_frame_keeps_the_refinement_and_bakes_as_a_fresh_problem():
    """The next frame moves everything 0.3 m along x (the gap unchanged): the problem moves
    (no new problem) with its refinement, and the frame's light equals a fresh bake's — to the
    solver's convergence: the frame starts its sweeps from the previous frame's solution
    (measured within 0.09 %; bound 0.2 %)."""
    settings = Settings(contact_levels=2, device="cpu", light_samples=16)
    scene = hovering(4, 0.02)
    moved = hovering(4, 0.02)
    moved.positions = moved.positions + np.float32([0.3, 0.0, 0.0])
    frames = Sequence(settings)
    frames.bake(scene)
    first = frames.problem
    light = frames.bake(moved)["vertices"].lighting
    assert frames.problem is first and first.counts["contact_triangles"] > 0
    np.testing.assert_allclose(light, bake(moved, settings)["vertices"].lighting, rtol=2e-3)


def test_lightmap_texels_on_split_triangles_get_light(tmp_path):
    """Texels of the floor, whose triangles under the box are split for the solver, get finite
    light; away from the box they agree with the unrefined bake (bound 5 %)."""
    from test_hierarchical import floor_target

    scene = hovering(4, 0.02)
    pages = {}
    for levels in (0, 2):
        r = bake(scene, Settings(contact_levels=levels, device="cpu", texel_density=12.0, light_samples=16),
                 targets=shapes.with_lightmap(LightmapRequest([floor_target(scene)], cache_dir=tmp_path)))
        pages[levels] = r["lightmap"].pages[0]
    covered = pages[2].covered
    assert np.isfinite(pages[2].rgb[covered]).all() and (pages[2].rgb[covered] >= 0).all()
    a, b = pages[0].rgb[..., 0][covered], pages[2].rgb[..., 0][covered]
    lit = a > 0.5 * a.max()
    assert np.median(np.abs(b[lit] / a[lit] - 1)) < 0.05
