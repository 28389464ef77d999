"""Every bake setting, stated once: type, default, range or choices, label and help.

The dataclass :class:`Settings` is what core reads. Each field's metadata (:class:`Option`) is the
one source the Blender PropertyGroup (``addon/props.py``), the command line (``addon/cli.py``), the
panel (which greys out what the chosen method does not read) and the manual's settings reference
(:func:`reference_page`, checked by a test) are made from. Fields are grouped by who reads them:
``solver`` (light transport), ``lightmap`` (texels, pages, files) and ``output`` (what is written
and how).
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Optional

from .errors import SettingsError
from .solvers import SOLVERS

# Older name of the reference solver, still accepted.
METHOD_ALIASES = {"bruteforce": "reference"}


class _Methods:
    """The registered solvers and their aliases, read when asked (so a solver registered after
    import is a valid method)."""

    def __iter__(self):
        return iter((*SOLVERS, *METHOD_ALIASES))

    def __contains__(self, value) -> bool:
        return value in SOLVERS or value in METHOD_ALIASES


METHODS = _Methods()
CONTENTS = ("lighting", "combined", "indirect", "ao")
TARGETS = ("vertex_colors", "lightmap", "both")
# The core targets (``core.targets``) each choice of ``target`` bakes into.
TARGET_OUTPUTS = {"vertex_colors": ("vertices",), "lightmap": ("lightmap",),
                  "both": ("vertices", "lightmap")}
LAYOUTS = ("atlas", "per_object")
ATLAS_PAGES = ("many", "one")
HOOKUPS = ("none", "node", "multiply")
LIGHTMAP_FORMATS = ("half", "float", "hdr", "rgbm", "rgbd")
TEXEL_INDIRECT = ("gather", "interpolate")
TEXEL_SHADOWS = ("adaptive", "fixed")
# Directional bins per element over the sphere (core/directions.py), as the panel's enum holds them.
DIRECTIONAL_BINS = ("64", "256", "1024")
DEVICES = ("auto", "cpu", "cuda")
DIRECTIONAL = ("none", "sh", "godot", "unity")
PROBES = ("none", "grid")
LIGHT_SELECTIONS = ("auto", "exact", "tree")
GROUPS = ("solver", "lightmap", "output")
# A Dask scheduler address (``scheduler``): a protocol and HOST:PORT, or local:N.
_SCHEDULER = re.compile(r"local:[1-9][0-9]*|[a-z]+://\S+")

# One line per choice, for tooltips and help.
CHOICE_HELP = {
    **{name: info.description for name, info in SOLVERS.items()},
    "lighting": "Light arriving at the surface (irradiance/π), without the surface colour",
    "combined": "Emission + surface colour × lighting: what the surface looks like",
    "indirect": "Only the light that bounced off other surfaces",
    "vertex_colors": "A FLOAT_COLOR point attribute on each mesh",
    "lightmap": "OpenEXR lightmaps on a 'Lightmap' UV map, loaded as images",
    "both": "A color attribute and lightmaps",
    "atlas": "One lightmap shared by all baked objects",
    "per_object": "One lightmap per object",
    "many": "More pages (a UDIM tile set: Lightmap.1001, .1002 …), each object whole on one, at "
            "its density",
    "one": "One page, the density lowered until everything fits",
    "none": "Leave materials alone",
    "node": "Add a UV Map + Image Texture node pair showing the lightmap to each material",
    "multiply": "Add the node pair and multiply the lightmap into the Base Color",
    "half": "16-bit float channels (smaller files)",
    "float": "32-bit float channels",
    "auto": "The GPU when Warp finds a usable one, else the CPU",
    "cpu": "The CPU, all cores",
    "cuda": "An NVIDIA GPU through CUDA",
    "gather": "The per-vertex solution interpolated, plus the detail a final gather over the "
              "element tree finds at each texel",
    "interpolate": "The per-vertex solution interpolated over each triangle",
    "adaptive": "One probe ray per texel; more only in 4×4-texel tiles where the probes disagree, "
                "most where a texel's own rays do",
    "fixed": "The light samples at every texel",
    "exact": "Every emitter weighed by its exact unoccluded light at every receiver (cost grows "
             "with the number of emitters)",
    "tree": "A light tree picks emitters by importance (cost grows with the log of their number)",
    "64": "8×8 bins of 0.196 sr (coarse, least memory)",
    "256": "16×16 bins of 0.049 sr",
    "1024": "32×32 bins of 0.012 sr (sharpest, 4× the memory of 256)",
}
CHOICE_HELP["ao"] = ("Ambient occlusion: the unoccluded fraction of the hemisphere within the AO "
                     "distance, in all three channels (what Cycles' AO bake gives)")


@dataclass(frozen=True)
class Option:
    """What a setting is, for every place that shows or checks it.

    label: the panel's name; help: one line (the CLI adds the default); group: who reads it
    (GROUPS); choices: allowed values (None: free); low/high: inclusive bounds (None: open);
    soft_high: where the panel's slider ends; flag: the command-line option; length: a length in
    metres (the panel shows units); folder: a folder path.
    """

    label: str
    help: str
    group: str
    choices: Optional[tuple] = None
    low: Optional[float] = None
    high: Optional[float] = None
    soft_high: Optional[float] = None
    flag: Optional[str] = None
    length: bool = False
    folder: bool = False
    digits: Optional[int] = None
    placeholder: Optional[str] = None


def _option(default, label, help, group, **kwargs):
    return field(default=default, metadata={"option": Option(label, help, group, **kwargs)})


@dataclass
class Settings:
    """Bake settings; see each field's Option (``option(name)``) for its meaning and range."""

    method: str = _option("hierarchical", "Method", "how light transport is computed", "solver",
                          choices=METHODS)
    content: str = _option("lighting", "Content", "which quantity is baked", "output",
                           choices=CONTENTS)
    target: str = _option("vertex_colors", "Target", "where the result is written", "output",
                          choices=TARGETS)
    attribute: str = _option("Lighting", "Attribute", "the color attribute written, the only "
                             "thing ever replaced; a UV map, another attribute or a vertex group "
                             "of that name stops the bake", "output")
    device: str = _option("auto", "Device", "where the computation runs", "solver", choices=DEVICES)
    light_samples: int = _option(64, "Light Samples", "shadow rays per receiver, shared by all lamps "
                                 "and emissive triangles by their light (softer, less noisy "
                                 "shadows)", "solver", low=1, soft_high=256, flag="--samples")
    light_selection: str = _option("auto", "Light Selection", "how shadow rays are shared among "
                                   "the emitters; auto: exact for up to 16 emitters or while "
                                   "receivers × emitters stay under 134 million, else the tree", "solver",
                                   choices=LIGHT_SELECTIONS)
    visibility_rays: int = _option(4, "Visibility Rays", "rays per element pair (reference) or "
                                   "link (hierarchical; one with Gather Rays, whose links only "
                                   "start the bounces) for the visibility of indirect light; "
                                   "sample pairs of a link's unoccluded transfer (implicit, "
                                   "antiradiance)",
                                   "solver", low=1, high=255,
                                   soft_high=64, flag="--rays")
    bounces: int = _option(64, "Bounces", "at most this many indirect bounces (sweeps)", "solver",
                           low=1, soft_high=128)
    tolerance: float = _option(1e-4, "Tolerance", "stop bouncing when the largest change, "
                               "relative to the largest value, is below this", "solver",
                               low=1e-8, high=0.5, digits=6)
    max_pairs: int = _option(16_000_000, "Max Pairs", "memory budget of the all-pairs transport, "
                             "in element pairs at 4 bytes each (the visibility alone takes 1 "
                             "byte a pair)", "solver", low=1)
    link_threshold: float = _option(0.1, "Link Threshold", "largest unoccluded transfer (form "
                                    "factor bound) a link between two element clusters may carry; "
                                    "smaller makes more, finer links (slower, more accurate; with "
                                    "Gather Rays the links only start the gather's bounces and are "
                                    "made at 0.5 at least, unless Texel Links gathers texels over "
                                    "them)",
                                    "solver", low=1e-5, high=1.0, digits=4)
    # 128: on the level of bench/real_scenes.py (116 k elements; against Cycles at 1 024 samples,
    # 2-core VM; bench/results/accuracy-level-gather-vm-2026-12-04.*) 256 rays gave 10.45 %
    # relative RMSE in 18.6 s (4.9x Cycles at equal error), 128 10.76 % in 13.8 s (6.3x), 64
    # 11.29 % in 11.4 s (6.8x, a separate bake): past ~100 rays its error is the direct light's
    # noise, not the gather's. Small scenes get more (GATHER_BUDGET).
    gather_rays: int = _option(128, "Gather Rays", "rays from each element for the final "
                               "gather (hierarchical): what each element sees, bounced until it "
                               "converges, in place of the links' cluster averages; more is "
                               "smoother and slower (scenes under 16 k elements get more, up to "
                               "2 M rays in all); 0: the links' own last bounce", "solver",
                               low=0, high=4096, soft_high=1024)
    contact_levels: int = _option(0, "Contact Levels", "times triangles are split where "
                                  "another surface comes within their size (an object standing "
                                  "on a floor, shelves against a wall): finer elements in the gap, "
                                  "where the light changes fastest; 0: elements as the mesh has them",
                                  "solver", low=0, high=6)
    link_memory: int = _option(4096, "Link Memory", "memory budget of the links (MB); a scene that "
                               "would need more gets coarser links, with a warning", "solver",
                               low=1, soft_high=65536)
    directional_bins: str = _option("256", "Directional Bins", "direction bins over the sphere per "
                                    "element (implicit visibility, antiradiance): more is sharper "
                                    "and slower, and takes more memory", "solver",
                                    choices=DIRECTIONAL_BINS)
    seed: int = _option(1, "Seed", "random seed of the sample jitter (results are deterministic "
                        "for a seed)", "solver", low=0)
    frames: str = _option("", "Frames", "frame range A:B[:STEP] to bake as an animation, each "
                          "frame into its own attribute or lightmap image of a sequence (empty: "
                          "the current frame; the panel's Bake Animation button: the scene's frame "
                          "range)", "output", placeholder="A:B[:STEP]")
    scheduler: str = _option("", "Scheduler", "Dask scheduler to bake on as a farm: tcp://HOST:PORT "
                             "(a running 'dask scheduler' with workers), local:N (N worker "
                             "processes on this machine); an animation's frames, else each "
                             "lightmap page, are its tasks (empty: bake here)", "output",
                             placeholder="ADDRESS")
    bake_copy: bool = _option(False, "Bake Copy", "when modifiers change an object's vertex count, "
                              "bake into a new object '<name>_baked' instead of skipping it",
                              "output")
    ao_distance: float = _option(0.0, "AO Distance", "occluders farther than this (m) do not count "
                                 "for AO; 0 uses the world's AO distance", "solver", low=0.0,
                                 soft_high=100.0, length=True)
    texel_density: float = _option(20.0, "Texel Density", "lightmap texels per metre of surface",
                                   "lightmap", low=1e-3, soft_high=1000.0)
    max_size: int = _option(1024, "Max Size", "largest lightmap side in texels (each page of an "
                            "atlas of several is this size); engines take at most 16384", "lightmap",
                            low=16, high=16384, soft_high=8192)
    atlas_pages: str = _option("many", "Atlas Pages", "what happens when the charts do not fit "
                               "one page at the asked density", "lightmap", choices=ATLAS_PAGES)
    padding: int = _option(4, "Padding", "texels between lightmap charts, filled by dilation",
                           "lightmap", low=1, soft_high=16)
    layout: str = _option("atlas", "Layout", "one lightmap for all baked objects or one each",
                          "lightmap", choices=LAYOUTS)
    output: str = _option("//lightmaps", "Output", "folder the EXR lightmaps and PNG previews are "
                          "written to ('//' is the .blend's folder)", "lightmap", folder=True)
    hookup: str = _option("none", "Hook Up", "show the lightmap in the objects' materials "
                          "('--hookup' alone: node)", "lightmap", choices=HOOKUPS)
    reunwrap: bool = _option(False, "Re-unwrap", "make new 'Lightmap' UVs even where a mesh "
                             "already has them", "lightmap")
    supersample: int = _option(1, "Supersample", "lighting samples per texel along each axis",
                               "lightmap", low=1, high=8)
    texel_indirect: str = _option("gather", "Texel Indirect", "indirect light per texel",
                                  "lightmap", choices=TEXEL_INDIRECT)
    texel_links: bool = _option(False, "Texel Links", "hierarchical radiosity: gather each texel's "
                                "indirect light over the solver's links with rays from the texel "
                                "(sharp indirect shadows of small nearby occluders; several times "
                                "slower) instead of over the element tree", "lightmap")
    texel_shadows: str = _option("adaptive", "Texel Shadows", "shadow rays per lightmap texel",
                                 "lightmap", choices=TEXEL_SHADOWS)
    shadow_budget: int = _option(256, "Shadow Budget", "most shadow rays a texel traces in a "
                                 "penumbra (adaptive texel shadows: elsewhere one per texel, or "
                                 "the light samples where a shadow edge passes)", "lightmap", low=1,
                                 soft_high=1024)
    lightmap_format: str = _option("half", "Lightmap Format", "lightmap files: OpenEXR of half or "
                                   "float channels; hdr: Radiance RGBE; rgbm, rgbd: 8-bit PNG for "
                                   "engines without float textures (beside a half EXR for Blender)",
                                   "lightmap", choices=LIGHTMAP_FORMATS)
    pack_images: bool = _option(False, "Pack Images", "pack the lightmap images into the .blend "
                                "file", "lightmap")
    directional: str = _option("none", "Directional", "where each lightmap texel's light comes "
                               "from, for normal maps: sh writes its L1 spherical harmonics (L0 = "
                               "the plain lightmap, L1 along x, y, z per colour channel) as "
                               "<page>.sh.exr; godot: Godot 4's four L1 layers stacked in "
                               "<page>.godot.exr; unity: Unity's direction map <page>.dir.png "
                               "beside the plain page (its colour map); none: the plain lightmap "
                               "alone (manual: Directional lightmaps)", "lightmap",
                               choices=DIRECTIONAL)
    probes: str = _option("none", "Light Probes", "light probes for objects that move through the "
                          "baked scene: grid bakes the L2 spherical harmonics of the light arriving "
                          "at points on a grid over the scene (or over a Light Probe Volume's "
                          "box and resolution) into Probes.json in the output folder, shown as "
                          "the object 'RB Probes'; none: no probes", "output", choices=PROBES)
    probe_spacing: float = _option(1.0, "Probe Spacing", "distance between light probes of the grid "
                                   "(m)", "output", low=0.01, soft_high=10.0, length=True)

    @property
    def solver(self) -> str:
        """The solver that runs: AO content is the ``ao`` solver's, aliases are resolved."""
        if self.content == "ao":
            return "ao"
        return METHOD_ALIASES.get(self.method, self.method)

    @property
    def baked_content(self) -> str:
        """The content baked: ``ao`` for the AO solver, else ``content``."""
        return "ao" if self.solver == "ao" else self.content

    def validate(self) -> "Settings":
        """Raise SettingsError naming the setting for a value out of range; return self."""
        for f in fields(self):
            opt = option(f.name)
            value = getattr(self, f.name)
            if opt.choices is not None and value not in opt.choices:
                raise SettingsError(f"{f.name} must be one of {', '.join(opt.choices)}, not {value!r}")
            if opt.low is not None and not value >= opt.low:
                raise SettingsError(f"{f.name} must be at least {opt.low:g}, not {value}")
            if opt.high is not None and not value <= opt.high:
                raise SettingsError(f"{f.name} must be at most {opt.high:g}, not {value}")
        if not self.attribute or not self.attribute.strip():
            raise SettingsError("attribute name must not be empty")
        if "lightmap" in self.targets and not self.output.strip():
            raise SettingsError("output folder must not be empty when baking lightmaps")
        self.frame_list()
        if self.scheduler.strip() and not _SCHEDULER.fullmatch(self.scheduler.strip()):
            raise SettingsError(f"scheduler must be tcp://HOST:PORT (or another Dask protocol) or "
                                f"local:N with N ≥ 1, not {self.scheduler!r}")
        if self.content == "indirect" and not SOLVERS[self.solver].indirect:
            raise SettingsError(f"content indirect needs a method with indirect light; method "
                                f"{self.method} computes none (it would bake black)")
        return self

    @property
    def targets(self) -> tuple:
        """The names of the core targets ``target`` bakes into (``TARGET_OUTPUTS``)."""
        return TARGET_OUTPUTS[self.target] + (("probes",) if self.probes != "none" else ())

    def frame_list(self) -> Optional[list[int]]:
        """The frames of ``frames`` (A:B or A:B:STEP, B included), None when empty; raises
        SettingsError for anything else."""
        text = self.frames.strip()
        if not text:
            return None
        try:
            parts = [int(x) for x in text.split(":")]
        except ValueError:
            parts = []
        if len(parts) not in (2, 3) or parts[1] < parts[0] or (len(parts) == 3 and parts[2] < 1):
            raise SettingsError(f"frames must be A:B or A:B:STEP with A ≤ B and STEP ≥ 1, not {text!r}")
        return list(range(parts[0], parts[1] + 1, parts[2] if len(parts) == 3 else 1))

    def unread(self) -> list[str]:
        """Settings changed from their defaults that the chosen solver does not read (for a
        warning: a bunnell bake ignores --bounces)."""
        return [f.name for f in fields(self)
                if not _same(getattr(self, f.name), f.default) and not reads(self.solver, f.name)]

    def as_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def group(self, name: str) -> dict:
        """{field: value} of the settings read by ``name`` (one of GROUPS)."""
        return {f.name: getattr(self, f.name) for f in fields(self) if option(f.name).group == name}


def _same(value, default) -> bool:
    """A setting left at its default; floats to single precision (Blender's float properties)."""
    if isinstance(default, float) and isinstance(value, float):
        return math.isclose(value, default, rel_tol=1e-6, abs_tol=1e-12)
    return value == default


def option(name: str) -> Option:
    """The Option of Settings field ``name``."""
    return _OPTIONS[name]


def flag(name: str) -> str:
    """The command-line option of Settings field ``name``."""
    return option(name).flag or "--" + name.replace("_", "-")


_OPTIONS = {f.name: f.metadata["option"] for f in fields(Settings)}
# Settings only some solvers read (SolverInfo.reads names them); the others are read by all.
SOLVER_SPECIFIC = {name for info in SOLVERS.values() for name in info.reads}
# light_samples and light_selection are read by every solver that transports light, not by AO.
SOLVER_SPECIFIC.update(("light_samples", "light_selection"))


def reads(solver: str, name: str) -> bool:
    """Whether ``solver`` reads setting ``name`` (the panel greys out the others)."""
    if name in ("light_samples", "light_selection"):
        return SOLVERS[solver].light
    return name not in SOLVER_SPECIFIC or name in SOLVERS[solver].reads


def metavar(name: str) -> Optional[str]:
    """The placeholder of Settings field ``name``'s value on the command line (None: a switch or
    a choice)."""
    opt, default = option(name), _DEFAULTS[name]
    if opt.placeholder is not None:
        return opt.placeholder
    if opt.choices is not None or isinstance(default, bool):
        return None
    if isinstance(default, (int, float)):
        return "N" if isinstance(default, int) else "X"
    return "DIR" if opt.folder else "NAME"


def describe(name: str) -> str:
    """One line on Settings field ``name``: its help, what each method is, its range."""
    opt = option(name)
    text = opt.help
    if opt.choices is not None and name not in ("device", "layout", "lightmap_format",
                                                "directional", "probes"):
        text += ": " + "; ".join(f"{c}: {CHOICE_HELP[c]}" for c in opt.choices
                                if c in CHOICE_HELP and c != "auto")  # auto is the device's
    if name == "method":
        text += "; " + ", ".join(f"{a} is another name for {m}" for a, m in METHOD_ALIASES.items())
    if opt.low is not None and opt.high is not None:
        text += f" ({opt.low:g} to {opt.high:g})"
    elif opt.low is not None:
        text += f" (at least {opt.low:g})"
    return text


GROUP_TITLES = {"solver": "How the light is computed", "output": "What is baked, where and when",
                "lightmap": "Lightmaps"}
REFERENCE_PAGE = "docs/settings.md"  # the manual's page this module writes (reference_page)


def options_markdown(group: Optional[str] = None) -> str:
    """The table of the settings (of ``group``, else all): command-line option, panel label,
    meaning with range, default."""
    rows = ["| option | panel | meaning (default) |", "| --- | --- | --- |"]
    for f in fields(Settings):
        opt = option(f.name)
        if group is not None and opt.group != group:
            continue
        shown = flag(f.name)
        if opt.choices is not None:
            shown += " " + "\\|".join(opt.choices)
        elif metavar(f.name):
            shown += " " + metavar(f.name)
        default = "off" if isinstance(f.default, bool) else f"`{f.default}`"
        rows.append(f"| `{shown}` | {opt.label} | {describe(f.name)} ({default}) |")
    return "\n".join(rows)


def reference_page() -> str:
    """The manual's settings reference (``REFERENCE_PAGE``), made from the fields above; a test
    checks the committed page is this; ``write_reference_page`` writes it."""
    head = ["# Settings reference", "",
            "Every setting of a bake, as the command line spells it (`bake` options), with its "
            "label in the panel (Properties › Render › Radiosity Bake) and in `core.Settings` "
            "(the field is the option without `--`, `-` as `_`). This page is generated from "
            "`core/settings.py`; do not edit it by hand "
            "([Development](development.md#settings)). A setting a method does not read is "
            "greyed out in the panel and ignored on the command line.", ""]
    body = []
    for group in GROUPS:
        body += [f"## {GROUP_TITLES[group]}", "", options_markdown(group), ""]
    return "\n".join(head + body)


def write_reference_page() -> Path:
    """Write ``reference_page()`` over ``REFERENCE_PAGE`` in this checkout; returns its path."""
    target = Path(__file__).resolve().parents[1] / REFERENCE_PAGE
    target.write_text(reference_page(), encoding="utf-8")
    return target


_DEFAULTS = {f.name: f.default for f in fields(Settings)}
