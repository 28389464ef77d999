"""One dataclass holds every bake setting; the Blender PropertyGroup and the CLI mirror it."""
from __future__ import annotations

from dataclasses import dataclass, fields

from .errors import SettingsError

METHODS = ("direct", "reference", "bunnell")
# Older name of the reference solver, still accepted.
METHOD_ALIASES = {"bruteforce": "reference"}
CONTENTS = ("lighting", "combined", "indirect", "ao")
TARGETS = ("vertex_colors", "lightmap", "both")
LAYOUTS = ("atlas", "per_object")
HOOKUPS = ("none", "node", "multiply")
LIGHTMAP_FORMATS = ("half", "float")
TEXEL_INDIRECT = ("gather", "interpolate")
DEVICES = ("auto", "cpu", "cuda")


@dataclass
class Settings:
    """Bake settings.

    method: ``direct`` (lamps and emissive triangles only) or ``reference`` (all-pairs multi-bounce
        radiosity with ray-cast visibility, O(n²), small scenes; ``bruteforce`` is the same) or
        ``bunnell`` (one bounce of indirect light gathered over the disk hierarchy, O(n log n), no
        rays; approximate, see README).
    content: ``lighting`` (irradiance/π, Cycles DIFFUSE Direct+Indirect without Color),
        ``combined`` (emission + albedo × lighting), ``indirect`` (lighting minus direct) or ``ao``
        (accessibility in [0,1] in all three channels, what Cycles' AO bake gives).
    target: where results go: ``vertex_colors``, ``lightmap`` (EXR images on a ``Lightmap`` UV map)
        or ``both``.
    attribute: name of the color attribute written (only that exact name is ever overwritten).
    device: ``auto`` (CUDA when usable, else CPU), ``cpu`` or ``cuda``.
    light_samples: stratified shadow samples per lamp / emissive triangle and receiver (soft shadows).
    visibility_rays: rays per element pair in the reference gather (jittered over the sender disk).
    bounces: maximum number of indirect bounces (reference).
    tolerance: stop iterating when the largest change of indirect lighting, relative to the largest
        value, falls below this.
    max_pairs: memory budget of the reference transport, in element pairs (4 bytes each): the whole
        matrix is kept while n² fits, else rows are recomputed in blocks on each sweep.
    seed: random seed of sample jitter (results are deterministic for a given seed).
    bake_copy: when an object's modifiers change its vertex count, bake into a new object
        ``<name>_baked`` holding the evaluated mesh instead of skipping the object with a message.
    ao_distance: occluders farther than this (m) do not count for ``ao``; 0: the scene world's AO
        distance (Blender's default is 10 m).
    texel_density: lightmap texels per metre of surface (world space).
    max_size: largest lightmap page side (texels); the density is lowered until the atlas fits.
    padding: texels between charts (filled by dilation so bilinear filtering shows no seams).
    layout: ``atlas`` (one lightmap shared by all baked objects) or ``per_object`` (one each).
    output: folder the EXR lightmaps (and PNG previews) are written to; ``//`` = next to the .blend.
    hookup: ``none``; ``node`` adds a UV Map + Image Texture node pair to each affected material;
        ``multiply`` also multiplies the lightmap into the Base Color.
    reunwrap: make new ``Lightmap`` UVs even where a mesh has them (else they are reused).
    supersample: texel sub-samples per axis (1: texel centres only).
    texel_indirect: how a texel gets its indirect light: ``interpolate`` the per-vertex solution
        over its triangle, or ``gather`` (that, plus the detail a final gather of the solution over
        the disk hierarchy finds at the texel and not at the triangle's vertices: contact shadows
        and bleeding finer than the mesh).
    lightmap_format: EXR channel precision, ``half`` or ``float``.
    pack_images: pack the lightmap images into the .blend.
    """

    method: str = "reference"
    content: str = "lighting"
    target: str = "vertex_colors"
    attribute: str = "Lighting"
    device: str = "auto"
    light_samples: int = 16
    visibility_rays: int = 4
    bounces: int = 64
    tolerance: float = 1e-4
    max_pairs: int = 16_000_000
    seed: int = 1
    bake_copy: bool = False
    ao_distance: float = 0.0
    texel_density: float = 20.0
    max_size: int = 1024
    padding: int = 4
    layout: str = "atlas"
    output: str = "//lightmaps"
    hookup: str = "none"
    reunwrap: bool = False
    supersample: int = 1
    texel_indirect: str = "gather"
    lightmap_format: str = "half"
    pack_images: bool = False

    def validate(self) -> "Settings":
        """Raise SettingsError with a clear message for an out-of-range setting; return self."""
        for name, allowed in (("method", METHODS + tuple(METHOD_ALIASES)), ("content", CONTENTS), ("target", TARGETS),
                              ("device", DEVICES), ("layout", LAYOUTS), ("hookup", HOOKUPS),
                              ("lightmap_format", LIGHTMAP_FORMATS), ("texel_indirect", TEXEL_INDIRECT)):
            value = getattr(self, name)
            if value not in allowed:
                raise SettingsError(f"{name} must be one of {', '.join(allowed)}, not {value!r}")
        if not self.attribute or not self.attribute.strip():
            raise SettingsError("attribute name must not be empty")
        for name in ("light_samples", "visibility_rays", "bounces", "max_pairs"):
            if getattr(self, name) < 1:
                raise SettingsError(f"{name} must be at least 1, not {getattr(self, name)}")
        for name, low in (("max_size", 16), ("padding", 1), ("supersample", 1)):
            if getattr(self, name) < low:
                raise SettingsError(f"{name} must be at least {low}, not {getattr(self, name)}")
        if not self.texel_density > 0.0:
            raise SettingsError(f"texel_density must be positive, not {self.texel_density}")
        if self.target != "vertex_colors" and not self.output.strip():
            raise SettingsError("output folder must not be empty when baking lightmaps")
        if not self.ao_distance >= 0.0:
            raise SettingsError(f"ao_distance must be at least 0, not {self.ao_distance}")
        if not 0.0 < self.tolerance < 1.0:
            raise SettingsError(f"tolerance must be in (0, 1), not {self.tolerance}")
        return self

    @property
    def solver(self) -> str:
        """The method with aliases resolved."""
        return METHOD_ALIASES.get(self.method, self.method)

    def as_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}
