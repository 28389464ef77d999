"""Where results go on disk: paths checked before a bake, files written under temporary names beside
their targets and moved into place together at the end, so that a failure, a cancel or a full disk
leaves every target (and the folders around it) as it was.
"""
from __future__ import annotations

import contextlib
import os
import re
import secrets
import shutil
import time
from pathlib import Path

from ..core.errors import BakeError


class OutputError(BakeError):
    """A result cannot be written where it was asked for: an unwritable path, or a name that other
    data of the file already holds. The message names the path, or the object and the clash."""


# The names of the temporary files Staging (``.NAME.rb-<8 hex>[-old].EXT``) and check_folder
# (``.radiosity_baker-<8 hex>.tmp``) make: only these are ever removed as stale.
_TEMPORARY = re.compile(r"\..+\.rb-([0-9a-f]{8})(-old)?(\.[^.]*)?|\.radiosity_baker-[0-9a-f]{8}\.tmp")


def remove_stale(folder: Path, before: float, keep: str = "") -> None:
    """Remove from ``folder`` the temporary files that bakes killed while writing (``kill -9``, a
    crash) left behind: our names alone (``_TEMPORARY``), last modified before ``before`` (seconds
    since the epoch, the start of this run), none of the token ``keep`` (this run's). Files that
    cannot be removed are left."""
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return
    for entry in entries:
        match = _TEMPORARY.fullmatch(entry.name)
        if match is None or (keep and match[1] == keep):
            continue
        with contextlib.suppress(OSError):
            if entry.is_file(follow_symlinks=False) and entry.stat(follow_symlinks=False).st_mtime < before:
                os.unlink(entry.path)


def _make_folders(folder: Path, made: list) -> None:
    """Create ``folder`` and its missing parents, prepending each one made to ``made`` (so it lists
    them deepest first). Raises OSError."""
    missing = []
    while not folder.exists() and folder.parent != folder:
        missing.append(folder)
        folder = folder.parent
    for path in reversed(missing):
        path.mkdir()
        made.insert(0, path)


def _remove_folders(made: list) -> None:
    """Remove the folders in ``made`` (deepest first) that are still empty."""
    for path in made:
        with contextlib.suppress(OSError):
            path.rmdir()


def _reason(exc: OSError) -> str:
    return exc.strerror or str(exc)


def same_file(a: Path, b: Path) -> bool:
    """Whether paths ``a`` and ``b`` name one file: the same after resolving links, ``.`` and
    ``..``, or (where both exist) the same device and inode, which also catches another spelling
    of the name on a case-insensitive file system."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist (yet)
        return False


def check_folder(folder: Path, target=None) -> None:
    """Raise OutputError unless files can be created in ``folder``: missing folders are made, a file
    is created in it and everything is removed again, so the check leaves nothing behind (creating a
    file is the only test that holds for every file system and user, root and /proc included).
    ``target`` is the path the message names (default: the folder)."""
    made: list = []
    try:
        _make_folders(folder, made)
        probe = folder / f".radiosity_baker-{secrets.token_hex(4)}.tmp"
        probe.open("xb").close()
        probe.unlink()
    except OSError as exc:
        raise OutputError(f"cannot write {target or folder}: {_reason(exc)}") from None
    finally:
        _remove_folders(made)


def check_file(path: Path) -> None:
    """Raise OutputError unless a file can be written at ``path`` (see :func:`check_folder`)."""
    if path.is_dir():
        raise OutputError(f"cannot write {path}: it is a directory")
    if path.exists() and not os.access(path, os.W_OK):
        raise OutputError(f"cannot write {path}: permission denied")
    check_folder(path.parent, path)


class Staging:
    """Files written under temporary names beside their targets and moved into place together::

        with Staging() as staging:
            with staging.writing(target) as temp:
                ...  # write the file at ``temp`` and check it
            staging.commit()  # every target replaced, or none

    A temporary file sits in its target's folder (so the final rename is atomic, and a .blend's
    relative paths stay right) and keeps its suffix (so writers choose the format by it). Leaving
    the block without ``commit`` (an error, Ctrl-C) removes the temporary files and the folders made
    for them; the targets are untouched. The first file written into a folder removes from it the
    temporary files earlier bakes left when killed (``remove_stale``).
    """

    def __init__(self):
        self._token = secrets.token_hex(4)
        self._started = time.time()
        self._swept: set = set()  # folders cleared of stale temporary files (``remove_stale``)
        self._files: list = []   # (temporary, target, versions)
        self._folders: list = []  # made for the targets, deepest first
        self._committed = False

    def __enter__(self) -> "Staging":
        return self

    def __exit__(self, *exc) -> None:
        if not self._committed:
            for temp, _, _ in self._files:
                with contextlib.suppress(OSError):
                    temp.unlink()
            _remove_folders(self._folders)

    def _aside(self, target: Path, tag: str) -> Path:
        return target.with_name(f".{target.stem}.rb-{self._token}{tag}{target.suffix}")

    @contextlib.contextmanager
    def writing(self, target: Path, versions: int = 0):
        """Yield the temporary path to write ``target`` at. An OSError or BakeError while writing or
        checking it becomes OutputError naming ``target``. ``versions`` > 0 keeps the file it
        replaces as ``<name>1`` … ``<name>N``, older ones shifted up (Blender's Save Versions)."""
        target = Path(target)
        temp = self._aside(target, "")
        try:
            _make_folders(target.parent, self._folders)
            if target.parent not in self._swept:
                self._swept.add(target.parent)
                remove_stale(target.parent, self._started, self._token)
            self._files.append((temp, target, versions))
            yield temp
        except OSError as exc:
            raise OutputError(f"cannot write {target}: {_reason(exc)}") from None
        except BakeError as exc:
            if isinstance(exc, OutputError):
                raise
            # the writer's message names the temporary file: name the target instead
            raise OutputError(str(exc).replace(str(temp), str(target))) from None

    def commit(self) -> None:
        """Move every file into place, each with one atomic rename over its target. When one fails,
        the targets replaced before it get their old content back and OutputError names it."""
        replaced = []  # (target, whether it existed, a link to its old content or None)
        try:
            for temp, target, _ in self._files:
                existed = target.exists()
                old = self._keep_old(target) if existed else None
                try:
                    os.replace(temp, target)
                except OSError:
                    if old is not None:
                        with contextlib.suppress(OSError):
                            old.unlink()
                    raise
                replaced.append((target, existed, old))
        except OSError as exc:
            for done, existed, old in reversed(replaced):
                with contextlib.suppress(OSError):
                    if old is not None:
                        os.replace(old, done)
                    elif not existed:
                        done.unlink()
            raise OutputError(f"cannot write {target}: {_reason(exc)}") from None
        self._committed = True
        for (_, target, versions), (_, _, old) in zip(self._files, replaced):
            if old is not None:
                _keep_version(old, target, versions)

    def _keep_old(self, target: Path):
        """A second name for the content of ``target`` (a hard link, else a copy), so that it can be
        restored or kept as a version; None where neither can be made (it then cannot be undone)."""
        old = self._aside(target, "-old")
        try:
            os.link(target, old)
        except OSError:
            try:
                shutil.copy2(target, old)
            except OSError:
                with contextlib.suppress(OSError):
                    old.unlink()
                return None
        return old


def _keep_version(old: Path, target: Path, versions: int) -> None:
    """Keep ``old`` (the replaced content of ``target``) as ``<target>1``, shifting ``<target>1`` …
    up to ``<target>N``; with ``versions`` 0 it is removed."""
    with contextlib.suppress(OSError):
        if versions < 1:
            old.unlink()
            return
        for i in range(versions - 1, 0, -1):
            older = target.with_name(f"{target.name}{i}")
            if older.exists():
                os.replace(older, target.with_name(f"{target.name}{i + 1}"))
        os.replace(old, target.with_name(f"{target.name}1"))
