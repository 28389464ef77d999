"""The unwrap cache: in a folder of the user's own (not the shared temporary folder), entries
written whole or not at all, held to a size by removing the least recently used, and leftovers
of killed bakes removed once stale."""
import os
import stat
import tempfile
from pathlib import Path

import numpy as np
import pytest

from radiosity_baker.core.lightmap import cache


def test_the_cache_lies_in_the_users_own_cache_folder_not_the_shared_temporary_one(monkeypatch, tmp_path):
    monkeypatch.delenv("RADIOSITY_BAKER_CACHE", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache.default_dir() == tmp_path / "xdg" / "radiosity_baker" / "unwrap"
    monkeypatch.delenv("XDG_CACHE_HOME")
    folder = cache.default_dir()
    assert folder == Path.home() / ".cache" / "radiosity_baker" / "unwrap"
    assert Path(tempfile.gettempdir()) not in folder.parents
    monkeypatch.setenv("RADIOSITY_BAKER_CACHE", str(tmp_path / "mine"))
    assert cache.default_dir() == tmp_path / "mine"
    made = cache.prepare(tmp_path / "mine" / "deeper")
    assert stat.S_IMODE(made.stat().st_mode) == 0o700  # nobody else may write (or read) there


def test_an_entry_whose_writing_fails_leaves_nothing_behind(monkeypatch, tmp_path):
    def savez(file, **arrays):
        file.write(b"PK\x03\x04 half an entry")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np, "savez", savez)
    with pytest.raises(OSError, match="No space"):
        cache.cached(tmp_path, "c", {"k": 1}, lambda todo: {"k": {"uv": np.zeros(4)}})
    assert list(tmp_path.iterdir()) == []  # neither a damaged entry nor a temporary file


def _entry(folder: Path, name: str, size: int, age: float) -> Path:
    path = folder / name
    np.savez(path, data=np.zeros(size // 8))
    then = path.stat().st_mtime - age
    os.utime(path, (then, then))
    return path


def test_the_cache_is_held_to_its_size_removing_the_least_recently_used(monkeypatch, tmp_path):
    old = _entry(tmp_path, "c-old.npz", 4000, 300)
    read = _entry(tmp_path, "c-read.npz", 4000, 200)
    recent = _entry(tmp_path, "c-recent.npz", 4000, 100)
    monkeypatch.setattr(cache, "MAX_BYTES", 3 * read.stat().st_size)
    computed = []

    def compute(todo):
        computed.extend(todo)
        return {key: {"data": np.zeros(500)} for key in todo}

    out = cache.cached(tmp_path, "c", {"read": 0, "new": 0}, compute)
    assert computed == ["new"] and set(out) == {"read", "new"}
    # reading "read" made it the most recently used: the oldest untouched entry went
    assert not old.exists() and read.exists() and recent.exists()
    assert (tmp_path / "c-new.npz").exists()
    assert sum(p.stat().st_size for p in tmp_path.iterdir()) <= cache.MAX_BYTES


def test_leftovers_of_a_killed_bake_are_removed_once_stale(tmp_path):
    stale, fresh = tmp_path / "rb-xatlas-stale", tmp_path / "rb-xatlas-fresh"
    for folder in (stale, fresh):
        folder.mkdir()
        (folder / "in0.npz").write_bytes(b"x")
    temp = tmp_path / ".rb-entry-abc.npz"
    temp.write_bytes(b"x")
    long_ago = stale.stat().st_mtime - cache.STALE - 60
    for path in (stale, temp):
        os.utime(path, (long_ago, long_ago))
    cache.prune(tmp_path)
    assert not stale.exists() and not temp.exists() and fresh.exists()
