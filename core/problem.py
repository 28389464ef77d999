"""The bake problem: built once per bake, shared by every stage and solver.

It holds the scene (recentred: see ``SceneData.recentred``) as given and as the solver sees it
(its triangles near contacts split: ``core.refine``), the settings, the device, the stages
(progress, cancellation, timings, warnings), the shading vertices and elements, and everything the
kernels read, uploaded to the device once: the BVH of all triangles, the lights, and the elements
as one ``surfels.Surfels`` struct. Direct light per element (and at points of the triangles
across which it varies), the cluster tree and (for link-based solvers) links are computed the
first time they are asked for and kept (links per oracle, until the scene moves).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np
import warp as wp

from . import device as device_mod
from . import direct as direct_mod
from . import elements as elements_mod
from . import scene as scene_mod
from . import refine as refine_mod
from . import surfels as surfels_mod
from .errors import BakeError
from .scene import SceneData
from .settings import Settings
from .stages import Stages

wp.set_module_options({"enable_backward": False})  # no gradients: halves compile time


class Problem:
    """One bake of ``scene`` with ``settings`` (validated here).

    source: the recentred SceneData, whose vertices and triangles targets want results on;
    refinement: its triangles split near contacts (``refine.Refinement``, ``contact_levels``);
    scene: ``source`` so split, what the solver and the BVH work on (the source's vertices first,
    so a source triangle's vertices keep their indices); shading: ``source``'s
    ``elements.ShadingVertices``; elements: ``elements.Elements`` (host arrays) of ``scene``, one
    per its shading vertex, ``shading``'s first (element i is shading vertex i below
    ``shading.count``); surfels: the same on the device (``surfels.Surfels``); mesh: the
    ``wp.Mesh`` BVH; lights: ``direct.Lights``; far: a length (m) beyond the scene; stages:
    ``core.stages.Stages``; counts: what was made and traced, for the report.
    """

    def __init__(self, scene: SceneData, settings: Settings, stages: Stages | None = None):
        self.settings = settings.validate()
        self.stages = stages if stages is not None else Stages()
        try:
            scene.validate()
        except ValueError as exc:
            raise BakeError(str(exc)) from None
        if scene.num_triangles == 0:
            raise BakeError("nothing to bake: the scene has no triangles")
        st = self.stages
        self.source = source = _reflecting(scene, st).recentred()
        _warn_imprecise(source, st)
        self.device = st.run("device", device_mod.select, settings.device)
        st.run("kernels", device_mod.load_kernels, self.device,
               lambda: st.report("compiling kernels (first bake only, cached afterwards)", 0.0))
        degenerate = ~(source.triangle_areas() > 0)
        if degenerate.any():
            names = sorted({source.object_names[i] for i in np.unique(source.tri_object[degenerate])})
            st.warn(f"{int(degenerate.sum())} zero-area triangles ignored in {', '.join(names)}")
        d = self.device.name
        self.shading = st.run("elements", elements_mod.shading_vertices, source)
        self.mesh = st.run("bvh", _mesh, source, d)
        self.refinement = st.run("refine", refine_mod.contacts, source, self.mesh, settings.contact_levels,
                                 self.device)
        scene, self._solving = self._refined(source, self.shading)
        if self.refinement.starts[-1]:
            self.mesh = st.run("bvh", _mesh, scene, d)
        self._fans = st.run("elements", elements_mod.fans, scene, self._solving)
        self.elements = els = st.run("elements", elements_mod.build, scene, self._solving, self._fans)
        extent = float(np.linalg.norm(scene.positions.max(axis=0) - scene.positions.min(axis=0))) or 1.0
        self.far = extent * 1e3 + 1e3
        self.scene = scene = _escaping(scene, self.mesh, self.far, d, st)
        self.source = replace(source, lamps=scene.lamps)
        self.lights = st.run("bvh", direct_mod.Lights, scene, self.device)
        self.surfels = surfels_mod.upload(els, self.mesh, d)
        # The solution of the previous frame of an animation (``pipeline.Sequence``), which
        # iterating solvers start from, and what moved since that frame; None for a first or
        # single frame.
        self.previous = None
        self.motion: Motion | None = None
        self._links = {}
        self.counts = {"objects": len(scene.object_names), "triangles": source.num_triangles,
                       "vertices": source.num_vertices, "shading_vertices": self.shading.count,
                       "contact_triangles": scene.num_triangles - source.num_triangles,
                       "elements": els.count, "lamps": len(scene.lamps),
                       "emissive_triangles": self.lights.num_emitters, "rays": 0}

    def _refined(self, source: SceneData, shading) -> tuple:
        """(the scene the solver works on: ``source`` with ``refinement`` applied, its shading
        vertices, those of ``source`` (``shading``) first and in order)."""
        if not self.refinement.starts[-1]:
            return source, shading
        scene = self.refinement.apply(source)
        return scene, refine_mod.shading(self.refinement, shading, elements_mod.shading_vertices(scene),
                                         source.num_vertices)

    def shading_of(self, scene: SceneData):
        """The shading vertices of ``scene`` when it has this problem's vertices, triangles and
        split (so the problem can ``move`` to it), else None. A flat-shaded mesh that deforms can
        change its split (coplanar faces stop being coplanar): its elements change then."""
        if scene.num_vertices != self.source.num_vertices or not np.array_equal(scene.triangles,
                                                                                 self.source.triangles):
            return None
        shading = elements_mod.shading_vertices(scene)
        return shading if np.array_equal(shading.corner, self.shading.corner) else None

    def move(self, scene: SceneData, shading=None) -> None:
        """Take the positions, normals, materials and lamps of ``scene`` — the same triangles and
        vertices, deformed or moved (an animation frame) — keeping this problem's frame, device
        arrays, contact refinement and BVH (refitted) and the tree (refitted) if built; ``shading``:
        the scene's split when known (``shading_of``). Direct light is traced again when next asked
        for."""
        if (scene.num_vertices, scene.num_triangles) != (self.source.num_vertices, self.source.num_triangles):
            raise BakeError("the scene's topology changed: build a new problem")
        try:
            scene.validate()
        except ValueError as exc:
            raise BakeError(str(exc)) from None
        scene = _reflecting(scene, self.stages)
        shift = np.asarray(scene.origin, np.float64) - self.source.origin
        positions = (np.asarray(scene.positions, np.float64) + shift).astype(np.float32)
        lamps = replace(scene.lamps, position=(np.asarray(scene.lamps.position, np.float64)
                                                + shift).astype(np.float32))
        source = replace(scene, positions=positions, lamps=lamps, origin=self.source.origin)
        shading = shading if shading is not None else elements_mod.shading_vertices(source)
        if not np.array_equal(shading.corner, self.shading.corner):
            raise BakeError("the scene's shading vertices changed: build a new problem")
        # the split is the scene's; its positions are taken in this problem's frame
        self.shading = shading = replace(shading, position=np.ascontiguousarray(positions[shading.vertex]))
        scene, solving = self._refined(source, shading)
        if not np.array_equal(solving.corner, self._solving.corner):
            raise BakeError("the scene's shading vertices changed: build a new problem")
        self._solving = solving
        before_scene, before_elements = self.scene, self.elements
        self.elements = els = elements_mod.build(scene, solving, self._fans)  # the same topology
        self.motion = motion(before_scene, scene, before_elements, els)
        self.mesh.points.assign(scene.positions)
        self.mesh.refit()
        self.scene = scene = _escaping(scene, self.mesh, self.far, self.device.name, self.stages)
        self.source = replace(source, lamps=scene.lamps)
        self.lights = direct_mod.Lights(scene, self.device)
        surfels_mod.assign(self.surfels, els)
        self.__dict__.pop("direct", None)
        self.__dict__.pop("near", None)
        self.__dict__.pop("open_fraction", None)
        self.counts["rays"] = 0
        self._links.clear()  # links are made again from scratch over the refitted tree
        if "tree" in self.__dict__:
            from . import hierarchy

            hierarchy.refit(self.tree, self.surfels)

    @cached_property
    def contact(self) -> np.ndarray:
        """bool[n]: the elements with a triangle split near a contact (``core.refine``)."""
        per = np.zeros(self.elements.count, bool)
        np.logical_or.at(per, self.elements.corner.reshape(-1), np.repeat(self.refinement.split, 3))
        return per

    @property
    def element_sizes(self) -> np.ndarray:
        """float32[n]: each element's size √area (m), its local feature size for ray offsets."""
        return np.sqrt(self.elements.area)

    @cached_property
    def direct(self) -> np.ndarray:
        """float32[n,3]: direct lighting (irradiance/π) at each element, traced once."""
        els = self.elements
        light, rays = self.stages.run("direct", direct_mod.direct_lighting, self, els.position,
                                      els.normal, self.element_sizes, self.stages.reporter("direct"))
        self.counts["rays"] += rays
        return light

    @cached_property
    def near(self):
        """The direct light of triangles across which it varies, at fixed points
        (``nearfield.Detail``), traced once: what final gathers near them see."""
        from . import nearfield

        return self.stages.run("near field", nearfield.build, self)

    @cached_property
    def open_fraction(self) -> wp.array:
        """float32[n] on the device: the share of each element's view not shut inside a closed
        surface (``enclosure.open_fraction``), traced once — or set by a solver whose rays tell
        it (the hierarchical solver's final gather, ``hits.Hits.free``)."""
        from . import enclosure

        return wp.array(self.stages.run("enclosure", enclosure.open_fraction, self), dtype=wp.float32,
                        device=self.device.name)

    @cached_property
    def tree(self):
        """The cluster tree over the elements (``hierarchy.Tree``), built once."""
        from . import hierarchy

        tree = self.stages.run("hierarchy", hierarchy.build, self)
        self.counts["nodes"] = tree.count
        return tree

    def links(self, oracle, radiance=None):
        """The links over ``tree`` chosen by ``oracle`` (``links.Oracle``, the cache key), built the
        first time each is asked for and kept until the scene moves (``links.Links``).
        ``radiance()`` gives the first radiance estimate (float32[n,3]) an oracle with
        ``brightness`` is built with; it is called only when the links are built."""
        if oracle not in self._links:
            from . import links as links_mod

            estimate = radiance() if radiance is not None else None
            made = self.stages.run("links", links_mod.build, self, oracle, estimate)
            self.counts["links"] = made.count
            self.counts["rays"] += made.rays_traced
            self._links[oracle] = made
        return self._links[oracle]



@dataclass
class Motion:
    """What moved between two frames of one problem (``Problem.move``). faces: bool[T] the
    triangles with a corner that moved; elements: bool[n] the elements whose position, normal or
    area changed (their rays are other rays)."""

    faces: np.ndarray
    elements: np.ndarray


# What counts as not moved: a few float32 steps of the coordinates (an object's static vertices
# round differently when the scene's frame is re-centred as others move).
STILL = 2.0 ** -20


def _apart(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """bool[k]: the points of a and b (float32[k,3], m) further apart than STILL × their size."""
    scale = np.maximum(np.abs(a).max(axis=1), np.abs(b).max(axis=1)) + 1e-6
    return np.abs(a - b).max(axis=1) > STILL * scale


def motion(before: SceneData, scene: SceneData, before_elements, elements) -> Motion:
    """The ``Motion`` from ``before`` to ``scene`` (the same triangles, as the solver sees them)
    and from ``before_elements`` to ``elements`` (``elements.Elements``)."""
    moved = _apart(before.positions, scene.positions)
    faces = moved[scene.triangles].any(axis=1)
    changed = (_apart(before_elements.position, elements.position)
               | (np.abs(before_elements.normal - elements.normal).max(axis=1) > STILL)
               | (np.abs(before_elements.area - elements.area) > STILL * 4 * elements.area))
    return Motion(faces, changed)

def _reflecting(scene: SceneData, stages: Stages) -> SceneData:
    """``scene`` without light it cannot bake (``SceneData.emitting``) and with its albedo clamped
    into [0, 1] (``SceneData.reflecting``), warning with the names of the lamps and objects
    changed."""
    scene, messages = scene.emitting()
    for message in messages:
        stages.warn(message)
    scene, names = scene.reflecting()
    if names:
        stages.warn(f"albedo outside [0, 1] clamped to it in {', '.join(names)}: a surface cannot "
                    "reflect more light than it receives (Cycles clamps a Principled Base Color "
                    "the same way)")
    return scene


def _warn_imprecise(scene: SceneData, stages: Stages) -> None:
    """Warn naming the objects of ``scene`` (recentred) that lie so far from its detail, for their
    size, that a ray leaving them starts more than ``scene_mod.PRECISION`` of their size above them
    (``rays.lift``: the float32 spacing at that distance): their shadows and contacts smaller
    than that are lost."""
    far, size, _ = scene_mod.object_reach(scene.positions, scene.triangles, scene.tri_object,
                                       len(scene.object_names), np.zeros(3))
    bad = np.flatnonzero(scene_mod.losing_detail(far, size))
    if not len(bad):
        return
    lift = far * scene_mod.RAY_LIFT
    bad = bad[np.argsort(size[bad] / lift[bad])]
    named = ", ".join(f"'{scene.object_names[i]}' ({far[i] / 1e3:,.0f} km away, {size[i]:.3g} m, "
                      f"detail under {lift[i]:.2g} m lost)" for i in bad[:5])
    more = f" and {len(bad) - 5} more" if len(bad) > 5 else ""
    stages.warn(f"{len(bad)} object(s) too far from the rest of the scene for float32 precision: "
                f"{named}{more}; their shadows and contacts are not kept: bake them apart, or bring "
                "them closer")


def _escaping(scene: SceneData, mesh: wp.Mesh, far: float, device: str, stages: Stages) -> SceneData:
    """``scene`` without its lamps inside a closed surface (``enclosure.enclosed_lamps``), warning
    with their names."""
    from . import enclosure

    inside = stages.run("bvh", enclosure.enclosed_lamps, scene.lamps, mesh, far, device)
    if not inside.any():
        return scene
    names = [scene.lamps.names[i] if i < len(scene.lamps.names) else f"lamp {i}"
             for i in np.flatnonzero(inside)]
    one = len(names) == 1
    stages.warn(f"{', '.join(names)} {'is' if one else 'are'} inside a closed surface, whose inside "
                f"sends and passes no light: left out, as {'it has' if one else 'they have'} no "
                "effect in Cycles either (to light that surface from inside, flip its normals)")
    return replace(scene, lamps=scene.lamps.take(~inside))


def _mesh(scene: SceneData, device: str) -> wp.Mesh:
    points = wp.array(np.ascontiguousarray(scene.positions, np.float32), dtype=wp.vec3, device=device)
    indices = wp.array(np.ascontiguousarray(scene.triangles, np.int32).reshape(-1), dtype=wp.int32,
                       device=device)
    return wp.Mesh(points=points, indices=indices)
