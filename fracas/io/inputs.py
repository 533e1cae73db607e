"""The files a run reads: bounded reading of a user's file, and the inputs no output may replace.

**Reading.**  :func:`read_bounded` reads a user's text file (a deck, a namelist, an OEM, a
CSV): only a regular file (a FIFO would block forever, ``/dev/zero`` never ends), opened
with ``O_NONBLOCK`` and checked with ``fstat`` before any byte is read, and at most
``limit + 1`` bytes, so a 7 GB file is refused after reading a little more than the limit.
:func:`check_regular` makes the same check for a file a library opens itself.

**Inputs.**  Inside :func:`input_scope` (the command line opens one per command; every
orchestrator opens one, joining the command's), every file a reader opens is noted
(:func:`note_input`: its device and inode, so a symlink or a hard link to it is the same
file), and :func:`input_conflict` says whether an output path is one of them (or of the
``also`` paths a caller names before it reads them: an STM file, a results file to export).
:func:`fracas.io.atomic.check_output_path` refuses such an output before any work, and
:func:`fracas.io.atomic.atomic_path` again before it replaces anything, so a run never
writes its results over its own deck.

**Paths in text.**  :func:`path_text` is a path as printable, encodable text: bytes that
are not UTF-8 (``good\\xff.toml``) and control characters (a newline) written as escapes.
"""

from __future__ import annotations

import contextlib
import errno
import functools
import os
import stat
from collections.abc import Callable, Iterable, Iterator
from typing import ParamSpec, TypeVar

from fracas.errors import FracasError

__all__ = [
    "check_regular",
    "input_conflict",
    "input_scope",
    "note_input",
    "path_text",
    "read_bounded",
    "reading_inputs",
    "same_file",
]

PathLike = str | os.PathLike[str]
P = ParamSpec("P")
R = TypeVar("R")

#: (device, inode) -> the path a reader gave, for each scope open (innermost last)
_SCOPES: list[dict[tuple[int, int], str]] = []


@contextlib.contextmanager
def input_scope() -> Iterator[None]:
    """Note the inputs read inside the block (a scope opened inside another joins it)."""
    if _SCOPES:
        yield
        return
    _SCOPES.append({})
    try:
        yield
    finally:
        _SCOPES.clear()


def reading_inputs(fn: Callable[P, R]) -> Callable[P, R]:
    """``fn`` run inside :func:`input_scope` (an orchestrator: its deck and the files it names
    are noted while it runs, so its output checks see them)."""

    @functools.wraps(fn)
    def run(*args: P.args, **kwargs: P.kwargs) -> R:
        with input_scope():
            return fn(*args, **kwargs)

    return run


def _key(path: PathLike) -> tuple[int, int] | None:
    try:
        st = os.stat(path)
    except (OSError, ValueError):
        return None
    return (st.st_dev, st.st_ino)


def note_input(path: PathLike | None) -> None:
    """Note ``path`` (followed through symlinks) as an input of the current scope, if any."""
    if path is None or not _SCOPES:
        return
    key = _key(path)
    if key is not None:
        _SCOPES[-1].setdefault(key, path_text(path))


def input_conflict(dest: PathLike, also: Iterable[PathLike | None] = ()) -> str | None:
    """The input (as noted, or one of ``also``) that ``dest`` is the same file as, or None."""
    key = _key(dest)
    if key is None:
        return None
    for other in also:
        if other is not None and _key(other) == key:
            return path_text(other)
    return _SCOPES[-1].get(key) if _SCOPES else None


def path_text(path: PathLike | bytes) -> str:
    """``path`` as printable text: undecodable bytes as ``\\xNN``, control characters escaped."""
    raw = os.fsencode(path)
    text = raw.decode("utf-8", errors="backslashreplace")
    if any(ord(c) < 32 or ord(c) == 127 for c in text):
        text = "".join(c.encode("unicode_escape").decode("ascii") if ord(c) < 32 or ord(c) == 127 else c for c in text)
    return text


def _kind_of(mode: int) -> str:
    if stat.S_ISDIR(mode):
        return "a directory"
    if stat.S_ISFIFO(mode):
        return "a FIFO"
    if stat.S_ISCHR(mode):
        return "a character device"
    if stat.S_ISBLK(mode):
        return "a block device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def check_regular(
    path: PathLike, error: type[FracasError], expected: str, source: str | None = None, limit: int | None = None
) -> int:
    """The size of ``path`` if it is a regular file (of at most ``limit`` bytes); otherwise a
    one-line ``error`` naming ``source`` (default: the path) and what was ``expected``.
    Notes it as an input (:func:`note_input`)."""
    src = source if source is not None else path_text(path)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise error(f"{src}: no such file, expected {expected}") from None
    except OSError as exc:
        raise error(f"{src}: cannot read: {exc.strerror or exc}") from None
    return _checked_size(st, path, error, expected, src, limit)


def _checked_size(
    st: os.stat_result, path: PathLike, error: type[FracasError], expected: str, src: str, limit: int | None
) -> int:
    if not stat.S_ISREG(st.st_mode):
        raise error(f"{src}: is {_kind_of(st.st_mode)}, expected {expected}")
    if limit is not None and st.st_size > limit:
        raise error(f"{src}: is {st.st_size} bytes; {expected} is at most {limit} bytes")
    note_input(path)
    return st.st_size


def read_bounded(
    path: PathLike, limit: int, error: type[FracasError], expected: str, source: str | None = None
) -> bytes:
    """The bytes of the regular file ``path``, at most ``limit`` of them; every failure a
    one-line ``error`` naming ``source`` (default: the path): missing, not a regular file (a
    FIFO, a device: checked before reading, without blocking), unreadable, or over the
    limit (by its size, or by reading ``limit + 1`` bytes of a file that grows)."""
    src = source if source is not None else path_text(path)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise error(f"{src}: no such file") from None
    except IsADirectoryError:
        raise error(f"{src}: is a directory, expected {expected}") from None
    except OSError as exc:
        if exc.errno == errno.ENXIO:  # a FIFO or socket with no writer
            raise error(f"{src}: is not a regular file, expected {expected}") from None
        raise error(f"{src}: cannot read: {exc.strerror or exc}") from None
    try:
        _checked_size(os.fstat(fd), path, error, expected, src, limit)
        os.set_blocking(fd, True)
        chunks, got = [], 0
        while got <= limit:
            chunk = os.read(fd, min(1 << 20, limit + 1 - got))
            if not chunk:
                break
            chunks.append(chunk)
            got += len(chunk)
    except OSError as exc:
        raise error(f"{src}: cannot read: {exc.strerror or exc}") from None
    finally:
        os.close(fd)
    if got > limit:
        raise error(f"{src}: is over {limit} bytes; {expected} is at most {limit} bytes")
    return b"".join(chunks)


def same_file(a: PathLike, b: PathLike) -> bool:
    """Whether two paths name one existing file (through symlinks and hard links)."""
    ka = _key(a)
    return ka is not None and ka == _key(b)
