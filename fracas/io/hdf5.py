"""HDF5 helpers shared by every fracas file: atomic writes sealed by an integrity header,
labelled and checksummed datasets, checked reading, provenance.

Writes are atomic (:mod:`fracas.io.atomic`): the file is built under a temporary name
``.<name>.<pid>-<host>.<random>.tmp`` in the destination directory, flushed and ``fsync``-ed, given
the user's normal permissions, then moved over the destination with ``os.replace``.  A
failure or a kill at any point leaves a previous file at the destination untouched.

**Integrity header.**  Every file :func:`atomic_h5` writes starts with a 512-byte HDF5 user
block (the HDF5 data proper begins at byte 512; HDF5 never reads or writes the user block).
After h5py has closed the temporary file and before the rename, :func:`seal` writes into it
a small ASCII header (``docs/hdf5_integrity.md``)::

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

Every dataset written by :func:`write` / :func:`write_strings` also carries ``data_sha256``, the
SHA-256 of its bytes (:func:`digest_array`, :func:`digest_strings`); :class:`Checked` reads
datasets back verifying dtype, shape, finiteness and that checksum (this names the damaged
dataset in files without the integrity header).
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import functools
import hashlib
import os
import platform
import re
import stat
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from importlib import metadata
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from fracas.errors import FracasError, ResultsFileError
from fracas.io.atomic import atomic_path

STR = h5py.string_dtype(encoding="utf-8")
LIBRARIES = ("numpy", "scipy", "jax", "jaxlib", "h5py", "pydantic", "click", "rich", "matplotlib", "jplephem", "de421")

USERBLOCK_SIZE = 512  # bytes reserved at the head of every file for the integrity header
MAGIC = b"fracas-hdf5-integrity 1\n"
HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
PROBE_ENV = "FRACAS_HDF5_PROBE_S"
PROBE_DEFAULT_S = 30.0
_KIND_ATTRS = ("file_kind", "format", "kind")
_CHUNK = 1 << 20

ErrorType = Callable[[str], Exception]


@contextlib.contextmanager
def atomic_h5(path: str | os.PathLike) -> Iterator[h5py.File]:
    """``with atomic_h5(path) as f:`` -- write an HDF5 file that appears complete or not at all,
    sealed by the integrity header (:func:`seal`).

    Built on :func:`fracas.io.atomic.atomic_path`: the parent directory is created if
    needed, the file gets the user's normal permissions; on any exception inside the block
    (or while closing/flushing/sealing) the temporary file is removed and the exception
    propagates.  The header's kind tag is the root attribute ``file_kind`` (or ``format``,
    ``kind``) as the block left it.
    """
    with atomic_path(path) as tmp:
        with h5py.File(tmp, "w", userblock_size=USERBLOCK_SIZE) as f:
            yield f
            kind = kind_attr(f)
        seal(tmp, kind)


def kind_attr(f: h5py.File) -> str:
    """The kind tag of an open file: its ``file_kind``, ``format`` or ``kind`` root attribute ("" if none)."""
    for key in _KIND_ATTRS:
        val = attr_text(f, key)
        if val:
            return val
    return ""


# --------------------------------------------------------------------------- integrity header


def _header_lines(kind: str, length: int, sha: str) -> bytes:
    return f"kind {kind}\nlength {length}\nsha256 {sha}\n".encode("ascii", "backslashreplace")


def _digest_tail(fh, length: int) -> str:
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


def _parse_header(block: bytes) -> tuple[str, int, str] | str:
    """(kind, length, sha256) from a user block, or why it is not a valid header."""
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


def _signature_at(fh, size: int) -> int | None:
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


def _check(p: Path, what: str, checksum: bool = True) -> tuple[str | None, str]:
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
            if block.startswith(MAGIC) or (block[:8] != HDF5_SIGNATURE and _signature_at(fh, size) == USERBLOCK_SIZE):
                parsed = _parse_header(block)
                if isinstance(parsed, str):
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
    try:
        with f:
            yield f
    except FracasError:
        raise
    except KeyError as exc:
        raise error(f"{p}: incomplete {what}: {one_line(exc)} is missing") from None
    except (OSError, ValueError, TypeError, IndexError, RuntimeError, AttributeError) as exc:
        raise error(f"{p}: unreadable or incomplete {what}: {type(exc).__name__}: {one_line(exc)}") from None


def read_kind(path: str | os.PathLike, error: ErrorType = ResultsFileError, what: str = "results file") -> str:
    """The kind of a fracas file (its ``file_kind``, ``format`` or ``kind`` root attribute),
    read from the integrity header when the file has one, else from the attributes after
    :func:`verify_file`'s probe; "" when it names none."""
    tag = verify_file(path, error, what)
    if tag:
        return tag
    with _opened(Path(path), error, what) as f:
        return kind_attr(f)


def one_line(exc: BaseException | str) -> str:
    """An exception's message on one line (the HDF5 library's span several)."""
    text = exc if isinstance(exc, str) else str(exc)
    return " ".join(text.split())


# --------------------------------------------------------------------------- checksums

CHECKSUM_ATTR = "data_sha256"


def digest_array(arr: Any) -> str:
    """SHA-256 (hex) of a numeric array's bytes: C order, little-endian, its own dtype."""
    a = np.asarray(arr)
    a = np.ascontiguousarray(a, dtype=a.dtype.newbyteorder("<"))
    return hashlib.sha256(a.tobytes()).hexdigest()


def digest_strings(values: Any) -> str:
    """SHA-256 (hex) of a string dataset: its values in UTF-8, each followed by a NUL byte."""
    vals = [values] if isinstance(values, str) else [str(v) for v in values]
    return hashlib.sha256(b"".join(v.encode("utf-8") + b"\0" for v in vals)).hexdigest()


def write_strings(group: h5py.Group, name: str, values, units: str = "none", **attrs: Any) -> h5py.Dataset:
    """A 1-D UTF-8 string dataset (empty lists included) with a ``units`` attribute."""
    vals = [str(v) for v in values]
    if vals:
        ds = group.create_dataset(name, data=np.array(vals, dtype=object), dtype=STR)
    else:
        ds = group.create_dataset(name, shape=(0,), dtype=STR)
    ds.attrs["units"] = units
    ds.attrs[CHECKSUM_ATTR] = digest_strings(vals)
    for key, val in attrs.items():
        set_attr(ds, key, val)
    return ds


def write(group: h5py.Group, name: str, data: Any, units: str, **attrs: Any) -> h5py.Dataset:
    """Create dataset ``name`` with a ``units`` attribute (``"1"``: dimensionless,
    ``"none"``: text or labels) and any further attributes."""
    if isinstance(data, str):
        ds = group.create_dataset(name, data=data, dtype=STR)
        ds.attrs[CHECKSUM_ATTR] = digest_strings(data)
    elif isinstance(data, (list, tuple)) and data and all(isinstance(x, str) for x in data):
        return write_strings(group, name, data, units, **attrs)
    else:
        arr = np.asarray(data)
        ds = group.create_dataset(name, data=arr)
        ds.attrs[CHECKSUM_ATTR] = digest_array(arr)
    ds.attrs["units"] = units
    for key, val in attrs.items():
        set_attr(ds, key, val)
    return ds


def set_attr(obj: h5py.HLObject, key: str, val: Any) -> None:
    """Attribute with lists of strings stored as UTF-8 string arrays."""
    if isinstance(val, (list, tuple)) and all(isinstance(x, str) for x in val):
        obj.attrs.create(key, np.array(val, dtype=object), dtype=STR)
    else:
        obj.attrs[key] = val


def read_str(ds: h5py.Dataset) -> str | list[str]:
    """A string dataset as ``str`` (scalar) or ``list[str]``."""
    val = ds.asstr()[()]
    return val if isinstance(val, str) else [str(x) for x in np.asarray(val).ravel()]


def attr_strs(obj: h5py.HLObject, key: str) -> list[str]:
    val = obj.attrs[key]
    return [v.decode() if isinstance(v, bytes) else str(v) for v in np.atleast_1d(val)]


def library_versions() -> dict[str, str]:
    """Versions of Python and the libraries the files depend on (a fresh copy; looked up once
    per process: the package metadata scan costs 20-40 ms, paid by every sweep study)."""
    return dict(_library_versions())


@functools.cache
def _library_versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for name in LIBRARIES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            continue
    return out


def provenance(deck_text: str | None, deck_path: str | None = None) -> dict[str, Any]:
    """What made a file: fracas version, UTC time, command line, deck text and its SHA-256,
    library versions, host platform."""
    from fracas import __version__

    text = deck_text or ""
    return {
        "fracas_version": __version__,
        "created_utc": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "command": " ".join(sys.argv),
        "platform": platform.platform(),
        "deck_path": deck_path or "",
        "deck_sha256": hashlib.sha256(text.encode("utf-8")).hexdigest(),
        "deck_text": text,
        "libraries": library_versions(),
    }


def write_provenance(f: h5py.File, prov: dict[str, Any]) -> None:
    """``/provenance``: attributes for the short items, ``deck_text`` dataset, ``libraries`` subgroup attrs."""
    g = f.create_group("provenance")
    for key, val in prov.items():
        if key == "deck_text":
            write(g, "deck_text", val, "none", sha256=prov.get("deck_sha256", ""))
        elif key == "libraries":
            lib = g.create_group("libraries")
            for name, ver in val.items():
                lib.attrs[name] = ver
        else:
            g.attrs[key] = val


def read_provenance(f: h5py.File) -> dict[str, Any]:
    if "provenance" not in f:
        return {}
    g = f["provenance"]
    out: dict[str, Any] = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in g.attrs.items()}
    if "deck_text" in g:
        out["deck_text"] = read_str(g["deck_text"])
    if "libraries" in g:
        out["libraries"] = {k: str(v) for k, v in g["libraries"].attrs.items()}
    return out


# --------------------------------------------------------------------------- checked reading


def dtype_name(dtype: np.dtype) -> str:
    """``float64``, ``int64``, ... or ``strings`` for an HDF5 string dtype."""
    return "strings" if h5py.check_string_dtype(dtype) is not None else str(dtype)


class Checked:
    """Read datasets of an open file, each checked before use; every refusal is one line,
    ``error(f"{src}: {dataset}: {problem}, expected {what}")``.

    ``verify``: compare each dataset's ``data_sha256`` with its bytes (False skips the
    checksums only; dtype, shape and finiteness are always checked); ``require_checksum``:
    a dataset without ``data_sha256`` is refused (files of a schema that writes them).
    """

    def __init__(
        self, f: h5py.File, src: Any, error: type[Exception], *, verify: bool = True, require_checksum: bool = True
    ):
        self.f, self.src, self.error = f, src, error
        self.verify, self.require_checksum = verify, require_checksum

    def fail(self, name: str, problem: str) -> Exception:
        return self.error(f"{self.src}: {name}: {problem}")

    def dataset(self, name: str) -> h5py.Dataset:
        if name not in self.f:
            raise self.fail(name, "missing, expected a dataset (incomplete file?)")
        try:
            obj = self.f[name]
        except (KeyError, ValueError, OSError) as exc:
            raise self.fail(name, f"missing or unreadable ({exc}), expected a dataset") from None
        if not isinstance(obj, h5py.Dataset):
            raise self.fail(name, f"is a {type(obj).__name__}, expected a dataset")
        return obj

    def _shape(self, name: str, got: tuple[int, ...], want: tuple[int | None, ...] | None) -> None:
        if want is None:
            return
        if len(got) != len(want) or any(w is not None and g != w for g, w in zip(got, want)):
            shown = "(" + ", ".join("*" if w is None else str(w) for w in want) + ("," if len(want) == 1 else "") + ")"
            raise self.fail(name, f"shape {got}, expected {shown}")

    def check_digest(
        self, name: str, obj: h5py.HLObject, got: str, attr: str = CHECKSUM_ATTR, index: int | None = None
    ) -> None:
        """Compare ``got`` with ``obj.attrs[attr]`` (or its element ``index``)."""
        if not self.verify:
            return
        if attr not in obj.attrs:
            if self.require_checksum:
                raise self.fail(name, f"no {attr} attribute, expected the SHA-256 checksum every dataset carries")
            return
        stored = obj.attrs[attr]
        if index is not None:
            vals = np.atleast_1d(stored)
            if index >= vals.shape[0]:
                raise self.fail(name, f"{attr} has {vals.shape[0]} entries, expected one per column ({index + 1}+)")
            stored = vals[index]
        stored = stored.decode() if isinstance(stored, bytes) else stored
        if not isinstance(stored, str):
            raise self.fail(name, f"{attr} attribute is {type(stored).__name__}, expected a hex string")
        if stored != got:
            where = f" (column {index})" if index is not None else ""
            raise self.fail(
                name,
                f"SHA-256 checksum mismatch{where}: data {got[:12]}..., stored {stored[:12]}..., expected equal "
                "(the file was damaged or edited after it was written)",
            )

    def num(
        self,
        name: str,
        shape: tuple[int | None, ...] | None = None,
        *,
        integer: bool = False,
        finite: bool = False,
    ) -> np.ndarray:
        """A float64 (or, ``integer``, any integer) dataset of ``shape`` (None: any length)."""
        ds = self.dataset(name)
        if integer:
            if ds.dtype.kind not in "iu":
                raise self.fail(name, f"dtype {dtype_name(ds.dtype)}, expected an integer dtype")
        elif ds.dtype != np.float64:
            raise self.fail(name, f"dtype {dtype_name(ds.dtype)}, expected float64")
        self._shape(name, tuple(ds.shape), shape)
        try:
            val = ds[()]
        except (OSError, ValueError) as exc:
            raise self.fail(name, f"unreadable ({exc}), expected {ds.dtype} data") from None
        self.check_digest(name, ds, digest_array(val))
        if finite and not np.all(np.isfinite(val)):
            bad = np.argwhere(~np.isfinite(np.atleast_1d(val)))[0]
            raise self.fail(name, f"non-finite value at index {tuple(int(i) for i in bad)}, expected finite numbers")
        return val

    def scalar(self, name: str, *, integer: bool = False, finite: bool = True) -> float | int:
        val = self.num(name, (), integer=integer, finite=finite)
        return int(val) if integer else float(val)

    def strs(self, name: str, n: int | None = None) -> list[str]:
        """A 1-D UTF-8 string dataset (``n`` values when given)."""
        ds = self.dataset(name)
        if h5py.check_string_dtype(ds.dtype) is None:
            raise self.fail(name, f"dtype {ds.dtype}, expected UTF-8 strings")
        self._shape(name, tuple(ds.shape), (n,))
        try:
            vals = [str(x) for x in ds.asstr()[()]]
        except (OSError, ValueError) as exc:
            raise self.fail(name, f"unreadable strings ({exc}), expected UTF-8") from None
        self.check_digest(name, ds, digest_strings(vals))
        return vals

    def text(self, name: str) -> str:
        """A scalar UTF-8 string dataset."""
        ds = self.dataset(name)
        if h5py.check_string_dtype(ds.dtype) is None:
            raise self.fail(name, f"dtype {ds.dtype}, expected a UTF-8 string")
        self._shape(name, tuple(ds.shape), ())
        try:
            val = ds.asstr()[()]
        except (OSError, ValueError) as exc:
            raise self.fail(name, f"unreadable string ({exc}), expected UTF-8") from None
        self.check_digest(name, ds, digest_strings(str(val)))
        return str(val)


def attr_int(obj: h5py.HLObject, key: str, error: Exception | None = None) -> int | None:
    """An integer attribute (numpy or Python int, not bool); None if absent, ``error`` if not an integer."""
    if key not in obj.attrs:
        return None
    val = obj.attrs[key]
    if isinstance(val, np.ndarray) and val.shape == ():
        val = val[()]
    if isinstance(val, (bool, np.bool_)) or not isinstance(val, (int, np.integer)):
        if error is not None:
            raise error
        return None
    return int(val)


def attr_text(obj: h5py.HLObject, key: str) -> str | None:
    """A string attribute as ``str``; None if absent or not a string."""
    if key not in obj.attrs:
        return None
    val = obj.attrs[key]
    if isinstance(val, bytes):
        try:
            return val.decode()
        except UnicodeDecodeError:
            return None
    return val if isinstance(val, str) else None
