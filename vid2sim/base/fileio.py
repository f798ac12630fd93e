"""Atomic file writing, staged output folders, bounded input reading and hashing.

Outputs appear whole or not at all: a single file is written to a temporary name beside it
and renamed (:func:`atomic_open`); a command's output folder is written into a staging folder
and moved into place when every output is complete (:func:`staged_folder`). Problems of the
output location (read-only, disk full, another filesystem) are the user's to fix: they raise
:class:`~vid2sim.base.errors.InputError` naming the path.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import os
import shutil
import signal
import tempfile
import threading
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import IO, Any

from vid2sim.base.errors import FormatError, InputError, MissingInputError, OutputError

#: errno values that describe the output location, not a bug: no permission, a read-only
#: filesystem, no space or quota left, a file larger than the filesystem or ulimit allows.
OUTPUT_ERRNOS = frozenset({errno.EACCES, errno.EPERM, errno.EROFS, errno.ENOSPC, errno.EDQUOT,
                           errno.EFBIG})

#: Largest text input read whole [bytes] unless a reader sets its own limit: 512 MiB is
#: several hours of any GPS log or detection file this tool reads; beyond it the file is not
#: one drive's (and reading it whole would take gigabytes of memory).
MAX_INPUT_BYTES = 512 * 1024 * 1024

#: Prefix of staging folders: hidden, and named so a user who finds one after a power cut
#: knows what made it.
STAGING_PREFIX = ".vid2sim-staging."


def output_error(path: str | Path, exc: OSError) -> InputError:
    """The user-facing error for an OSError writing ``path`` (see :data:`OUTPUT_ERRNOS`)."""
    what = exc.strerror or str(exc)
    if exc.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG):
        hint = "free some space or write the output elsewhere"
    else:
        hint = "choose a writable output location"
    return OutputError(path, f"cannot write the output: {what}", hint)


@contextlib.contextmanager
def atomic_open(path: str | Path, mode: str = "w", **kwargs) -> Iterator[IO]:
    """Open a temporary file beside ``path``; rename it over ``path`` only if the block succeeds.

    A crash or exception inside the block leaves any existing ``path`` untouched and removes
    the temporary file, so readers never see a half-written output. A symlink at ``path``
    is followed (its target is replaced, the link stays). A read-only location or a full disk
    raises :class:`InputError` naming ``path``.
    """
    # The file is closed (inner context) before the staged path is renamed (outer one).
    with _staged(path, keep_suffix=False) as tmp, open(tmp, mode, **kwargs) as fh:
        yield fh


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary path beside ``path``, with its suffix, for a writer that takes a file name
    (a video encoder); renamed over ``path`` only if the block succeeds (as
    :func:`atomic_open`: a failure leaves any existing ``path`` untouched and removes the
    temporary file; a read-only location or a full disk raises :class:`InputError`)."""
    with _staged(path, keep_suffix=True) as tmp:
        yield tmp


@contextlib.contextmanager
def _staged(path: str | Path, keep_suffix: bool) -> Iterator[Path]:
    """The temporary file of :func:`atomic_open` / :func:`atomic_path`: made beside ``path``
    (``.<name>.XXXX.tmp``, or ``.<stem>.XXXX<suffix>`` when the writer picks its format by
    the suffix) with a user file's permissions, renamed over ``path`` when the block succeeds
    and removed when it fails."""
    path = Path(path)
    if path.is_symlink():
        # Replacing the link itself would turn the user's link into a file; write where it
        # points, beside its target, so the rename stays on the target's filesystem.
        path = path.resolve()
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        prefix, suffix = ((f".{path.stem}.", path.suffix or ".tmp") if keep_suffix
                          else (f".{path.name}.", ".tmp"))
        fd, tmp = tempfile.mkstemp(prefix=prefix, suffix=suffix, dir=path.parent)
        os.close(fd)
        # mkstemp creates the file 0600; an output must get the permissions of any file the
        # user creates (0666 less the umask), or colleagues cannot read a shared build.
        os.chmod(tmp, 0o666 & ~_umask())
        yield Path(tmp)
        os.replace(tmp, path)
    except OSError as exc:
        _remove_quietly(tmp)
        if exc.errno in OUTPUT_ERRNOS:
            raise output_error(path, exc) from exc
        raise
    except BaseException:
        _remove_quietly(tmp)
        raise


def _remove_quietly(path: str | Path | None) -> None:
    if path is not None:
        with contextlib.suppress(OSError):
            os.unlink(path)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_text_atomic(path: str | Path, text: str) -> None:
    """Write ``text`` (UTF-8, ``\\n`` line ends) to ``path`` atomically."""
    with atomic_open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(text)


def write_bytes_atomic(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_open(path, "wb") as fh:
        fh.write(data)


def sha256_file(path: str | Path, chunk_bytes: int = 1 << 20) -> str:
    """Hex sha256 of a file, read in chunks (safe for multi-GB videos)."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        while chunk := fh.read(chunk_bytes):
            digest.update(chunk)
    return digest.hexdigest()


def sha256_path(path: str | Path) -> str:
    """sha256 of a file, or of a folder's files (sorted relative names and contents)."""
    path = Path(path)
    if path.is_file():
        return sha256_file(path)
    digest = hashlib.sha256()
    for child in sorted(p for p in path.rglob("*") if p.is_file()):
        digest.update(str(child.relative_to(path)).encode())
        digest.update(sha256_file(child).encode())
    return digest.hexdigest()


def check_input_size(path: str | Path, max_bytes: int = MAX_INPUT_BYTES,
                     what: str = "input") -> int:
    """The size of an input file [bytes]; :class:`InputError` above ``max_bytes``.

    Checked before reading, so a file far beyond any drive fails in a second instead of
    exhausting memory.
    """
    path = Path(path)
    try:
        size = path.stat().st_size
    except FileNotFoundError:
        raise MissingInputError(path, "no such file") from None
    except OSError as exc:
        raise MissingInputError(path, f"cannot read: {exc.strerror or exc}") from None
    if size > max_bytes:
        raise InputError(path, f"{what} file of {size / 2**20:.0f} MiB is larger than the "
                         f"{max_bytes / 2**20:.0f} MiB limit", "see docs/limits.md")
    return size


def read_input_text(path: str | Path, max_bytes: int = MAX_INPUT_BYTES) -> str:
    """Text of a user's input file (UTF-8, a leading BOM dropped).

    Raises, naming the file, so every reader reports these the same way:
    :class:`~vid2sim.base.errors.MissingInputError` for a missing or unreadable file or a
    folder, :class:`~vid2sim.base.errors.FormatError` for binary (NUL bytes) or non-UTF-8
    content, :class:`~vid2sim.base.errors.InputError` for a file over ``max_bytes``.
    """
    path = Path(path)
    try:
        if path.is_file():
            check_input_size(path, max_bytes)
        text = path.read_text(encoding="utf-8").lstrip("\ufeff")
    except FileNotFoundError:
        raise MissingInputError(path, "no such file") from None
    except IsADirectoryError:
        raise MissingInputError(path, "is a folder, not a file") from None
    except UnicodeDecodeError as exc:
        raise FormatError(path, f"not UTF-8 text (byte {exc.start})",
                          "is this a binary file?") from None
    except OSError as exc:
        raise MissingInputError(path, f"cannot read: {exc.strerror or exc}") from None
    nul = text.find("\x00")
    if nul >= 0:
        raise FormatError(path, f"binary content (a NUL byte at character {nul})",
                          "expected a text file")
    return text


def parse_json(text: str, path: str | Path | None) -> Any:
    """``json.loads`` with the project's errors: bad JSON or nesting too deep for the parser
    (a 100,000-deep array) is a :class:`~vid2sim.base.errors.FormatError` naming the file."""
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise FormatError(path, f"not valid JSON: {exc.msg} at line {exc.lineno}") from None
    except RecursionError:
        raise FormatError(path, "JSON nested too deeply to read",
                          "no vid2sim input nests more than a few levels") from None


# --------------------------------------------------------------------------- output folders


def check_output_file(path: str | Path) -> None:
    """Raise :class:`InputError` now if ``path`` cannot be written, before any work.

    Creates (and removes) a temporary file where :func:`atomic_open` will create its own,
    so a read-only folder or a full disk fails in a second, not after the whole run.
    """
    path = Path(path)
    if path.is_symlink():
        path = path.resolve()
    _probe_folder(_nearest_existing(path.parent), path)


def check_output_folder(path: str | Path) -> None:
    """Raise :class:`InputError` now if the output folder ``path`` cannot be written."""
    path = Path(path)
    _probe_folder(path.resolve() if path.is_dir() else _nearest_existing(path.parent), path)


def _nearest_existing(path: Path) -> Path:
    path = Path(os.path.abspath(path))
    while not path.exists() and path != path.parent:
        path = path.parent
    return path.resolve()


def _probe_folder(folder: Path, named: Path) -> None:
    try:
        fd, probe = tempfile.mkstemp(prefix=STAGING_PREFIX, suffix=".probe", dir=folder)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        if exc.errno in OUTPUT_ERRNOS or isinstance(exc, (NotADirectoryError, FileNotFoundError)):
            raise output_error(named, exc) from exc
        raise


@contextlib.contextmanager
def staged_folder(out_dir: str | Path, owned: Iterable[str] = ()) -> Iterator[Path]:
    """Write a command's outputs into a staging folder; move them into ``out_dir`` on success.

    Yields the staging folder. When the block completes, every entry of the staging folder
    replaces the entry of the same name in ``out_dir``, and the names in ``owned`` that this
    run did not write are removed from ``out_dir`` (the outputs of an earlier run that this
    one replaces: a rebuild without keyframes must not leave the old ``metrics.json``).
    Other files in ``out_dir`` are not touched. When the block raises (or the process is
    interrupted by SIGINT/SIGTERM, which the CLI turns into exceptions), ``out_dir`` is
    untouched and the staging folder removed.

    The staging folder is created first, on the filesystem the outputs end up on: inside
    ``out_dir`` when it exists (an ``--out`` that is a mount point or a link to another
    filesystem), else in its nearest existing parent, whose filesystem a new ``out_dir``
    gets; renames never cross filesystems, and if one still does (EXDEV, e.g. overlayfs
    directories) the entry is copied beside its target and renamed. A location that cannot
    be written fails here, before the caller does any work.

    Raises
    ------
    InputError
        If the output location cannot be written (read-only, full, not a folder).
    """
    out_dir = Path(out_dir)
    into = out_dir.is_dir()
    base = out_dir.resolve() if into else _nearest_existing(out_dir.parent)
    try:
        # Inside an existing output folder the prefix marks it; beside a new one it is named
        # after it (".<name>.<random>", the random part without dots), so that a batch can
        # tell which row a killed attempt's staging folder belongs to.
        prefix = STAGING_PREFIX if into else f".{out_dir.name}."
        staging = Path(tempfile.mkdtemp(prefix=prefix, dir=base))
        os.chmod(staging, 0o777 & ~_umask())
    except OSError as exc:
        if exc.errno in OUTPUT_ERRNOS or isinstance(exc, (NotADirectoryError, FileNotFoundError)):
            raise output_error(out_dir, exc) from exc
        raise
    try:
        try:
            yield staging
        except InputError as exc:
            # Name the output the user asked for, not the staging folder's random name.
            if exc.path is not None and exc.path.startswith(str(staging)):
                final = out_dir / os.path.relpath(exc.path, staging)
                raise exc.naming(final) from exc
            raise
        except OSError as exc:
            if exc.errno in OUTPUT_ERRNOS:
                raise output_error(out_dir, exc) from exc
            raise
        # The moves take milliseconds; an interrupt in their middle would leave half the old
        # and half the new outputs, so SIGINT/SIGTERM wait until they are done.
        with deferred_interrupts():
            try:
                _commit(staging, out_dir, set(owned))
            except OSError as exc:
                if exc.errno in OUTPUT_ERRNOS:
                    raise output_error(out_dir, exc) from exc
                raise
    finally:
        shutil.rmtree(staging, ignore_errors=True)


@contextlib.contextmanager
def deferred_interrupts() -> Iterator[None]:
    """Hold SIGINT and SIGTERM for the duration of the block, then deliver them.

    Only in the main thread (the only one that may set signal handlers); elsewhere the block
    simply runs.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    wanted = [s for s in (signal.SIGINT, getattr(signal, "SIGTERM", None)) if s is not None]
    previous = {s: signal.signal(s, lambda signum, _frame: caught.append(signum))
                for s in wanted}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        for s in dict.fromkeys(caught):
            signal.raise_signal(s)


def _commit(staging: Path, out_dir: Path, owned: set[str]) -> None:
    """Move the staged entries into ``out_dir``; old owned entries go to a trash folder
    inside ``staging`` (removed with it), so nothing of the old outputs is lost before the
    new ones are in place."""
    if not out_dir.exists():
        out_dir.parent.mkdir(parents=True, exist_ok=True)
        try:
            os.rename(staging, out_dir)  # a new output folder appears whole, in one step
            return
        except OSError as exc:
            if exc.errno not in (errno.EXDEV, errno.EEXIST, errno.ENOTEMPTY):
                raise
            out_dir.mkdir(parents=True, exist_ok=True)
    target_dir = out_dir.resolve()
    new = sorted(staging.iterdir())
    trash = staging / _TRASH
    trash.mkdir()
    for name in sorted(owned - {p.name for p in new}):
        _discard(target_dir / name, trash)
    for entry in new:
        target = target_dir / entry.name
        # rename() replaces a file by a file, not a folder or a folder by a file.
        if (target.is_dir() and not target.is_symlink()) or (
                entry.is_dir() and (target.exists() or target.is_symlink())):
            _discard(target, trash)
        _move(entry, target)


# Inside a staging folder: where replaced outputs wait until the new ones are in place.
_TRASH = ".replaced"


def _discard(path: Path, trash: Path) -> None:
    """Move an old output out of the way (into ``trash``), or delete it if it cannot move."""
    if not (path.exists() or path.is_symlink()):
        return
    try:
        os.rename(path, trash / path.name)
    except OSError as exc:
        if exc.errno != errno.EXDEV:
            raise
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        else:
            path.unlink()


def _move(src: Path, dst: Path) -> None:
    """``os.replace``, or copy beside ``dst`` then rename where the two differ in filesystem."""
    try:
        os.replace(src, dst)
        return
    except OSError as exc:
        if exc.errno != errno.EXDEV:
            raise
    tmp = dst.parent / f"{STAGING_PREFIX}{dst.name}.copy"
    try:
        if src.is_dir():
            shutil.copytree(src, tmp, symlinks=True)
        else:
            shutil.copy2(src, tmp)
        os.replace(tmp, dst)
    except BaseException:
        if tmp.is_dir():
            shutil.rmtree(tmp, ignore_errors=True)
        else:
            _remove_quietly(tmp)
        raise
