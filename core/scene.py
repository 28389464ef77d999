"""SceneData: what the bake needs of a Blender scene, as plain numpy arrays (no bpy references).

Units: metres. Colours are linear Rec.709 RGB. Positions are relative to ``origin`` (world =
origin + position): extraction subtracts a point amid the scene's detail (``detail_centre``) in
double precision, so a scene far from the world origin keeps the float32 precision of one at the
origin.

Vertices are mesh vertices; each triangle corner carries its own shading normal. Splitting a vertex
whose corners carry different normals (a hard edge) into shading vertices is core's job
(``core.elements.shading_vertices``).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

LAMP_POINT, LAMP_SPOT, LAMP_SUN, LAMP_AREA = 0, 1, 2, 3
SHAPE_RECTANGLE, SHAPE_ELLIPSE = 0, 1


# A ray leaving a point starts this share of its coordinates' magnitude above it (``core.rays``:
# about 128 float32 ulps). Detail smaller than that lift is lost: an object whose lift passes
# PRECISION of its own size loses its shadows and contacts (a warning), and one whose lift passes
# PRECISION of its mean edge moves the scene's frame where that helps (``detail_centre``).
RAY_LIFT = 2.0 ** -16
PRECISION = 0.05


def object_reach(positions: np.ndarray, triangles: np.ndarray, tri_object: np.ndarray, count: int,
                 centre) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(far, size, edge), float64[count] each (m): how far each object's farthest corner lies from
    ``centre`` float[3] (its largest coordinate, as ``core.rays.lift`` measures it), the diagonal
    of its bounds and the mean length of its triangles' edges (inf for an object without
    triangles). positions float[V,3] (m), triangles int[T,3], tri_object int[T]."""
    corners = np.asarray(positions, np.float64)[triangles] - np.asarray(centre, np.float64)
    far, lo, hi = np.zeros(count), np.full((count, 3), np.inf), np.full((count, 3), -np.inf)
    np.maximum.at(far, tri_object, np.abs(corners).max(axis=(1, 2)))
    np.minimum.at(lo, tri_object, corners.min(axis=1))
    np.maximum.at(hi, tri_object, corners.max(axis=1))
    empty = ~np.isfinite(lo).all(axis=1)
    size = np.where(empty, np.inf, np.linalg.norm(hi - lo, axis=1))
    edges = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).sum(axis=1)  # [T]
    with np.errstate(invalid="ignore", divide="ignore"):
        edge = np.bincount(tri_object, edges, count) / (3.0 * np.bincount(tri_object, None, count))
    return far, size, np.where(empty, np.inf, edge)


def losing_detail(far: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """bool[count]: the objects of :func:`object_reach` whose rays start more than PRECISION of
    ``scale`` (their size, or their mean edge) above them."""
    return far * RAY_LIFT > PRECISION * scale


def detail_centre(positions: np.ndarray, triangles: np.ndarray, tri_object: np.ndarray,
                  count: int) -> np.ndarray:
    """float64[3]: the point a scene's coordinates are taken from (m). The centre of the bounds of
    its vertices float[V,3], which spreads float32 precision evenly over the scene, unless some
    object would lose detail of its own edges' size there (:func:`losing_detail`: one huge plane
    1 km under a small scene puts that centre 500 m from everything lit) and fewer would at the
    per-axis median of the vertices, where most of the detail is. triangles int[T,3], tri_object
    int[T]: the objects, ``count`` of them."""
    p = np.asarray(positions, np.float64)

    def lost(centre):
        far, _, edge = object_reach(p, triangles, tri_object, count, centre)
        return int(losing_detail(far, edge).sum())

    bounds = 0.5 * (p.min(axis=0) + p.max(axis=0))
    at_bounds = lost(bounds)
    if not at_bounds:
        return bounds
    median = np.median(p, axis=0)
    return median if lost(median) < at_bounds else bounds


@dataclass
class Lamps:
    """L lamps, as Blender defines them.

    kind: int32[L], LAMP_POINT / LAMP_SPOT / LAMP_SUN / LAMP_AREA.
    position: float32[L,3], position (m, relative to the scene's ``origin``).
    direction: float32[L,3], unit vector the lamp points along (its local −Z); sun: towards the scene.
    axis_u, axis_v: float32[L,3], unit local X and Y axes in world space (area lamp extent).
    size: float32[L,2], area: full size along X and Y (m, square/disk repeat it); point/spot: radius
        (m) in [:,0]; sun: angular diameter (rad) in [:,0].
    shape: int32[L], area lamps: SHAPE_RECTANGLE or SHAPE_ELLIPSE.
    power: float32[L,3], colour × power: W for point, spot and area; W/m² (strength) for sun.
    spot_size: float32[L], full cone angle (rad); spot_blend: float32[L] in [0,1].
    names: list of L lamp names (for messages).
    """

    kind: np.ndarray
    position: np.ndarray
    direction: np.ndarray
    axis_u: np.ndarray
    axis_v: np.ndarray
    size: np.ndarray
    shape: np.ndarray
    power: np.ndarray
    spot_size: np.ndarray
    spot_blend: np.ndarray
    names: list = field(default_factory=list)

    # the per-lamp arrays, in field order
    ARRAYS = ("kind", "position", "direction", "axis_u", "axis_v", "size", "shape", "power", "spot_size",
              "spot_blend")

    @staticmethod
    def empty() -> "Lamps":
        z3 = np.zeros((0, 3), np.float32)
        return Lamps(np.zeros(0, np.int32), z3, z3.copy(), z3.copy(), z3.copy(),
                     np.zeros((0, 2), np.float32), np.zeros(0, np.int32), z3.copy(),
                     np.zeros(0, np.float32), np.zeros(0, np.float32), [])

    @staticmethod
    def concat(items: list["Lamps"]) -> "Lamps":
        if not items:
            return Lamps.empty()
        out = {}
        for name in Lamps.ARRAYS:
            out[name] = np.concatenate([getattr(x, name) for x in items])
        return Lamps(**out, names=[n for x in items for n in x.names])

    def take(self, keep: np.ndarray) -> "Lamps":
        """The lamps where bool[L] ``keep`` is true, in order."""
        keep = np.asarray(keep, bool)
        out = {name: getattr(self, name)[keep] for name in Lamps.ARRAYS}
        return Lamps(**out, names=[n for n, k in zip(self.names, keep) if k])

    def __len__(self) -> int:
        return int(self.kind.shape[0])


@dataclass
class SceneData:
    """Triangles and lamps of a scene.

    positions: float32[V,3] mesh-vertex positions (m, relative to ``origin``).
    triangles: int32[T,3] vertex indices, counter-clockwise seen from the front.
    corner_normals: float32[T,3,3] unit shading normal of each triangle corner.
    tri_object: int32[T] index into ``object_names`` of the object each triangle came from.
    albedo: float32[T,3] diffuse reflectance; the bake clamps it into [0,1] (``reflecting``).
    emission: float32[T,3] emitted radiance (W m⁻² sr⁻¹, Blender's Emission Strength × Color),
        leaving both faces.
    lamps: the scene's lamps.
    object_names: names of the objects (or instances) the triangles came from.
    ao_distance: the world's ambient occlusion distance (m, Blender's world.light_settings.distance):
        occluders farther away do not count.
    origin: float64[3], the world position positions are relative to.
    """

    positions: np.ndarray
    triangles: np.ndarray
    corner_normals: np.ndarray
    tri_object: np.ndarray
    albedo: np.ndarray
    emission: np.ndarray
    lamps: Lamps
    object_names: list = field(default_factory=list)
    ao_distance: float = 10.0
    origin: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @property
    def num_vertices(self) -> int:
        return int(self.positions.shape[0])

    @property
    def num_triangles(self) -> int:
        return int(self.triangles.shape[0])

    def triangle_areas(self) -> np.ndarray:
        """float64[T]: area of each triangle (m²); 0 for triangles with non-finite corners."""
        p = np.asarray(self.positions, np.float64)[self.triangles]
        finite = np.isfinite(p).all(axis=(1, 2))
        p = np.where(finite[:, None, None], p, 0.0)
        return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)

    def validate(self) -> None:
        """Raise ValueError naming the object for NaN / infinite geometry or inconsistent arrays."""
        v, t = self.num_vertices, self.num_triangles
        shapes = {"positions": (v, 3), "triangles": (t, 3), "corner_normals": (t, 3, 3),
                  "tri_object": (t,), "albedo": (t, 3), "emission": (t, 3)}
        for name, shape in shapes.items():
            if getattr(self, name).shape != shape:
                raise ValueError(f"SceneData.{name} has shape {getattr(self, name).shape}, expected {shape}")
        if t and (self.triangles.min() < 0 or self.triangles.max() >= v):
            raise ValueError("SceneData.triangles index outside positions")
        # Blender stores overflowing coordinates as ±FLT_MAX: as unusable as NaN.
        limit = np.float32(np.finfo(np.float32).max) / 2
        with np.errstate(invalid="ignore"):
            bad_v = ~(np.abs(self.positions) < limit).all(axis=1)
        if bad_v.any():
            bad_t = bad_v[self.triangles].any(axis=1)
            names = sorted({self.object_names[i] for i in np.unique(self.tri_object[bad_t])})
            raise ValueError(f"NaN or infinite vertex positions in {', '.join(names) or 'the scene'}")

    def emitting(self) -> tuple["SceneData", list]:
        """This scene without the light it cannot bake: lamps whose power is negative or not a
        finite number left out, triangles' emission that is negative or not finite set to none
        (beyond FLT_MAX/2 counts as infinite: Blender stores infinity as FLT_MAX).
        Also the messages naming them (empty when nothing changed)."""
        messages = []
        limit = np.finfo(np.float32).max / 2  # Blender stores an infinite value as ±FLT_MAX
        power = np.asarray(self.lamps.power, np.float64)
        with np.errstate(invalid="ignore"):
            bad_lamp = ~((power < limit) & (power >= 0)).all(axis=1)
        scene = self
        if bad_lamp.any():
            named = [f"'{self.lamps.names[i] if i < len(self.lamps.names) else f'lamp {i}'}' "
                     f"(power {_power_text(power[i])})" for i in np.flatnonzero(bad_lamp)]
            messages.append(f"lamp {', '.join(named)} left out: a lamp's power (a sun's strength) "
                            "must be a finite number ≥ 0 (a negative one would take light away)")
            scene = replace(scene, lamps=self.lamps.take(~bad_lamp))
        emission = np.asarray(self.emission, np.float64)
        with np.errstate(invalid="ignore"):
            bad_tri = ~((emission < limit) & (emission >= 0)).all(axis=1)
        if bad_tri.any():
            names = sorted({self.object_names[i] for i in np.unique(self.tri_object[bad_tri])})
            messages.append(f"emission that is negative, infinite or not a number in "
                            f"{', '.join(names)}: left out (no light from those faces)")
            fixed = np.where(bad_tri[:, None], 0.0, emission).astype(np.float32)
            scene = replace(scene, emission=fixed)
        return scene, messages

    def reflecting(self) -> tuple["SceneData", list]:
        """This scene with each albedo channel clamped into [0, 1] (NaN read as 0), as Cycles
        clamps a Principled Base Color: a surface reflecting more than it receives would make the
        light grow with every bounce. Also the sorted names of the objects whose albedo changed."""
        with np.errstate(invalid="ignore"):
            outside = ~((self.albedo >= 0) & (self.albedo <= 1)).all(axis=1)
        if not outside.any():
            return self, []
        names = sorted({self.object_names[i] for i in np.unique(self.tri_object[outside])})
        albedo = np.clip(np.nan_to_num(self.albedo, nan=0.0), 0.0, 1.0).astype(np.float32)
        return replace(self, albedo=albedo), names

    def recentred(self) -> "SceneData":
        """This scene with positions relative to :func:`detail_centre` (computed and subtracted in
        double precision; ``origin`` moves to match): kernels then work with the coordinates' full
        float32 precision where the scene's detail is, wherever the scene lies."""
        p = np.asarray(self.positions, np.float64)
        if not len(p):
            return self
        centre = detail_centre(p, self.triangles, self.tri_object, len(self.object_names))
        lamps = replace(self.lamps, position=(np.asarray(self.lamps.position, np.float64)
                                               - centre).astype(np.float32))
        return replace(self, positions=(p - centre).astype(np.float32), lamps=lamps,
                       origin=np.asarray(self.origin, np.float64) + centre)


def _power_text(power: np.ndarray) -> str:
    """A lamp's float[3] colour × power for a message: one number where the channels agree."""
    if np.all(np.isnan(power)):
        return "NaN"
    power = np.where(np.abs(power) >= np.finfo(np.float32).max / 2, np.sign(power) * np.inf, power)
    values = {f"{x:g}" for x in power}
    return values.pop() if len(values) == 1 else "(" + ", ".join(f"{x:g}" for x in power) + ")"
