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
    """A solver registered the way README's developer section shows: indirect light 0.25
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
