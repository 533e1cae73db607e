"""Atomic output files: complete or absent, with the user's normal permissions.

Every fracas output (HDF5 files, PNG plots) is built under a temporary name in the
destination folder, flushed and ``fsync``-ed, given the permissions a plain ``open()``
would give it (``0o666 & ~umask``), then moved over the destination with ``os.replace``
(atomic on POSIX within one filesystem).  A failure, or a kill, at any point leaves the
previous file at the destination untouched: readers never see a partial file.

Temporary files are named ``.<name>.<pid>-<host>.<random>.tmp`` in the destination folder
(``<host>``: 8 hex digits identifying this machine and PID namespace, :func:`host_tag`;
``<random>``: 8 characters of ``tempfile``'s alphabet), so they can be recognised.  A
killed run leaves one behind; the next write to that folder removes those of this pattern
whose process is gone (judged only for temporaries of this host: on a shared filesystem
another machine's pid means nothing here) or that are older than an hour
(:func:`remove_stale_temps`), nothing else.

:func:`check_output_path` checks an output path before a run starts, creating nothing; it
and :func:`atomic_path` refuse an output that is one of the run's inputs (its deck, a file
the deck names: :mod:`fracas.io.inputs`).  A write that fails for want of room (a full disk,
a quota) removes its temporary file and raises an OSError naming the destination.
"""

from __future__ import annotations

import contextlib
import errno
import functools
import hashlib
import os
import re
import socket
import tempfile
import time
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

from fracas.errors import OutputPathError
from fracas.io.inputs import input_conflict, path_text

__all__ = [
    "STALE_AGE_S",
    "TEMP_PATTERN",
    "atomic_path",
    "check_output_path",
    "check_not_input",
    "file_mode",
    "host_tag",
    "remove_stale_temps",
    "savefig_atomic",
    "temp_prefix",
]

STALE_AGE_S = 3600.0  # a temporary file older than this is stale even if its pid is alive (pid reuse)
TEMP_PATTERN = re.compile(r"^\.(?P<name>.+)\.(?P<pid>[0-9]+)-(?P<host>[0-9a-f]{8})\.(?P<rand>[a-z0-9_]{8})\.tmp$")


@functools.cache
def host_tag() -> str:
    """8 hex digits naming this machine and PID namespace (hostname, ``/proc/self/ns/pid``)."""
    try:
        ns = os.readlink("/proc/self/ns/pid")
    except OSError:
        ns = ""
    return hashlib.sha256(f"{socket.gethostname()}\0{ns}".encode()).hexdigest()[:8]


def _umask() -> int:
    """The process umask, read without changing it where possible (Linux ``/proc``)."""
    with contextlib.suppress(OSError, ValueError):
        with open("/proc/self/status", encoding="ascii", errors="replace") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    old = os.umask(0o022)  # elsewhere: set and restore at once
    os.umask(old)
    return old


def file_mode() -> int:
    """Permissions of a new file for this user: ``0o666 & ~umask``."""
    return 0o666 & ~_umask()


def temp_prefix(name: str) -> str:
    """``.<name>.<pid>-<host>.``: the start of this process's temporary names for ``name``."""
    return f".{name}.{os.getpid()}-{host_tag()}."


def _pid_alive(pid: int) -> bool:
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, another user's
        return True
    except OSError:
        return False
    return True


def remove_stale_temps(folder: str | os.PathLike, max_age_s: float = STALE_AGE_S) -> list[Path]:
    """Remove this module's temporary files in ``folder`` whose process is gone (temporaries
    of this host only) or that are older than ``max_age_s``; only plain files matching
    :data:`TEMP_PATTERN`.  Returns them."""
    removed: list[Path] = []
    now = time.time()
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    for entry in entries:
        m = TEMP_PATTERN.match(entry.name)
        if m is None:
            continue
        try:
            if not entry.is_file(follow_symlinks=False):
                continue
            age = now - entry.stat(follow_symlinks=False).st_mtime
        except OSError:
            continue
        pid, here = int(m.group("pid")), m.group("host") == host_tag()
        if here and pid == os.getpid() and age <= max_age_s:
            continue  # possibly a write in progress in another thread of this process
        if age > max_age_s or (here and not _pid_alive(pid)):
            with contextlib.suppress(OSError):
                os.unlink(entry.path)
                removed.append(Path(entry.path))
    return removed


def _fsync_dir(folder: Path) -> None:
    with contextlib.suppress(OSError):  # best effort: not every filesystem allows it
        dfd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)


#: a full disk, a quota, a file too big: the write failed for want of room
_NO_ROOM = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG})


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """``with atomic_path(dest) as tmp:`` write ``tmp``; on success it becomes ``dest``.

    ``tmp`` is an empty file ``.<name>.<pid>-<host>.<random>.tmp`` in ``dest``'s folder (created
    if needed); the writer may truncate or recreate it.  On leaving the block normally it is
    fsync-ed, given mode ``0o666 & ~umask`` and renamed over ``dest``; on any exception it
    is removed and the exception propagates, ``dest`` untouched (a full disk: an OSError
    naming ``dest``, not the temporary file).  Stale temporary files of killed runs in the
    folder are removed first (:func:`remove_stale_temps`).  A ``dest`` that is an input of
    the run (:mod:`fracas.io.inputs`) is refused before anything is written.
    """
    dest = Path(path)
    check_not_input(dest, "output file")
    folder = dest.parent
    folder.mkdir(parents=True, exist_ok=True)
    remove_stale_temps(folder)
    fd, name = tempfile.mkstemp(prefix=temp_prefix(dest.name), suffix=".tmp", dir=folder)
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        with open(tmp, "rb+") as fh:
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, file_mode())
        os.replace(tmp, dest)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(exc, OSError) and exc.errno in _NO_ROOM and exc.filename in (None, name, str(tmp)):
            raise type(exc)(exc.errno, exc.strerror, str(dest)) from None
        raise
    _fsync_dir(folder)


def savefig_atomic(fig: Any, path: str | os.PathLike, **kwargs: Any) -> Path:
    """``fig.savefig`` into ``path`` atomically (:func:`atomic_path`); returns the path.

    The format is ``kwargs["format"]`` or the suffix of ``path`` (``png`` without one);
    other keyword arguments go to ``savefig``.  The figure is not closed.
    """
    dest = Path(path)
    fmt = kwargs.pop("format", None) or (dest.suffix[1:].lower() or "png")
    with atomic_path(dest) as tmp:
        fig.savefig(tmp, format=fmt, **kwargs)
    return dest


def check_not_input(dest: str | os.PathLike, what: str, inputs: Iterable[str | os.PathLike | None] = ()) -> None:
    """A one-line OutputPathError if ``dest`` is the same file (through symlinks and hard
    links) as one of ``inputs`` or as a file this run has read (:mod:`fracas.io.inputs`)."""
    other = input_conflict(dest, inputs)
    if other is not None:
        shown = path_text(dest)
        same = "" if other == shown else f" (the same file as {other})"
        raise OutputPathError(
            f"{shown}: {what} is an input of this run{same}; expected another output path",
            reason=f"is an input of this run{same}",
        )


def check_output_path(path: str | os.PathLike, what: str, inputs: Iterable[str | os.PathLike | None] = ()) -> Path:
    """The output ``path`` as a Path, or a one-line :class:`fracas.errors.OutputPathError`
    if it cannot be written: empty or ``.``, an existing directory (or a name ending in
    ``/``), an existing non-regular file, a folder that is a file, cannot be created or is
    not writable, or a file the run reads (one of ``inputs``, or one noted by a reader:
    :func:`check_not_input`).  Creates nothing.  ``what`` names the output in the message
    ("results file", "plot", ...)."""
    text = os.fspath(path)
    if isinstance(text, bytes):
        text = os.fsdecode(text)
    shown = path_text(text)
    if text.strip() in ("", ".", ".."):
        raise OutputPathError(f"{what}: output path {shown!r} is not a file name, expected e.g. out/{_example(what)}")
    if "\0" in text:
        raise OutputPathError(
            f"{shown}: {what} is not a usable path (a NUL character in the name); expected a plain file name",
            reason="is not a usable path (a NUL character in the name)",
        )
    dest = Path(text).expanduser()
    try:
        return _check_output_path(text, dest, shown, what, inputs)
    except OSError as exc:  # a name no file system takes (too long, NUL): stat itself fails
        why = exc.strerror or type(exc).__name__
        raise OutputPathError(
            f"{shown}: {what} is not a usable path ({why}); expected a shorter or plainer file name",
            reason=f"is not a usable path ({why})",
        ) from None


def _check_output_path(
    text: str, dest: Path, shown: str, what: str, inputs: Iterable[str | os.PathLike | None]
) -> Path:
    """:func:`check_output_path` past the empty-name check (may raise OSError from stat)."""
    if text.endswith(("/", os.sep)) or dest.is_dir():
        raise OutputPathError(
            f"{shown}: {what} is a directory, expected a file name inside it",
            reason=f"is a directory ({shown}); expected a file name",
        )
    if dest.exists() and not dest.is_file():
        raise OutputPathError(
            f"{shown}: {what} exists and is not a regular file", reason=f"exists and is not a regular file ({shown})"
        )
    check_not_input(dest, what, inputs)
    folder = dest.parent
    probe = folder
    while not probe.exists():  # the nearest existing ancestor decides whether mkdir can work
        if probe.parent == probe:
            break
        probe = probe.parent
    shown_probe, shown_folder = path_text(probe), path_text(folder)
    if not probe.is_dir():
        raise OutputPathError(
            f"{shown}: {what}: folder {shown_probe} is a file, expected a directory",
            reason=f"cannot create its folder: {shown_probe} is a file",
        )
    if not os.access(probe, os.W_OK | os.X_OK):
        why = f"cannot write there: {shown_probe} is not writable"
        if probe == folder:
            raise OutputPathError(f"{shown}: {what}: folder {shown_folder} is not writable", reason=why)
        raise OutputPathError(
            f"{shown}: {what}: cannot create folder {shown_folder} ({shown_probe} is not writable)", reason=why
        )
    return dest


def _example(what: str) -> str:
    return "plot.png" if "plot" in what else "out.h5"
