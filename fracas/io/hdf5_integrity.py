"""The integrity header of fracas's HDF5 files and the checks made before h5py opens one.

**Integrity header.**  Every file :func:`fracas.io.hdf5.atomic_h5` writes starts with a
512-byte HDF5 user block (the HDF5 data proper begins at byte 512; HDF5 never reads or
writes the user block).  After h5py has closed the temporary file and before the rename,
:func:`seal` writes into it a small ASCII header (``docs/hdf5_integrity.md``)::

    fracas-hdf5-integrity 1
    kind <file_kind>            the file's kind tag (file_kind / format / kind attribute)
    length <bytes>              the length of the whole file
    sha256 <64 hex digits>      SHA-256 of every byte after the user block (512 .. end)
    header_sha256 <64 hex>      SHA-256 of the four lines above

padded with NUL bytes.  Every reader first calls :func:`verify_file` (or :func:`open_h5`),
which reads that header with plain Python I/O and checks the length and the hash *before
h5py ever opens the file*: the HDF5 library is handed only bytes fracas wrote, so a
flipped bit or a zeroed block cannot reach its decoder (where some damage makes it loop
forever inside an attribute read, or crash).  A damaged file is refused in one line.

Files without the header (written by fracas before the header existed, or by other
programs) are still read, but only after a bounded probe: a child process (a fresh Python,
so a hang or a crash of the HDF5 library cannot take fracas with it) opens the file and
reads every attribute and every dataset; it is killed after ``FRACAS_HDF5_PROBE_S`` seconds
(default 30) and the file refused in one line.  Why a probe rather than refusing such files
outright: earlier STM files take minutes to rebuild and are intact as a rule, and files
written by hand (tests, other tools) stay readable; the probe costs ~0.3-1 s per file and
bounds the decode all the same (a sealed file is decoded only if its hash holds, an
unsealed one only if a disposable process decoded all of it in time).  A file whose check
passed is not checked again in the same process while its inode, size, mtime and ctime are
unchanged (kept only for files whose ctime is 2 s older than the check, so that a later
change always shows in the ctime).  A file changed in place after fracas wrote it
(``h5py.File(path, "r+")``, a bit flip) no longer matches its hash and is refused; fracas
itself never opens its files for writing in place.

Everything here is re-exported by :mod:`fracas.io.hdf5`.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
import stat
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import BinaryIO

import h5py

from fracas.errors import FracasError, ResultsFileError

USERBLOCK_SIZE = 512  # bytes reserved at the head of every file for the integrity header
MAGIC = b"fracas-hdf5-integrity 1\n"
HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
PROBE_ENV = "FRACAS_HDF5_PROBE_S"
PROBE_DEFAULT_S = 30.0
_CHUNK = 1 << 20

ErrorType = Callable[[str], Exception]


# --------------------------------------------------------------------------- integrity header


def _header_lines(kind: str, length: int, sha: str) -> bytes:
    return f"kind {kind}\nlength {length}\nsha256 {sha}\n".encode("ascii", "backslashreplace")


def _digest_tail(fh: BinaryIO, length: int) -> str:
    """SHA-256 of bytes USERBLOCK_SIZE .. length of an open binary file (read in 1 MiB pieces)."""
    h = hashlib.sha256()
    fh.seek(USERBLOCK_SIZE)
    left = length - USERBLOCK_SIZE
    while left > 0:
        piece = fh.read(min(_CHUNK, left))
        if not piece:
            break
        h.update(piece)
        left -= len(piece)
    return h.hexdigest()


def seal(path: str | os.PathLike, kind: str = "") -> str:
    """Write the integrity header into the user block of a closed HDF5 file (made with
    ``userblock_size=USERBLOCK_SIZE``): kind tag, length, SHA-256 of bytes 512..end and the
    header's own SHA-256.  Returns the data SHA-256 (hex).  Also re-seals a file changed on
    purpose (tests that build damaged-but-consistent files)."""
    p = Path(path)
    kind = re.sub(r"[^\x20-\x7e]", "?", kind)[:100]  # printable ASCII, spaces kept
    with open(p, "r+b") as fh:
        length = os.fstat(fh.fileno()).st_size
        fh.seek(USERBLOCK_SIZE)
        if length < USERBLOCK_SIZE + 8 or fh.read(8) != HDF5_SIGNATURE:
            raise ValueError(f"{p}: no HDF5 superblock at byte {USERBLOCK_SIZE}: not written with the user block")
        sha = _digest_tail(fh, length)
        body = _header_lines(kind, length, sha)
        head = MAGIC + body + f"header_sha256 {hashlib.sha256(MAGIC + body).hexdigest()}\n".encode()
        assert len(head) <= USERBLOCK_SIZE
        fh.seek(0)
        fh.write(head.ljust(USERBLOCK_SIZE, b"\0"))
        fh.flush()
        os.fsync(fh.fileno())
    _VERIFIED.clear()
    return sha


class _Newer(str):
    """Why a header is refused that is not damaged: a later version of it (a newer fracas)."""


_VERSION_RE = re.compile(rb"fracas-hdf5-integrity ([0-9]{1,9})\n")


def _parse_header(block: bytes) -> tuple[str, int, str] | str:
    """(kind, length, sha256) from a user block, or why it is not a valid header (a
    :class:`_Newer` when it is a later version's header, written by a newer fracas)."""
    version = _VERSION_RE.match(block)
    if version is not None and int(version.group(1)) > 1:
        return _Newer(
            f"integrity header version {int(version.group(1))}: written by a newer fracas (this one reads "
            "version 1); read it with that version of fracas or a later one"
        )
    text = block.rstrip(b"\0")
    if b"\0" in text:
        return "NUL bytes inside the integrity header"
    lines = text.split(b"\n")
    if len(lines) != 6 or lines[-1] != b"" or lines[0] + b"\n" != MAGIC:
        return "integrity header garbled"
    body = b"\n".join(lines[1:4]) + b"\n"
    m = re.fullmatch(rb"header_sha256 ([0-9a-f]{64})", lines[4])
    if m is None or hashlib.sha256(MAGIC + body).hexdigest().encode() != m.group(1):
        return "integrity header does not match its own checksum"
    kind = re.fullmatch(rb"kind ([\x20-\x7e]*)", lines[1])
    length = re.fullmatch(rb"length ([0-9]{1,18})", lines[2])
    sha = re.fullmatch(rb"sha256 ([0-9a-f]{64})", lines[3])
    if kind is None or length is None or sha is None:
        return "integrity header fields garbled"
    return kind.group(1).decode(), int(length.group(1)), sha.group(1).decode()


# files checked in this process: resolved path -> (stat key, how, kind tag); how is "sealed"
# (hash verified), "legacy" (no header, probed) or "probed" (header or hash wrong, probed).
# Only files whose status last changed _SETTLED_NS before the check are kept: any change after
# it then gets a later ctime (timestamps can be coarse, a few ms), so the stat key sees it.
_SETTLED_NS = 2_000_000_000
_VERIFIED: dict[str, tuple[tuple[int, ...], str, str]] = {}
_VERIFIED_LOCK = threading.Lock()


def _stat_key(st: os.stat_result) -> tuple[int, ...]:
    return (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns)


def _signature_at(fh: BinaryIO, size: int) -> int | None:
    """Offset of the HDF5 superblock signature (0, 512, 1024, 2048, ... as HDF5 searches)."""
    off = 0
    while off + 8 <= size:
        fh.seek(off)
        if fh.read(8) == HDF5_SIGNATURE:
            return off
        off = 512 if off == 0 else 2 * off
    return None


def probe_timeout_s() -> float:
    """Seconds a child process gets to decode a file without the integrity header
    (``FRACAS_HDF5_PROBE_S``, default 30)."""
    raw = os.environ.get(PROBE_ENV, "")
    try:
        val = float(raw) if raw.strip() else PROBE_DEFAULT_S
    except ValueError:
        val = PROBE_DEFAULT_S
    return val if val > 0 else PROBE_DEFAULT_S


_PROBE = r"""
import sys
sys.path.insert(0, sys.argv[2])
import h5py
def attrs(o):
    for k in list(o.attrs.keys()):
        o.attrs[k]
def visit(name, o):
    attrs(o)
    if isinstance(o, h5py.Dataset):
        o[()]
try:
    with h5py.File(sys.argv[1], "r") as f:
        attrs(f)
        f.visititems(visit)
except Exception as exc:
    sys.stderr.write(type(exc).__name__ + ": " + " ".join(str(exc).split()) + "\n")
    sys.exit(3)
"""


def _probe(p: Path, timeout: float) -> str | None:
    """Why a child process could not decode every attribute and dataset of ``p`` within
    ``timeout`` seconds, or None when it could."""
    # -I: no user site, no PYTHONPATH, no current folder; the same h5py as this process
    cmd = [sys.executable, "-I", "-c", _PROBE, os.fspath(p), str(Path(h5py.__file__).parent.parent)]
    try:
        r = subprocess.run(cmd, stdin=subprocess.DEVNULL, capture_output=True, timeout=timeout, check=False)
    except subprocess.TimeoutExpired:
        return (
            f"no integrity header (written before fracas sealed its files, or not by fracas) and "
            f"decoding it did not finish within {timeout:g} s (damaged? the limit is {PROBE_ENV}): rebuild it"
        )
    except OSError as exc:
        return f"cannot start the process that checks files without an integrity header: {one_line(exc)}"
    if r.returncode == 0:
        return None
    err = [ln for ln in r.stderr.decode("utf-8", "replace").splitlines() if ln.strip()]
    why = err[-1].strip() if err else ""
    if r.returncode < 0:
        why = f"the HDF5 library crashed (signal {-r.returncode})"
    return f"unreadable HDF5 file (damaged or truncated?): {why or f'exit status {r.returncode}'}"


# C901 on purpose: the integrity checks in the order a damaged file must be refused (stat, header, size, checksum)
def _check(p: Path, what: str, checksum: bool = True) -> tuple[str | None, str]:  # noqa: C901
    """(why ``p`` is refused or None, kind tag from its integrity header or "")."""
    try:
        st = os.stat(p)
    except FileNotFoundError:
        return f"no such {what or 'file'}", ""
    except OSError as exc:
        return f"cannot read: {exc.strerror or one_line(exc)}", ""
    if stat.S_ISDIR(st.st_mode):
        return f"is a directory, expected a {what or 'file'} (HDF5)", ""
    if not stat.S_ISREG(st.st_mode):
        return f"not a regular file, expected a {what or 'file'} (HDF5)", ""
    started_ns = time.time_ns()
    key = str(p.resolve())
    with _VERIFIED_LOCK:
        hit = _VERIFIED.get(key)
    if hit is not None and hit[0] == _stat_key(st) and (hit[1] != "probed" or not checksum):
        return None, hit[2]
    how, kind, damage = "legacy", "", ""
    try:
        with open(p, "rb") as fh:
            st = os.fstat(fh.fileno())
            size = st.st_size
            block = fh.read(USERBLOCK_SIZE)
            if (
                block.startswith(MAGIC)
                or _VERSION_RE.match(block)
                or (block[:8] != HDF5_SIGNATURE and _signature_at(fh, size) == USERBLOCK_SIZE)
            ):
                parsed = _parse_header(block)
                if isinstance(parsed, _Newer):
                    damage = str(parsed)
                elif isinstance(parsed, str):
                    damage = f"damaged file: {parsed} (the file was changed after fracas wrote it)"
                else:
                    kind, length, sha = parsed
                    got = _digest_tail(fh, size) if size == length else ""
                    if size != length:
                        how_ = "truncated" if size < length else "extended"
                        damage = (
                            f"damaged file: {size} bytes, its integrity header says {length} "
                            f"({how_} after fracas wrote it)"
                        )
                    elif got != sha:
                        damage = (
                            f"damaged file: checksum mismatch (expected SHA-256 {sha[:16]}..., got {got[:16]}...: "
                            "the file was changed after fracas wrote it)"
                        )
                how = "probed" if damage else "sealed"
            elif _signature_at(fh, size) is None:
                return "not an HDF5 file (no HDF5 signature; damaged?)" + (f", expected a {what}" if what else ""), ""
    except OSError as exc:
        return f"cannot read: {exc.strerror or one_line(exc)}", ""
    if damage and checksum:
        return damage, ""
    if how != "sealed":
        why = _probe(p, probe_timeout_s())
        if why is not None:
            return (f"{damage}; {why}" if damage else why), ""
    if st.st_ctime_ns < started_ns - _SETTLED_NS:  # a later change gets a new ctime: the key tells
        with _VERIFIED_LOCK:
            _VERIFIED[key] = (_stat_key(st), how, kind)
    return None, kind


def file_problem(path: str | os.PathLike, what: str = "") -> str | None:
    """Why ``path`` cannot be decoded safely (one line, without the path; ``what``: the kind
    of file expected, named in some reasons), or None.  See :func:`verify_file`."""
    return _check(Path(path), what)[0]


def verify_file(
    path: str | os.PathLike,
    error: ErrorType = ResultsFileError,
    what: str = "fracas HDF5 file",
    *,
    checksum: bool = True,
) -> str:
    """Check a file before h5py opens it; return the kind tag of its integrity header ("" for
    a file without one).

    Refuses with ``error(f"{path}: {why}")``, one line: a missing file, a directory or other
    non-regular file (a FIFO would block), a sealed file whose length or SHA-256 differs
    from its header's (or whose header is damaged), a file with no HDF5 signature, and a
    file without the header that a child process could not decode completely within
    :func:`probe_timeout_s` seconds.  ``checksum=False`` (the readers' ``verify=False``)
    decodes a sealed file that fails its hash like one without a header, through the
    bounded probe, instead of refusing it.  Bounded either way: the header path reads the
    file once with plain Python I/O; the probe is killed at its time limit.
    """
    p = Path(path)
    why, kind = _check(p, what, checksum)
    if why is not None:
        raise error(f"{p}: {why}")
    return kind


@contextlib.contextmanager
def open_h5(
    path: str | os.PathLike,
    error: ErrorType = ResultsFileError,
    what: str = "fracas HDF5 file",
    *,
    checksum: bool = True,
) -> Iterator[h5py.File]:
    """``with open_h5(path, Error, "TEAM results file") as f:`` -- :func:`verify_file`, then
    ``h5py.File(path, "r")``.  Any error of the HDF5 library or of a missing item while the
    block runs (OSError, KeyError, ValueError, TypeError, IndexError, RuntimeError) becomes
    one line ``error(f"{path}: unreadable or incomplete {what}: ...")``; a FracasError
    raised in the block passes through unchanged."""
    p = Path(path)
    verify_file(p, error, what, checksum=checksum)
    with _opened(p, error, what) as f:
        yield f


@contextlib.contextmanager
def _opened(p: Path, error: ErrorType, what: str) -> Iterator[h5py.File]:
    """h5py.File(p, "r") of a file :func:`verify_file` passed, errors as in :func:`open_h5`."""
    try:
        f = h5py.File(p, "r")
    except (OSError, ValueError, RuntimeError) as exc:
        raise error(f"{p}: unreadable HDF5 file (damaged or truncated?): {one_line(exc)}") from None
    with h5_errors(p, error, what), f:
        yield f


@contextlib.contextmanager
def h5_errors(p: Path, error: ErrorType, what: str) -> Iterator[None]:
    """``with h5_errors(path, Error, "STM file"):`` -- an error of the HDF5 library or of a
    missing item while reading an open file (KeyError, OSError, ValueError, TypeError,
    IndexError, RuntimeError, AttributeError) becomes one line ``error(f"{path}: incomplete
    {what}: ...")``; a FracasError passes through unchanged."""
    try:
        yield
    except FracasError:
        raise
    except KeyError as exc:
        raise error(f"{p}: incomplete {what}: {one_line(exc)} is missing") from None
    except (OSError, ValueError, TypeError, IndexError, RuntimeError, AttributeError) as exc:
        raise error(f"{p}: unreadable or incomplete {what}: {type(exc).__name__}: {one_line(exc)}") from None


def one_line(exc: BaseException | str) -> str:
    """An exception's message on one line (the HDF5 library's span several)."""
    text = exc if isinstance(exc, str) else str(exc)
    return " ".join(text.split())
