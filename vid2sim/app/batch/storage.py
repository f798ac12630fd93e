"""Where a batch reads and writes: local (or shared POSIX) paths and fsspec URLs.

A location is a :class:`~pathlib.Path` for anything on a mounted file system (plain paths and
``file://`` URLs: NFS, Lustre, CephFS and the like, where a rename is atomic) or a ``str``
URL for every other fsspec protocol (``s3://``, ``gs://``, ``memory://``, ...), where the
bytes go through fsspec. Local locations take the fast path (``os``/``pathlib`` and the
atomic writers of :mod:`vid2sim.base.fileio`); only URLs touch fsspec, which is imported here at
module level because it is a core dependency (small, pure Python).

Object stores have no rename: a URL row folder is uploaded file by file with
``scenario.json`` last, and it counts as built only once the batch index records it (see
:mod:`vid2sim.app.batch.worker`).
"""

from __future__ import annotations

import hashlib
import posixpath
import shutil
from pathlib import Path

import fsspec

from vid2sim.base.errors import FormatError, InputError, MissingInputError
from vid2sim.base.fileio import read_input_text, sha256_path, write_bytes_atomic

Where = Path | str
"""A location: a local path, or an fsspec URL (``s3://bucket/key``)."""

#: Files uploaded last into an object-store row folder, in this order: a reader that finds
#: ``scenario.json`` finds every other output of the row already there.
COMMIT_LAST = ("report.html", "scenario.json")
#: Bytes read per chunk when hashing through fsspec (1 MiB: the sha256 loop's cost dominates
#: above ~64 KiB; measured with ``python -m timeit`` on the demo video).
HASH_CHUNK_BYTES = 1 << 20


def is_url(text: str | Path) -> bool:
    """True for a URL other than ``file://`` (those are local paths)."""
    return isinstance(text, str) and "://" in text and not text.startswith("file://")


def location(text: str | Path) -> Where:
    """``text`` as a location: a :class:`Path` for local paths and ``file://`` URLs, else the
    URL string (without a trailing slash)."""
    if isinstance(text, Path):
        return text
    text = str(text).strip()
    if text.startswith("file://"):
        return Path(fsspec.core.url_to_fs(text)[1])
    if is_url(text):
        return text.rstrip("/")
    return Path(text).expanduser()


def join(base: Where, *parts: str) -> Where:
    """``base/part/...`` for a path or a URL."""
    if isinstance(base, Path):
        return base.joinpath(*parts)
    return posixpath.join(base, *parts)


def parent(where: Where) -> Where:
    """The folder holding ``where``."""
    if isinstance(where, Path):
        return where.parent
    protocol, _, rest = where.partition("://")
    return f"{protocol}://{posixpath.dirname(rest)}"


def name(where: Where) -> str:
    """The last component of a path or URL."""
    return where.name if isinstance(where, Path) else posixpath.basename(where)


def _fs(url: str):
    try:
        return fsspec.core.url_to_fs(url)
    except (ImportError, ValueError) as exc:
        raise InputError(url, f"cannot open this URL: {exc}",
                         "install the fsspec back end for its protocol, e.g. s3fs or gcsfs"
                         ) from None


def exists(where: Where) -> bool:
    if isinstance(where, Path):
        return where.exists()
    fs, path = _fs(where)
    return fs.exists(path)


def is_file(where: Where) -> bool:
    if isinstance(where, Path):
        return where.is_file()
    fs, path = _fs(where)
    return fs.isfile(path)


def is_dir(where: Where) -> bool:
    if isinstance(where, Path):
        return where.is_dir()
    fs, path = _fs(where)
    return fs.isdir(path)


def read_text(where: Where) -> str:
    """Text of an input file (UTF-8, BOM dropped); missing or unreadable: :class:`InputError`."""
    if isinstance(where, Path):
        return read_input_text(where)
    fs, path = _fs(where)
    try:
        data = fs.cat_file(path)
    except FileNotFoundError:
        raise MissingInputError(where, "no such file") from None
    except OSError as exc:
        raise MissingInputError(where, f"cannot read: {exc}") from None
    try:
        return data.decode("utf-8").lstrip("\ufeff")
    except UnicodeDecodeError as exc:
        raise FormatError(where, f"not UTF-8 text (byte {exc.start})") from None


def read_bytes(where: Where) -> bytes:
    if isinstance(where, Path):
        return where.read_bytes()
    fs, path = _fs(where)
    return fs.cat_file(path)


def write_bytes(where: Where, data: bytes) -> None:
    """Write ``data`` whole or not at all: a temporary file renamed into place locally, one
    object PUT (atomic on object stores) for a URL."""
    if isinstance(where, Path):
        write_bytes_atomic(where, data)
        return
    fs, path = _fs(where)
    fs.makedirs(posixpath.dirname(path), exist_ok=True)
    fs.pipe_file(path, data)


def listdir(where: Where) -> list[str]:
    """Names in a folder ([] when it does not exist)."""
    if isinstance(where, Path):
        try:
            return sorted(p.name for p in where.iterdir())
        except (FileNotFoundError, NotADirectoryError):
            return []
    fs, path = _fs(where)
    try:
        return sorted(posixpath.basename(p.rstrip("/")) for p in fs.ls(path, detail=False))
    except FileNotFoundError:
        return []


def remove(where: Where) -> None:
    """Delete a file or a folder tree (nothing when absent)."""
    if isinstance(where, Path):
        if where.is_dir() and not where.is_symlink():
            shutil.rmtree(where, ignore_errors=True)
        else:
            where.unlink(missing_ok=True)
        return
    fs, path = _fs(where)
    if fs.exists(path):
        fs.rm(path, recursive=True)


# --------------------------------------------------------------------------- hashing, stat


def stat_key(where: Where) -> tuple[int, str]:
    """(size in bytes, modification stamp) of a file or folder, read without its contents.

    A folder's size is the sum of its files' and its stamp counts the files and takes the
    newest one (a folder's own mtime does not change when a file in it is rewritten).
    Object stores give their ``LastModified``-like time through fsspec.
    """
    if isinstance(where, Path):
        st = where.stat()
        if not where.is_dir():
            return st.st_size, str(st.st_mtime_ns)
        size, newest, count = 0, 0, 0
        for child in where.rglob("*"):
            if child.is_file():
                cst = child.stat()
                size, newest, count = size + cst.st_size, max(newest, cst.st_mtime_ns), count + 1
        return size, f"{count}:{newest}"
    fs, path = _fs(where)
    if fs.isdir(path):
        files = fs.find(path, detail=True)
        stamps = [str(_modified(fs, p, info)) for p, info in sorted(files.items())]
        return sum(int(i.get("size") or 0) for i in files.values()), \
            f"{len(files)}:{max(stamps, default='')}"
    info = fs.info(path)
    return int(info.get("size") or 0), str(_modified(fs, path, info))


def _modified(fs, path: str, info: dict) -> str:
    for key in ("ETag", "etag", "md5Hash", "LastModified", "updated", "mtime", "created"):
        if info.get(key):
            return f"{key}={info[key]}"
    try:
        return fs.modified(path).isoformat()
    except (NotImplementedError, OSError, AttributeError):
        return ""


def sha256_of(where: Where) -> str:
    """sha256 of a file or folder, as :func:`vid2sim.base.fileio.sha256_path` computes it (a
    folder: its files' relative names and hashes in sorted order), streamed through fsspec
    for a URL so that no local copy is needed."""
    if isinstance(where, Path):
        return sha256_path(where)
    fs, path = _fs(where)
    if not fs.isdir(path):
        return _sha256_stream(fs, path)
    digest = hashlib.sha256()
    root = path.rstrip("/") + "/"
    for child in sorted(fs.find(path)):
        digest.update(child[len(root):].encode())
        digest.update(_sha256_stream(fs, child).encode())
    return digest.hexdigest()


def _sha256_stream(fs, path: str) -> str:
    digest = hashlib.sha256()
    with fs.open(path, "rb") as fh:
        while chunk := fh.read(HASH_CHUNK_BYTES):
            digest.update(chunk)
    return digest.hexdigest()


# --------------------------------------------------------------------------- copies (workers)


def download(url: str, folder: Path) -> Path:
    """Copy a URL input (file or folder) into ``folder`` under its own name; the local path.

    Only workers call this, for the row they build: the batch driver never copies inputs.
    """
    fs, path = _fs(url)
    target = folder / posixpath.basename(path.rstrip("/"))
    if fs.isdir(path):
        fs.get(path.rstrip("/") + "/", str(target), recursive=True)
    else:
        fs.get_file(path, str(target))
    return target


def upload_folder(local: Path, url: str) -> None:
    """Replace the object-store folder ``url`` by the files of ``local``.

    The old objects go first, then every file, :data:`COMMIT_LAST` last, so a row folder
    that holds ``scenario.json`` holds the whole build (a kill mid-upload leaves no
    ``scenario.json``, and the retry deletes the rest).
    """
    fs, path = _fs(url)
    if fs.exists(path):
        fs.rm(path, recursive=True)
    files = sorted((p for p in local.rglob("*") if p.is_file()),
                   key=lambda p: (COMMIT_LAST.index(p.name) + 1
                                  if p.parent == local and p.name in COMMIT_LAST else 0,
                                  str(p)))
    for file in files:
        target = posixpath.join(path, file.relative_to(local).as_posix())
        fs.makedirs(posixpath.dirname(target), exist_ok=True)
        fs.put_file(str(file), target)


def host_path(where: Where) -> str:
    """The location as text for the index and messages (a URL as given, a path absolute)."""
    return str(where.absolute()) if isinstance(where, Path) else where


def makedirs(where: Where) -> None:
    if isinstance(where, Path):
        where.mkdir(parents=True, exist_ok=True)
        return
    fs, path = _fs(where)
    fs.makedirs(path, exist_ok=True)

