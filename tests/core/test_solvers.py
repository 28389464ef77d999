"""The solver contract: every method plugs in through the registry, the pipeline dispatches once,
and a new solver is one module with solve/evaluate plus one registry line."""
import inspect
import sys
import types

import numpy as np
import pytest

import shapes
from radiosity_baker.core import Settings, bake, pipeline
from radiosity_baker.core.lightmap import LightmapRequest, LightmapObject
from radiosity_baker.core.scene import LAMP_POINT
from radiosity_baker.core.solvers import SOLVERS, SolverInfo, base


def lit_floor():
    p, n, t = shapes.grid(2.0, 6)
    return shapes.scene([(p, n, t, (0.5, 0.4, 0.3), (0,) * 3)],
                        shapes.lamp(LAMP_POINT, (0, 0, 1.5), power=(80,) * 3)), len(t)


def test_the_pipeline_holds_no_branch_per_solver():
    source = inspect.getsource(pipeline)
    for name in SOLVERS:
        assert f'"{name}"' not in source and f"'{name}'" not in source


@pytest.fixture
def constant_solver(monkeypatch):
    """A solver registered the way the manual's Development page shows: indirect light 0.25
    everywhere, evaluated by interpolation."""
    module = types.ModuleType("radiosity_baker.core.solvers.constant")
    module.solve = lambda problem: base.Solution(np.full((problem.elements.count, 3), 0.25, np.float32))
    module.evaluate = base.reconstruct
    monkeypatch.setitem(sys.modules, module.__name__, module)
    monkeypatch.setitem(SOLVERS, "constant", SolverInfo("constant", "a constant bounce"))
    return module


def test_a_new_solver_is_one_module_and_one_registry_line(constant_solver, tmp_path):
    scene, nt = lit_floor()
    target = LightmapObject("part0", "part0", corner_vert=scene.triangles.ravel().astype(np.int32),
                            corner_triangles=np.arange(3 * nt, dtype=np.int32).reshape(nt, 3),
                            triangle_offset=0)
    r = bake(scene, Settings(method="constant", content="combined", device="cpu", texel_density=8.0),
             targets=shapes.with_lightmap(LightmapRequest([target], cache_dir=tmp_path)))
    direct = bake(scene, Settings(method="direct", device="cpu"))
    np.testing.assert_allclose(r.indirect, 0.25)
    np.testing.assert_allclose(r.output, np.array([0.5, 0.4, 0.3]) * (direct.lighting + 0.25), rtol=1e-5)
    page, = r["lightmap"].pages
    assert page.rgb[page.covered].min() >= 0.3 * 0.25  # every texel got the bounce too


def test_every_registered_solver_bakes_through_the_same_call():
    scene, _ = lit_floor()
    for name, info in SOLVERS.items():
        r = bake(scene, Settings(method=name, device="cpu"))
        assert r.output.shape == (r.counts["elements"], 3) and np.isfinite(r.output).all()
        if info.light:  # a lone floor sees nothing to bounce light from
            np.testing.assert_allclose(r.lighting, r.direct, atol=1e-6)
            assert r.direct.min() > 0
        else:
            assert (r.output == 1.0).all()  # nothing occludes a lone floor


ITERATING = ("reference", "hierarchical", "implicit", "antiradiance")


def lit_closed_box(albedo: float):
    """One object, "Box": a closed 1 m cube (inward normals, 3×3 quads a face) of uniform
    ``albedo``, lit by a 10 W point lamp at its centre. Returns the scene and its triangles' areas."""
    faces = shapes.box(1.0, 3, inward=True)
    base = np.cumsum([0] + [len(p) for p, _, _ in faces[:-1]])
    p = np.concatenate([f[0] for f in faces])
    n = np.concatenate([f[1] for f in faces])
    t = np.concatenate([f[2] + b for f, b in zip(faces, base)])
    scene = shapes.scene([(p, n, t, (albedo,) * 3, (0,) * 3)], shapes.lamp(LAMP_POINT, power=(10,) * 3))
    scene.object_names = ["Box"]
    return scene


@pytest.mark.parametrize("method", ITERATING)
def test_albedo_above_one_is_clamped_to_one_with_a_warning_naming_the_object(method):
    bounces = 16
    r = bake(lit_closed_box(2.0), Settings(method=method, device="cpu", bounces=bounces))
    assert np.isfinite(r.output).all()
    assert any("albedo" in w and "Box" in w for w in r.warnings), r.warnings
    # albedo 1 in a closed box: every bounce carries the direct light's power on, no more
    area = np.bincount(r.shading.corner.ravel(), minlength=len(r.direct))  # triangles are equal
    mean_direct, mean_indirect = area @ r.direct / area.sum(), area @ r.indirect / area.sum()
    assert (mean_indirect <= 1.05 * bounces * mean_direct).all(), (mean_indirect, mean_direct)
    np.testing.assert_allclose(r.output, r.lighting)  # output is lighting, albedo plays no part


@pytest.mark.parametrize("method", ITERATING)
def test_a_diverging_iteration_stops_with_a_clear_error_not_nan(method):
    from radiosity_baker.core.errors import BakeError
    from radiosity_baker.core.problem import Problem
    from radiosity_baker.core.solvers import get

    problem = Problem(lit_closed_box(0.5), Settings(method=method, device="cpu", bounces=500))
    problem.elements.albedo[:] = 3.0  # past the clamp: light triples with every bounce
    problem.surfels.albedo.fill_(3.0)
    with pytest.raises(BakeError, match=f"method {method} diverged at bounce"):
        get(method).solve(problem)
