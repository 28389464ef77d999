"""Writers: how each core target's result (``core.targets``) reaches Blender and the disk, one class
per target, picked from ``WRITERS`` by the target's name; the job never branches on the kind.

A writer lives as long as its job (``addon.job.BakeJob``) and is called on the main thread except
where noted:

- ``begin(context)`` once, before the first frame: what must hold for the whole bake;
- ``check(context)`` after each frame's extraction, before it bakes: what can stop the writing
  (names taken, unwritable folders), and what the target needs from Blender (existing UVs);
- ``target()`` the ``core.targets`` object that frame bakes into;
- ``baked(result)`` in the baking thread after each frame (an animation stages its files);
- ``prepare(context)`` in the final step, before anything of the file is changed: every check
  again, files written (all or none); returns ``apply()``, which changes Blender data and returns
  warnings;
- ``discard()`` removes whatever was staged (a failed or cancelled bake).

``files`` maps what a writer put on disk ({name: path}) for the report; ``from_first_frame``:
an animation's later frames need the first one baked (the lightmap's layout), so a farm waits for
it before submitting them.
"""
from __future__ import annotations

from ..core import targets
from . import animation, lightmap, probes, write
from .outputs import Staging


class ColorWriter:
    """The ``vertices`` target into the color attribute ``settings.attribute`` (and, for an
    animation, one attribute per frame with a playback modifier)."""

    from_first_frame = False

    def __init__(self, job):
        self.job = job
        self.files: dict = {}

    def begin(self, context) -> None:
        pass

    def check(self, context) -> None:
        job = self.job
        if job.baked_frames:
            return  # the names were checked before the first frame
        names = [job.settings.attribute]
        if job.animation:
            names += [animation.frame_attribute(job.settings.attribute, f)
                      for f in [job.frame, *job.frames_left]]
        for name in names:
            write.check_color_attributes(job.extraction, name, job.settings, context)
        if job.animation:
            job.warn(animation.cache_warning(job.extraction, len(names) - 1))

    def target(self):
        return targets.make("vertices")

    def baked(self, result) -> None:
        pass

    def prepare(self, context):
        job = self.job
        if job.animation:
            writes = animation.prepare([(f, ex, r["vertices"].output) for f, ex, r in job.baked_frames],
                                       job.settings.attribute, job.settings, job.frame_now, context,
                                       lambda fraction: job.progress("write", fraction))
        else:
            writes = write.prepare_color_attributes(job.extraction, job.result["vertices"].output,
                                                    job.settings.attribute, job.settings, context)
        return lambda: writes.apply(context)

    def discard(self) -> None:
        pass


class LightmapWriter:
    """The ``lightmap`` target into EXR files in the output folder, ``Lightmap`` UV maps, images
    and material nodes. An animation's later frames keep the first frame's layout, and every
    frame's pages are staged as they are baked and go into place together."""

    from_first_frame = True

    def __init__(self, job):
        self.job = job
        self.files: dict = {}
        self._request = None
        self._first = None    # an animation's first frame: (request, LightmapResult, paths)
        self._staging = None  # an animation's files, staged frame by frame
        self._folder = None

    def begin(self, context) -> None:
        if self.job.animation:
            self._folder = lightmap.output_folder(self.job.settings)
            self._staging = Staging()

    def check(self, context) -> None:
        job = self.job
        lightmap.output_folder(job.settings)  # an unwritable folder fails before baking
        request, warnings = lightmap.request(job.extraction, job.settings)
        if self._first is not None:  # an animation's later frames: the first frame's layout
            for t in request.targets:
                t.corner_uv = self._first[1].uv.get(t.mesh_name, t.corner_uv)
            request.sizes = self._first[1].sizes
        else:
            job.warnings += warnings
        self._request = request

    def target(self):
        return targets.make("lightmap", self._request)

    def baked(self, result) -> None:
        """Stage the pages of the frame just baked as ``<page>.<frame>.exr``, and again for each
        frame up to the next baked one (a sequence with a step holds each frame), so the image
        sequence has a file for every scene frame."""
        if self._staging is None:
            return
        job = self.job
        upto = job.frames_left[0] if job.frames_left else job.frame + 1
        paths = None
        for frame in range(job.frame, upto):
            written, warnings = lightmap.write_files(result["lightmap"], job.settings,
                                                     self._staging, frame, self._folder)
            if paths is None:  # the frames it stands in for repeat its pages and warnings
                paths = written
                for message in warnings:
                    job.warn(message)
        if self._first is None:
            self._first = (self._request, result["lightmap"], paths)

    def prepare(self, context):
        settings = self.job.settings
        sequence = None
        if self._staging is not None:
            request, result, self.files = self._first
            maps = lightmap.prepare(result, request, settings)
            self._staging.commit()
            frames = [f for f, _, _ in self.job.baked_frames]
            sequence = (frames[0], frames[-1] - frames[0] + 1)
        else:
            result = self.job.result["lightmap"]
            maps = lightmap.prepare(result, self._request, settings)
            # files next, all or none: a disk error leaves Blender untouched
            self.files, warnings = lightmap.write_files(result, settings)
            maps.warnings += warnings
        return lambda: maps.apply(result, self.files, settings, sequence)

    def discard(self) -> None:
        if self._staging is not None:
            self._staging.__exit__(None, None, None)  # removes what was staged
            self._staging = None


class ProbesWriter:
    """The ``probes`` target into ``Probes.json`` in the output folder: per probe its position (m,
    world), validity and the SH of the arriving radiance (``core.sh``'s convention: nine RGB
    coefficients, L1 = the first four); then shown in the viewport (``addon.probes``). The grid
    covers the scene's first Light Probe Volume (its box and resolution) where there is one."""

    def __init__(self, job):
        self.job = job
        self.files: dict = {}
        self._volume = (None, None)

    def begin(self, context) -> None:
        pass

    def check(self, context) -> None:
        lightmap.output_folder(self.job.settings)  # an unwritable folder fails before baking
        self._volume = probes.volume_box(context.scene)
        self.target().check(self.job.extraction.scene, self.job.settings)  # too many: stop now

    def target(self):
        box, spacing = self._volume
        return targets.make("probes", box=box, spacing=spacing)

    def baked(self, result) -> None:
        pass

    def prepare(self, context):
        import json

        grid = self.job.result["probes"]
        path = lightmap.output_folder(self.job.settings) / "Probes.json"
        document = {"convention": "real SH of arriving radiance: Y00 = 0.282095, "
                                  "(Y1-1, Y10, Y11) = 0.488603 (y, z, x), then L2; lighting(n) = "
                                  "sum a_l c_lm Y_lm(n), a = (1, 2/3, 1/4)",
                    "shape": list(grid.shape), "spacing": grid.spacing.tolist(),
                    "points": grid.points.round(6).tolist(), "valid": grid.valid.tolist(),
                    "sh": grid.sh.round(7).tolist()}
        with Staging() as staging:
            with staging.writing(path) as temp:
                temp.write_text(json.dumps(document))
            staging.commit()
        self.files = {"Probes": path}
        return lambda: probes.show(context, grid)

    def discard(self) -> None:
        pass


# The writer of each core target, in the order the final step prepares them: colour writes only
# check, so they go before the lightmap's files are written.
WRITERS = {"vertices": ColorWriter, "lightmap": LightmapWriter, "probes": ProbesWriter}
