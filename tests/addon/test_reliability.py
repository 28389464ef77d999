"""Bad and unusual input, tried as a new user would: through the command line (in-process, and once
as a real process interrupted with Ctrl-C) and the operator / BakeJob.

Each case checks the exit status, that the message is one line naming the culprit, and that the
input file (its bytes) and every user attribute, UV map, vertex group, image and material are
unchanged afterwards; where the bake succeeds, the saved file differs from the input only by what
the bake was asked to write. Disks that fill up are simulated (a save cut short, a failing fsync).
"""
import errno
import hashlib
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import bpy
import numpy as np
import pytest

from radiosity_baker.addon import cli
from radiosity_baker.addon.extract import extract_scene
from radiosity_baker.addon.job import BakeJob
from radiosity_baker.core import device
from radiosity_baker.core.lightmap import files, raster

from scenes import GROUND, OCCLUDER, fast_settings, lit_ground, user_data, vertex_colors

FAST = ["--method", "direct", "--samples", "1"]
LIGHTMAP = ["--target", "lightmap", "--texel-density", "4", "--max-size", "64"]
CORNELL = Path(__file__).resolve().parents[2] / "sample_blends" / "cornell_box.blend"
BAKED = ("Lighting", "Lightmap")  # the layers the bakes below are asked to write
FLT_MAX = float(np.finfo(np.float32).max)


def sha(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def listing(folder: Path) -> dict:
    """Every file and folder under ``folder`` with a hash of its bytes (None for folders)."""
    return {str(p.relative_to(folder)): (None if p.is_dir() else sha(p)) for p in folder.rglob("*")}


def add_user_data(scene) -> None:
    """Data a bake must never touch, on the ground: a UV map (active and render), a corner paint
    layer (the active and render colour), a float attribute, smooth and flat faces, a vertex group,
    a material whose Base Color comes from a packed image; the occluder has a plain material and a
    colour attribute of its own (so a bake changes no mesh's active colour)."""
    ground = bpy.data.objects[GROUND]
    me = ground.data
    rng = np.random.default_rng(7)
    me.uv_layers.new(name="UVMap").uv.foreach_set("vector", rng.random(len(me.loops) * 2, np.float32))
    paint = me.color_attributes.new("Paint", "BYTE_COLOR", "CORNER")
    paint.data.foreach_set("color", rng.random(len(me.loops) * 4, np.float32))
    me.color_attributes.active_color_name = me.color_attributes.default_color_name = "Paint"
    me.attributes.new("weight", "FLOAT", "POINT").data.foreach_set(
        "value", rng.random(len(me.vertices), np.float32))
    me.polygons.foreach_set("use_smooth", rng.random(len(me.polygons)) > 0.5)
    ground.vertex_groups.new(name="Group").add([0, 1, 2], 0.5, "REPLACE")
    image = bpy.data.images.new("Texture", 8, 8)
    image.pixels.foreach_set(rng.random(8 * 8 * 4, np.float32))
    image.pack()
    painted = bpy.data.materials.new("Painted")
    tex = painted.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = image
    painted.node_tree.links.new(tex.outputs["Color"],
                                painted.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
    me.materials.append(painted)
    plain = bpy.data.materials.new("Plain")
    plain.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.2, 0.4, 0.6, 1)
    occluder = bpy.data.objects[OCCLUDER].data
    occluder.materials.append(plain)
    occluder.color_attributes.new("Tint", "FLOAT_COLOR", "POINT").data.foreach_set(
        "color", rng.random(len(occluder.vertices) * 4, np.float32))
    occluder.color_attributes.active_color_name = occluder.color_attributes.default_color_name = "Tint"


def save(path: Path) -> Path:
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path


@pytest.fixture
def blend(empty_scene, tmp_path) -> Path:
    """tmp/in.blend: the lit ground with user data."""
    lit_ground(empty_scene)
    add_user_data(empty_scene)
    return save(tmp_path / "in.blend")


def data_of(path: Path, skip=BAKED) -> dict:
    """``user_data`` of the file at ``path`` (opened for it)."""
    bpy.ops.wm.open_mainfile(filepath=str(path))
    return user_data(skip)


@dataclass
class Run:
    status: int
    out: str
    err: list

    @property
    def started(self) -> bool:
        """Whether the bake got past extraction (its progress lines name the stages)."""
        return "radiosity_baker: solve" in self.out

    @property
    def message(self) -> str:
        """The one error line (asserted to be the only line on stderr besides warnings)."""
        errors = [line for line in self.err if line.startswith("radiosity_baker: error:")]
        assert len(errors) == 1, self.err
        assert all(line.startswith("radiosity_baker: ") for line in self.err), self.err
        return errors[0]


def bake(capsys, *argv) -> Run:
    status = cli.main(["bake", *map(str, argv)])
    captured = capsys.readouterr()
    return Run(status, captured.out, captured.err.strip().splitlines())


def fails(capsys, tmp_path, blend, status, words, *argv, started=None) -> Run:
    """Bake ``argv`` (after the input); assert the exit ``status``, one error line holding every
    word of ``words``, input and folder unchanged, and (when ``started`` is given) whether the bake
    ran before failing."""
    digest, files_before = sha(blend), listing(tmp_path)
    before = data_of(blend)
    run = bake(capsys, blend, *argv)
    assert run.status == status, run
    for word in words:
        assert word in run.message, (word, run.message)
    assert "internal error" not in run.message
    if started is not None:
        assert run.started == started, run.out
    assert sha(blend) == digest and listing(tmp_path) == files_before
    assert user_data(BAKED) == before  # the session too: nothing was written half-way
    return run


# ------------------------------------------------------------------------------------------------
# input that cannot be read or baked


@pytest.mark.parametrize("kind", ["missing", "fake", "truncated"])
def test_unreadable_input_is_exit_2(blend, tmp_path, capsys, kind):
    path = tmp_path / f"{kind}.blend"
    if kind == "fake":
        path.write_text("not a blend file")
    elif kind == "truncated":
        path.write_bytes(blend.read_bytes()[:len(blend.read_bytes()) // 2])
    files_before = listing(tmp_path)
    run = bake(capsys, path, *FAST)
    assert run.status == 2 and str(path) in run.message
    assert listing(tmp_path) == files_before


def test_empty_scene_is_exit_1_and_removes_the_folders_made_for_outputs(empty_scene, tmp_path,
                                                                        capsys):
    path = save(tmp_path / "empty.blend")
    new = tmp_path / "new"
    fails(capsys, tmp_path, path, 1, ["nothing to bake"], "--save", new / "a" / "out.blend",
          "--report", new / "b" / "report.json")
    assert not new.exists()


@pytest.mark.parametrize("how", ["nan vertex", "inf vertex", "FLT_MAX vertex", "FLT_MAX location",
                                 "FLT_MAX scale"])
def test_nan_and_infinite_geometry_is_one_clear_line_without_numpy_warnings(blend, tmp_path, capsys,
                                                                            how):
    bad = {"nan vertex": float("nan"), "inf vertex": float("inf")}.get(how, FLT_MAX)
    me = bpy.data.meshes.new("Broken")
    me.from_pydata([(0, 0, 1), (1, 0, 1), (0, 1, 1)], [], [(0, 1, 2)])
    ob = bpy.data.objects.new("Broken", me)
    bpy.context.scene.collection.objects.link(ob)
    if how.endswith("vertex"):
        me.vertices[2].co.x = bad  # Blender stores an infinite coordinate as FLT_MAX
    elif how.endswith("location"):
        ob.location.x = bad
    else:
        ob.scale.x = bad
    save(blend)
    fails(capsys, tmp_path, blend, 1, ["Broken", "NaN or infinite vertex positions"], *FAST,
          started=False)


@pytest.mark.parametrize("option, where", [
    ("--save", "in.blend/out.blend"), ("--save", "/proc/radiosity_baker/out.blend"),
    ("--report", "/proc/radiosity_baker/report.json"), ("--preview", "in.blend/preview.png"),
    ("--output", "in.blend/maps"), ("--output", "/proc/radiosity_baker/maps")])
def test_unwritable_outputs_are_exit_2_before_baking(blend, tmp_path, capsys, option, where):
    target = tmp_path / where  # an absolute `where` replaces the folder
    extra = LIGHTMAP if option == "--output" else []
    fails(capsys, tmp_path, blend, 2, [str(target)], *FAST, *extra, option, target, started=False)


@pytest.mark.parametrize("option", ["--report", "--preview"])
@pytest.mark.parametrize("spelling", ["same", "relative", "dot-dot", "symlink", "hard link"])
def test_an_output_naming_the_input_is_exit_2_and_leaves_it_alone(blend, tmp_path, capsys,
                                                                 monkeypatch, option, spelling):
    monkeypatch.chdir(tmp_path)
    target = {"same": str(blend), "relative": f"./{blend.name}",
              "dot-dot": f"{tmp_path}/missing/../{blend.name}",
              "symlink": tmp_path / "link.blend", "hard link": tmp_path / "hard.blend"}[spelling]
    if spelling == "symlink":
        target.symlink_to(blend)
    elif spelling == "hard link":
        os.link(blend, target)
    fails(capsys, tmp_path, blend, 2, [option, str(Path(target)), "input"], *FAST, option, target,
          started=False)


def test_two_outputs_naming_one_file_through_a_link_are_exit_2(blend, tmp_path, capsys):
    (tmp_path / "report.json").write_text("{}")
    (tmp_path / "alias.json").symlink_to(tmp_path / "report.json")
    fails(capsys, tmp_path, blend, 2, ["--report", "--preview"], *FAST, "--report",
          tmp_path / "report.json", "--preview", tmp_path / "alias.json", started=False)


@pytest.mark.parametrize("option, name", [("--report", "Lightmap.png"), ("--preview", "lightmap.PNG"),
                                          ("--save", "Lightmap_Ground.exr")])
def test_an_output_a_lightmap_file_would_replace_is_exit_2(blend, tmp_path, capsys, option, name):
    maps = tmp_path / "maps"
    maps.mkdir()
    fails(capsys, tmp_path, blend, 2, [option, str(maps / name), "lightmap"], *FAST, *LIGHTMAP,
          "--output", maps, option, maps / name, started=False)


def test_an_input_in_the_lightmap_folder_under_a_lightmap_name_is_exit_2(blend, tmp_path, capsys):
    inside = tmp_path / "Lightmap.exr"
    inside.write_bytes(blend.read_bytes())
    fails(capsys, tmp_path, inside, 2, [str(inside), "input"], *FAST, *LIGHTMAP, "--output", tmp_path,
          started=False)


@pytest.mark.parametrize("argv, words", [
    (["--max-size", "100000"], ["--max-size", "16384"]),
    (["--max-size", "16384", "--texel-density", "100000", "--supersample", "8"],
     ["million texels", "GB", "texel density of"])])
def test_lightmap_pages_beyond_engines_or_memory_are_exit_2_before_baking(blend, tmp_path, capsys,
                                                                         argv, words):
    fails(capsys, tmp_path, blend, 2, words, *FAST, *LIGHTMAP, "--output", tmp_path / "maps", *argv,
          started=False)


def test_a_mesh_with_eight_uv_maps_is_an_error_naming_it(blend, tmp_path, capsys):
    for i in range(7):
        bpy.data.objects[GROUND].data.uv_layers.new(name=f"UV{i}")
    save(blend)
    fails(capsys, tmp_path, blend, 1, [f"mesh {GROUND}", "8 UV maps"], *FAST, *LIGHTMAP,
          "--output", tmp_path / "maps", started=False)


# ------------------------------------------------------------------------------------------------
# names: only a color attribute of the name asked for may be replaced


@pytest.mark.parametrize("name, words", [
    ("UVMap", [GROUND, "UV map"]), ("weight", [GROUND, "FLOAT attribute"]),
    ("Group", [GROUND, "vertex group"]), ("sharp_face", ["reserved"]),
    ("material_index", ["reserved"]), ("position", ["reserved"]), (".hidden", ["reserved"]),
    ("a" * 64, ["64 bytes"])])
def test_attribute_names_held_by_other_data_or_reserved_are_exit_2_before_baking(
        blend, tmp_path, capsys, name, words):
    fails(capsys, tmp_path, blend, 2, words, *FAST, "--attribute", name, "--save",
          tmp_path / "out.blend", started=False)


def test_the_default_attribute_name_held_by_a_uv_map_is_not_deleted(blend, tmp_path, capsys):
    bpy.data.objects[OCCLUDER].data.uv_layers.new(name="Lighting")
    save(blend)
    fails(capsys, tmp_path, blend, 2, [OCCLUDER, "UV map", "'Lighting'"], *FAST, "--save",
          tmp_path / "out.blend", started=False)


def test_the_color_attribute_of_that_name_is_the_one_thing_replaced(blend, tmp_path, capsys):
    out = tmp_path / "out.blend"
    before = data_of(blend, skip=BAKED + ("Paint",))
    assert bake(capsys, blend, *FAST, "--attribute", "Paint", "--save", out).status == 0
    assert data_of(out, skip=BAKED + ("Paint",)) == before
    paint = bpy.data.objects[GROUND].data.attributes["Paint"]
    assert (paint.domain, paint.data_type) == ("POINT", "FLOAT_COLOR")


def test_operator_with_a_reserved_name_keeps_the_flat_shading(blend):
    fast_settings(bpy.context.scene, attribute="sharp_face")
    before = user_data()
    with pytest.raises(RuntimeError, match="reserved"):
        bpy.ops.object.radiosity_bake(use_selected=False)
    assert user_data() == before


@pytest.mark.parametrize("kind", ["float attribute", "vertex group", "color attribute",
                                  "color attribute baked alongside"])
def test_another_layer_named_lightmap_is_exit_2_before_baking(blend, tmp_path, capsys, kind):
    ground = bpy.data.objects[GROUND]
    target = ["--target", "both", "--attribute", "Lightmap"]
    if kind == "float attribute":
        ground.data.attributes.new("Lightmap", "FLOAT", "POINT")
    elif kind == "vertex group":
        ground.vertex_groups.new(name="Lightmap")
    elif kind == "color attribute":
        ground.data.color_attributes.new("Lightmap", "FLOAT_COLOR", "POINT")
    if kind != "color attribute baked alongside":
        target = []
    save(blend)
    words = ["'Lightmap'"] + ([] if target else [GROUND])
    fails(capsys, tmp_path, blend, 2, words, *FAST, *LIGHTMAP, *target, "--output",
          tmp_path / "maps", "--save", tmp_path / "out.blend", started=False)


# ------------------------------------------------------------------------------------------------
# full disks: nothing reported done that is not whole on disk


@pytest.fixture
def save_cut_short(monkeypatch):
    """Blender's save reports success but the disk filled up: the file written is cut in half."""
    class Wm:  # bpy.ops.wm, with that save
        def __init__(self, real):
            self._real = real

        def __getattr__(self, name):
            return getattr(self._real, name)

        def save_as_mainfile(self, **kwargs):
            result = self._real.save_as_mainfile(**kwargs)
            path = Path(kwargs["filepath"])
            path.write_bytes(path.read_bytes()[:path.stat().st_size // 2])
            return result

    monkeypatch.setattr(bpy.ops, "wm", Wm(bpy.ops.wm))


@pytest.mark.parametrize("target", ["new", "existing", "in place"])
def test_a_save_cut_short_leaves_the_target_as_it_was(blend, tmp_path, capsys, save_cut_short,
                                                      target):
    out = {"new": tmp_path / "sub" / "out.blend", "existing": tmp_path / "out.blend",
           "in place": blend}[target]
    if target == "existing":
        out.write_bytes(blend.read_bytes())
    fails(capsys, tmp_path, blend, 2, [str(out), "incomplete"], *FAST, "--save", out, started=True)


def test_a_report_on_a_full_disk_writes_neither_it_nor_the_save(blend, tmp_path, capsys,
                                                               monkeypatch):
    def fsync(fd):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "fsync", fsync)
    report = tmp_path / "reports" / "report.json"
    fails(capsys, tmp_path, blend, 2, [str(report), "No space left"], *FAST, "--save",
          tmp_path / "out.blend", "--report", report, started=True)


def test_lightmap_files_cut_short_leave_the_output_folder_as_it_was(blend, tmp_path, capsys,
                                                                   monkeypatch):
    maps = tmp_path / "maps"
    assert bake(capsys, blend, *FAST, *LIGHTMAP, "--output", maps).status == 0
    assert sorted(p.name for p in maps.iterdir()) == ["Lightmap.exr", "Lightmap.png"]
    real = files.write_exr

    def write_exr(path, rgb, precision="half", objects=None):
        real(path, rgb, precision, objects)
        Path(path).write_bytes(Path(path).read_bytes()[:100])

    monkeypatch.setattr(files, "write_exr", write_exr)
    fails(capsys, tmp_path, blend, 2, [str(maps / "Lightmap.exr")], *FAST, *LIGHTMAP,
          "--texel-density", "6", "--output", maps, "--save", tmp_path / "out.blend", started=True)


# ------------------------------------------------------------------------------------------------
# lightmaps


def test_a_rebake_after_hookup_multiply_reads_the_materials_own_colours(blend, tmp_path, capsys):
    def albedo():
        return extract_scene(bpy.context.evaluated_depsgraph_get()).scene.albedo

    first = albedo()
    out = tmp_path / "out.blend"
    assert bake(capsys, blend, *FAST, *LIGHTMAP, "--output", tmp_path / "maps", "--hookup",
                "multiply", "--save", out).status == 0
    bpy.ops.wm.open_mainfile(filepath=str(out))
    base = bpy.data.materials["Plain"].node_tree.nodes["Principled BSDF"].inputs["Base Color"]
    assert base.links[0].from_node.name == "RB Lightmap Multiply"
    np.testing.assert_array_equal(albedo(), first)
    run = bake(capsys, out, *FAST, *LIGHTMAP, "--output", tmp_path / "maps", "--hookup", "multiply")
    assert run.status == 0 and "Mix" not in "".join(run.err)


@pytest.mark.parametrize("density", ["20", "10000"])
def test_a_millimetre_scene_gets_lightmap_texels_on_every_object(empty_scene, tmp_path, capsys,
                                                                 density):
    lit_ground(empty_scene)
    for ob in bpy.data.objects:
        ob.location *= 0.001
        ob.scale *= 0.001
    blend, out = save(tmp_path / "mm.blend"), tmp_path / "out.blend"
    run = bake(capsys, blend, *FAST, "--target", "lightmap", "--texel-density", density,
               "--output", tmp_path / "maps", "--save", out)
    assert run.status == 0, run.err
    bpy.ops.wm.open_mainfile(filepath=str(out))
    width, height = bpy.data.images["Lightmap"].size
    for name in (GROUND, OCCLUDER):
        me = bpy.data.objects[name].data
        uv = np.empty(len(me.loops) * 2, np.float32)
        me.uv_layers["Lightmap"].uv.foreach_get("vector", uv)
        corners = np.empty(len(me.loop_triangles) * 3, np.int32)
        me.loop_triangles.foreach_get("loops", corners)
        tri_uv = uv.reshape(-1, 2)[corners.reshape(-1, 3)]
        assert raster.rasterize(tri_uv, width, height, device.select("cpu")).count > 0, name


def test_object_deleted_during_a_modal_lightmap_bake_writes_no_file(blend, tmp_path):
    fast_settings(bpy.context.scene, target="both", output=str(tmp_path / "maps"), texel_density=4.0)
    before = user_data()
    job = BakeJob(bpy.context.scene.radiosity_baker.to_settings())
    job.start(bpy.context)
    bpy.data.objects.remove(bpy.data.objects[OCCLUDER])
    before = {k: v for k, v in before.items() if k != "objects" and OCCLUDER not in k}
    while not job.poll()[2]:
        threading.Event().wait(0.01)
    with pytest.raises(RuntimeError, match=f"object {OCCLUDER} no longer exists"):
        job.finish(bpy.context)
    assert not (tmp_path / "maps").exists()
    assert {k: v for k, v in user_data().items() if k != "objects" and OCCLUDER not in k} == before


def test_mesh_renamed_during_a_modal_lightmap_bake_gets_its_uv_map(blend, tmp_path):
    fast_settings(bpy.context.scene, target="lightmap", output=str(tmp_path / "maps"),
                  texel_density=4.0)
    job = BakeJob(bpy.context.scene.radiosity_baker.to_settings())
    job.start(bpy.context)
    bpy.data.objects[OCCLUDER].data.name = "Renamed"
    job.finish(bpy.context)
    assert "Lightmap" in bpy.data.meshes["Renamed"].uv_layers
    assert (tmp_path / "maps" / "Lightmap.exr").is_file()


def test_mesh_edited_during_a_modal_bake_writes_nothing(blend):
    fast_settings(bpy.context.scene)
    job = BakeJob(bpy.context.scene.radiosity_baker.to_settings())
    job.start(bpy.context)
    bpy.data.objects[OCCLUDER].data.vertices.add(1)
    before = user_data()
    with pytest.raises(RuntimeError, match=f"{OCCLUDER} changed during the bake"):
        job.finish(bpy.context)
    assert user_data() == before


# ------------------------------------------------------------------------------------------------
# exit codes and messages


def test_device_cuda_without_a_gpu_is_exit_2(blend, tmp_path, capsys, monkeypatch):
    import warp

    monkeypatch.setattr(warp, "get_cuda_device_count", lambda: 0)
    fails(capsys, tmp_path, blend, 2, ["cuda", "--device cpu"], *FAST, "--device", "cuda",
          started=False)


@pytest.mark.parametrize("objects, status, words", [
    ("", 2, ["--objects"]), (",", 2, ["--objects"]), ("Lamp", 1, ["nothing to write", "Lamp"])])
def test_objects_naming_nothing_to_write_are_errors(blend, tmp_path, capsys, objects, status, words):
    fails(capsys, tmp_path, blend, status, words, *FAST, "--objects", objects, "--save",
          tmp_path / "out.blend", started=False)


@pytest.fixture
def bake_raises(monkeypatch):
    """``bake_raises(exc)``: the bake itself (core.bake, as the job calls it) raises ``exc``."""
    from radiosity_baker.addon import job as job_module

    def arm(exc):
        def bake(*args, **kwargs):
            raise exc

        monkeypatch.setattr(job_module.Sequence, "bake", bake)

    return arm


def test_ctrl_c_is_one_line_and_status_130(blend, tmp_path, capsys, bake_raises):
    bake_raises(KeyboardInterrupt())
    digest = sha(blend)
    try:
        run = bake(capsys, blend, *FAST, "--save", tmp_path / "new" / "out.blend")
    except KeyboardInterrupt:  # escaping, it would stop the whole test session
        pytest.fail("KeyboardInterrupt escaped the command line")
    assert (run.status, run.err) == (130, ["radiosity_baker: bake cancelled"])
    assert sha(blend) == digest and not (tmp_path / "new").exists()


def _as_from_a_shell():
    """In the child before it starts: Ctrl-C as a terminal delivers it. Blender's threads in this
    test process may be ignoring or blocking SIGINT when it forks, and a child would inherit
    that (Python keeps an ignored SIGINT ignored): the bake then runs to its end."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, [signal.SIGINT])


def test_ctrl_c_of_a_real_process(tmp_path):
    # 4096 light samples keep the direct stage busy for seconds after its first line, so the
    # signal lands in the bake even when this process reads the line late
    env = {k: v for k, v in os.environ.items() if k != "BLENDER_USER_RESOURCES"}
    out = tmp_path / "out.blend"
    proc = subprocess.Popen([sys.executable, "-m", "radiosity_baker", "bake", str(CORNELL),
                             "--samples", "4096", "--save", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                            preexec_fn=_as_from_a_shell)
    for line in proc.stdout:
        if line.startswith("radiosity_baker: direct"):
            proc.send_signal(signal.SIGINT)
            break
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert err.strip().splitlines()[-1] == "radiosity_baker: bake cancelled"
    assert "Traceback" not in err and not out.exists() and list(tmp_path.iterdir()) == []


def test_a_first_ctrl_c_asks_the_bake_to_stop_and_a_second_interrupts():
    # the first only sets the job's flag, so it cannot be lost in a finaliser (where Python drops
    # a KeyboardInterrupt); the bake's next check raises BakeCancelled
    class Job:
        def __init__(self):
            self.asked = 0

        def stop_soon(self):
            self.asked += 1

    job = Job()
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    with pytest.raises(KeyboardInterrupt):
        with cli._ctrl_c_stops(job):
            signal.raise_signal(signal.SIGINT)
            assert job.asked == 1
            signal.raise_signal(signal.SIGINT)
    assert job.asked == 1 and signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_an_internal_error_shows_its_traceback_and_one_line(blend, capsys, bake_raises):
    bake_raises(ValueError("a bug"))
    run = bake(capsys, blend, *FAST)
    assert run.status == 1 and "Traceback (most recent call last):" in run.err
    assert run.err[-1] == "radiosity_baker: error: internal error: ValueError: a bug"


def test_an_internal_error_in_the_operator_says_so_and_prints_its_traceback(blend, capsys,
                                                                            bake_raises):
    bake_raises(ValueError("a bug"))
    fast_settings(bpy.context.scene)
    before = user_data()
    with pytest.raises(RuntimeError, match="internal error: ValueError: a bug"):
        bpy.ops.object.radiosity_bake(use_selected=False)
    assert "Traceback (most recent call last):" in capsys.readouterr().err
    assert user_data() == before


# ------------------------------------------------------------------------------------------------
# cases that bake: only what was asked for changes


def test_topology_changing_modifier_is_skipped_or_baked_into_a_copy(blend, tmp_path, capsys):
    bpy.data.objects[OCCLUDER].modifiers.new("Sub", "SUBSURF")
    save(blend)
    before = data_of(blend)
    out = tmp_path / "out.blend"
    run = bake(capsys, blend, *FAST, "--save", out)
    assert run.status == 0 and any(OCCLUDER in line and "--bake-copy" in line for line in run.err)
    assert data_of(out) == before and "Lighting" not in bpy.data.objects[OCCLUDER].data.attributes
    assert bake(capsys, blend, *FAST, "--bake-copy", "--save", out).status == 0
    after = data_of(out)
    copy = f"{OCCLUDER}_baked"
    assert "Lighting" in bpy.data.objects[copy].data.attributes
    assert {k: v for k, v in after.items() if copy not in k and k != "objects"} == {
        k: v for k, v in before.items() if k != "objects"}


def test_shared_mesh_is_baked_with_a_warning(blend, tmp_path, capsys):
    twin = bpy.data.objects.new("Twin", bpy.data.objects[OCCLUDER].data)
    twin.location = (-1.0, 0.0, 1.5)
    bpy.context.scene.collection.objects.link(twin)
    save(blend)
    before = data_of(blend)
    out = tmp_path / "out.blend"
    run = bake(capsys, blend, *FAST, "--save", out)
    assert run.status == 0 and any("shared by" in line for line in run.err)
    assert data_of(out) == before


def test_a_mirrored_object_bakes_as_its_mirror_image(blend, tmp_path, capsys):
    """Mirrored in x, the ground's vertex at (x, y) lies where the unmirrored one's at (−x, y) does."""
    def ground_values(path):
        out = tmp_path / "out.blend"
        assert bake(capsys, path, *FAST, "--objects", GROUND, "--save", out).status == 0
        bpy.ops.wm.open_mainfile(filepath=str(out))
        me = bpy.data.objects[GROUND].data
        co = np.empty(len(me.vertices) * 3, np.float32)
        me.vertices.foreach_get("co", co)
        return co.reshape(-1, 3), vertex_colors(me, "Lighting")[:, :3]

    co, plain = ground_values(blend)
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    bpy.data.objects[GROUND].scale.x = -1.0
    _, mirrored = ground_values(save(tmp_path / "mirrored.blend"))
    key = {(round(float(x), 4), round(float(y), 4)): i for i, (x, y, _) in enumerate(co)}
    partner = [key[(round(float(-x), 4), round(float(y), 4))] for x, y, _ in co]
    # the quads' diagonals mirror too: border vertices, moved into their triangles, move differently
    np.testing.assert_allclose(mirrored, plain[partner], rtol=2e-3, atol=1e-6)
    assert plain.max() > 0.1


def test_a_bake_in_place_keeps_the_original_as_a_version(blend, tmp_path, capsys):
    original, before = blend.read_bytes(), data_of(blend)
    assert bake(capsys, blend, *FAST, "--save", blend).status == 0
    assert data_of(blend) == before and "Lighting" in bpy.data.objects[GROUND].data.attributes
    assert (tmp_path / "in.blend1").read_bytes() == original
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.blend", "in.blend1"]


def test_the_same_save_twice(blend, tmp_path, capsys):
    out, before = tmp_path / "out.blend", data_of(blend)
    assert bake(capsys, blend, *FAST, "--save", out).status == 0
    first = out.read_bytes()
    assert bake(capsys, blend, *FAST, "--save", out, "--report", tmp_path / "r.json").status == 0
    assert (tmp_path / "out.blend1").read_bytes() == first
    assert data_of(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.blend", "out.blend", "out.blend1",
                                                          "r.json"]



# ------------------------------------------------------------------------------------------------
# medium cases: file names, linked meshes, half floats, stale temporaries


def test_objects_whose_names_clean_to_one_file_name_get_files_of_their_own(blend, tmp_path, capsys):
    bpy.data.objects[GROUND].name, bpy.data.objects[OCCLUDER].name = "a/b", "a_b"
    save(blend)
    maps, out = tmp_path / "maps", tmp_path / "out.blend"
    run = bake(capsys, blend, *FAST, *LIGHTMAP, "--layout", "per_object", "--output", maps,
               "--save", out)
    assert run.status == 0, run.err
    assert any("share the file name Lightmap_a_b" in line for line in run.err), run.err
    assert sorted(p.name for p in maps.glob("*.exr")) == ["Lightmap_a_b.exr", "Lightmap_a_b_2.exr"]
    bpy.ops.wm.open_mainfile(filepath=str(out))
    paths = {im.name: bpy.path.abspath(im.filepath) for im in bpy.data.images
             if im.get("radiosity_baker_lightmap")}
    assert sorted(paths) == ["Lightmap_a/b", "Lightmap_a_b"] and len(set(paths.values())) == 2


def test_a_scene_whose_meshes_are_all_linked_from_a_library_is_exit_1(empty_scene, tmp_path, capsys):
    lit_ground(empty_scene)
    library = save(tmp_path / "library.blend")
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    with bpy.data.libraries.load(str(library), link=True) as (source, linked):
        linked.objects = source.objects
    for ob in linked.objects:
        bpy.context.scene.collection.objects.link(ob)
    blend = save(tmp_path / "in.blend")
    fails(capsys, tmp_path, blend, 1, ["nothing to write", "linked from a library"], *FAST,
          "--save", tmp_path / "out.blend", started=False)


def test_lighting_beyond_half_float_is_written_as_float_with_a_warning(blend, tmp_path, capsys):
    bpy.data.lights["Lamp"].energy = 1e8  # about 3·10⁵ under the lamp
    save(blend)
    maps = tmp_path / "maps"
    run = bake(capsys, blend, *FAST, *LIGHTMAP, "--output", maps)
    assert run.status == 0 and any("beyond half float's 65504" in line for line in run.err), run.err
    exr = files.read_exr(maps / "Lightmap.exr")
    assert np.isfinite(exr).all() and exr.max() > 65504


def test_a_bake_into_a_folder_removes_the_temporaries_a_killed_bake_left_there(blend, tmp_path, capsys):
    """Ours alone (hidden, ``.rb-`` and 8 hex digits, or check_folder's probe) and only those older
    than the run: a file another bake is writing now stays."""
    maps = tmp_path / "maps"
    maps.mkdir()
    stale = [".Lightmap.rb-deadbeef.exr", ".Lightmap.rb-deadbeef-old.png", ".out.rb-0badf00d",
             ".radiosity_baker-0badf00d.tmp"]
    kept = [".Lightmap.rb-notes.txt", "Lightmap.rb-deadbeef.exr", ".young.rb-12345678.exr"]
    for name in stale + kept:
        (maps / name).write_text("left")
        when = 1e9 if name != kept[-1] else os.stat(maps / name).st_mtime + 3600
        os.utime(maps / name, (when, when))
    assert bake(capsys, blend, *FAST, *LIGHTMAP, "--output", maps).status == 0
    assert sorted(p.name for p in maps.iterdir()) == sorted(kept + ["Lightmap.exr", "Lightmap.png"])


def _workers(pid: int) -> list[int]:
    """The pids of the xatlas workers process ``pid`` started (Linux /proc)."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            parent = int(stat.read_text().rsplit(")", 1)[1].split()[1])
            command = (stat.parent / "cmdline").read_bytes()
        except (OSError, ValueError, IndexError):
            continue
        if parent == pid and b"_xatlas_worker" in command:
            found.append(int(stat.parent.name))
    return found


def _running(pid: int) -> bool:
    """Whether process ``pid`` still runs (a zombie waiting to be reaped does not)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] not in ("Z", "X")
    except OSError:
        return False


def _until(condition, seconds: float) -> bool:
    end = time.monotonic() + seconds
    while not condition() and time.monotonic() < end:
        time.sleep(0.05)
    return condition()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc; PR_SET_PDEATHSIG")
@pytest.mark.parametrize("how", ["Ctrl-C", "SIGINT", "SIGTERM", "kill -9"])
def test_stopping_a_bake_while_it_unwraps_stops_the_xatlas_workers(empty_scene, tmp_path, how):
    """A 20480-face sphere keeps xatlas busy for seconds: Ctrl-C (to the terminal's process group)
    or SIGINT to the bake alone ends the bake with status 130 and its workers at once, SIGTERM
    likewise with status 143, all three leaving no temporary folder; kill -9 of the bake ends the
    workers with it."""
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=6)
    lamp = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT"))
    lamp.location = (0.0, 0.0, 3.0)
    empty_scene.collection.objects.link(lamp)
    blend = save(tmp_path / "sphere.blend")
    env = {k: v for k, v in os.environ.items() if k != "BLENDER_USER_RESOURCES"}
    env["RADIOSITY_BAKER_CACHE"] = str(tmp_path / "cache")  # nothing cached: xatlas runs
    proc = subprocess.Popen([sys.executable, "-m", "radiosity_baker", "bake", str(blend), *FAST,
                             "--target", "lightmap", "--texel-density", "200", "--max-size", "4096",
                             "--output", str(tmp_path / "maps")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                            preexec_fn=_as_from_a_shell, start_new_session=True)
    try:
        for line in proc.stdout:
            if line.startswith("radiosity_baker: unwrap"):
                break
        assert _until(lambda: _workers(proc.pid), 20), "no xatlas worker started"
        workers = _workers(proc.pid)
        if how == "Ctrl-C":
            os.killpg(proc.pid, signal.SIGINT)  # what a terminal does: the whole foreground group
        else:
            proc.send_signal({"SIGINT": signal.SIGINT, "SIGTERM": signal.SIGTERM}.get(how, signal.SIGKILL))
        _, err = proc.communicate(timeout=60)
        assert _until(lambda: not any(map(_running, workers)), 3), "xatlas workers still run"
        if how in ("Ctrl-C", "SIGINT"):
            assert proc.returncode == 130, err
            assert err.strip().splitlines()[-1] == "radiosity_baker: bake cancelled"
        if how == "SIGTERM":  # before: exit 143 without a word, the workers' folder left behind
            assert proc.returncode == 143, err
            assert err.strip().splitlines()[-1] == "radiosity_baker: bake stopped (SIGTERM)"
        if how != "kill -9":  # nothing left: the workers' folder, the output folder
            assert not list((tmp_path / "cache").glob("rb-xatlas-*"))
            assert not (tmp_path / "maps").exists()
    finally:
        proc.kill()
        proc.wait()


def test_a_second_objects_bake_replacing_the_first_ones_lightmap_file_says_so(blend, tmp_path, capsys):
    """Two ``--objects`` bakes into one folder share the atlas file ``Lightmap.exr``: the second
    replaces the first's, which the first's saved .blend still shows (before: without a word).
    Baking the same objects again replaces nothing of another bake: no warning."""
    maps = tmp_path / "maps"
    first = bake(capsys, blend, *FAST, *LIGHTMAP, "--objects", GROUND, "--output", maps,
                 "--save", tmp_path / "ground.blend")
    assert first.status == 0 and not [w for w in first.err if "held the lightmap" in w]
    second = bake(capsys, blend, *FAST, *LIGHTMAP, "--objects", OCCLUDER, "--output", maps,
                  "--save", tmp_path / "occluder.blend")
    said = [w for w in second.err if "held the lightmap" in w]
    assert second.status == 0 and len(said) == 1, second.err
    assert f"Lightmap.exr in {maps} held the lightmap of {GROUND}" in said[0]
    assert f"now holds {OCCLUDER}'s" in said[0] and "its own --output" in said[0]
    again = bake(capsys, blend, *FAST, *LIGHTMAP, "--objects", OCCLUDER, "--output", maps)
    assert again.status == 0 and not [w for w in again.err if "held the lightmap" in w]
