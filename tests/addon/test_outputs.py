"""Output files: checked without leaving a trace, staged beside their targets, moved in all or none."""
import os

import pytest

from radiosity_baker.addon.outputs import OutputError, Staging, check_file, check_folder
from radiosity_baker.core.errors import BakeError


def test_checks_leave_nothing_behind(tmp_path):
    check_folder(tmp_path / "a" / "b")
    check_file(tmp_path / "c" / "out.blend")
    assert list(tmp_path.iterdir()) == []
    (tmp_path / "file").write_text("x")
    with pytest.raises(OutputError, match="file/out.blend"):
        check_file(tmp_path / "file" / "out.blend")
    with pytest.raises(OutputError, match="it is a directory"):
        check_file(tmp_path)
    with pytest.raises(OutputError, match="/proc/radiosity_baker"):
        check_folder(tmp_path.parent / "/proc/radiosity_baker")


def test_commit_moves_every_file_into_place_and_keeps_versions(tmp_path):
    blend, report = tmp_path / "out.blend", tmp_path / "new" / "report.json"
    for content in ("first", "second", "third"):
        with Staging() as staging:
            with staging.writing(blend, versions=2) as temp:
                temp.write_text(content)
            with staging.writing(report) as temp:
                temp.write_text(content)
            assert not blend.exists() or blend.read_text() != content  # nothing moved yet
            staging.commit()
    assert (blend.read_text(), report.read_text()) == ("third", "third")
    assert (tmp_path / "out.blend1").read_text() == "second"
    assert (tmp_path / "out.blend2").read_text() == "first"
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["new", "out.blend", "out.blend1",
                                                            "out.blend2", "report.json"]


@pytest.mark.parametrize("error", [OSError(28, "No space left on device"), BakeError("broken")])
def test_a_failed_write_leaves_the_targets_and_removes_temporaries_and_folders(tmp_path, error):
    old = tmp_path / "old.txt"
    old.write_text("old")
    with pytest.raises(OutputError, match="No space left|broken"):
        with Staging() as staging:
            with staging.writing(old) as temp:
                temp.write_text("new")
            with staging.writing(tmp_path / "deep" / "er" / "new.txt") as temp:
                temp.write_text("partial")
                raise error
            staging.commit()
    assert [p.name for p in tmp_path.iterdir()] == ["old.txt"] and old.read_text() == "old"


def test_a_writers_message_names_the_target_not_the_temporary_file(tmp_path):
    target = tmp_path / "Lightmap.exr"
    with pytest.raises(OutputError) as caught:
        with Staging() as staging:
            with staging.writing(target) as temp:
                raise BakeError(f"cannot write {temp}: disk full")
    assert str(caught.value) == f"cannot write {target}: disk full"


def test_a_failed_rename_restores_the_targets_replaced_before_it(tmp_path, monkeypatch):
    first, second, third = (tmp_path / n for n in ("a.exr", "b.png", "c.json"))
    first.write_text("old a")
    real = os.replace

    def replace(src, dst):
        if str(dst) == str(third):
            raise OSError(13, "Permission denied")
        real(src, dst)

    with Staging() as staging:
        for target in (first, second, third):
            with staging.writing(target) as temp:
                temp.write_text("new")
        monkeypatch.setattr(os, "replace", replace)
        with pytest.raises(OutputError, match="c.json: Permission denied"):
            staging.commit()
    assert [p.name for p in tmp_path.iterdir()] == ["a.exr"] and first.read_text() == "old a"
