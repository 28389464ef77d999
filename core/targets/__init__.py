"""Targets: where the user wants the light and in what form, one module each, and their registry.

Every target module provides a class ``Target``; the caller makes one per output it wants (with
what that target needs: the objects to lightmap, …) through :func:`make` and hands them to
``core.pipeline.bake``, which for each::

    r = target.receivers(problem)              # core.receivers.Receivers: where values are wanted
    light = receivers.light_at(problem, solver, solution, r)   # the one shared path
    result = target.finish(problem, r, light)  # arrays, pages … kept as BakeResult.targets[name]

``light_at`` is the same for every target: direct light at the receivers, the solver's
``evaluate`` there, the content composed once. Writing a result into Blender or onto disk is the
add-on's (a writer per target, ``addon/writers.py``).

Adding a target: write ``core/targets/<name>.py`` with its ``Target`` and add one ``TargetInfo``
line to ``TARGETS`` below. Like the solver registry, this module imports no target until one is
made.
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass


@dataclass(frozen=True)
class TargetInfo:
    """name: the key of its results (``BakeResult.targets``); description: one line."""

    name: str
    description: str


TARGETS = {info.name: info for info in (
    TargetInfo("vertices", "Per shading vertex: the values a color attribute holds"),
    TargetInfo("lightmap", "Per lightmap texel: pages laid out by xatlas (or the objects' own "
               "Lightmap UVs), rasterised, dilated into their padding"),
    TargetInfo("probes", "Light probes: the spherical harmonics of the light arriving at points "
               "on a grid in space, for objects that move through the scene"),
)}


# What a bake makes when it is given no targets.
DEFAULT = ("vertices",)


def make(name: str, *args, **kwargs):
    """A target of the kind registered as ``name``, made with ``args`` and ``kwargs`` (what its
    ``Target`` takes); its ``name`` attribute is the registry's."""
    if name not in TARGETS:
        raise KeyError(f"no target {name!r}; known: {', '.join(TARGETS)}")
    target = importlib.import_module(f"{__name__}.{name}").Target(*args, **kwargs)
    target.name = name
    return target


def default() -> list:
    """The targets of a bake given none (``DEFAULT``)."""
    return [make(name) for name in DEFAULT]
