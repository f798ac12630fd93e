"""Input hashes without re-reading terabytes: a cache keyed by (path, size, modification stamp).

A batch decides that a row is already built by comparing its inputs' sha256 with the ones the
build recorded. Hashing reads every byte (about 1 s per GB), so a resumed 100,000-video batch
would spend hours re-hashing unchanged videos. The cache remembers each input's sha256 with
the size and modification stamp it had when it was hashed (:func:`storage.stat_key`, a
``stat`` or one object-store ``HEAD``); while both are unchanged the cached hash is used.

The cache lives in the batch folder (``DIR/_batch/hashes.csv``, shared by every node that
writes into ``DIR``) and is filled by the workers, which read the inputs anyway: the driver
only looks hashes up.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass

from vid2sim.app.batch import storage
from vid2sim.app.batch.storage import Where

#: Columns of ``hashes.csv``.
CACHE_COLUMNS = ("path", "size_bytes", "stamp", "sha256")


@dataclass(frozen=True, slots=True)
class HashEntry:
    """One input's sha256 and the (size, stamp) it had when hashed."""

    size_bytes: int
    stamp: str
    sha256: str

    def matches(self, key: tuple[int, str]) -> bool:
        return (self.size_bytes, self.stamp) == key


class HashCache:
    """Path or URL -> :class:`HashEntry`, loaded from and saved to a CSV file."""

    def __init__(self, entries: dict[str, HashEntry] | None = None):
        self.entries: dict[str, HashEntry] = dict(entries or {})
        self.changed = False

    def lookup(self, where: Where, key: tuple[int, str] | None) -> str | None:
        """The cached sha256 of ``where`` if its current ``key`` (size, stamp) matches."""
        entry = self.entries.get(storage.host_path(where))
        return entry.sha256 if entry is not None and key is not None and entry.matches(key) \
            else None

    def add(self, path: str, entry: HashEntry) -> None:
        if self.entries.get(path) != entry:
            self.entries[path] = entry
            self.changed = True

    def subset(self, paths: list[str]) -> dict[str, HashEntry]:
        """The entries of ``paths`` (what a worker needs for one row)."""
        return {p: self.entries[p] for p in paths if p in self.entries}

    @classmethod
    def load(cls, where: Where) -> HashCache:
        """The cache in ``where`` (empty when absent or unreadable: it is only a cache)."""
        try:
            text = storage.read_bytes(where).decode("utf-8")
        except (OSError, UnicodeDecodeError):
            return cls()
        entries: dict[str, HashEntry] = {}
        try:
            for r in csv.DictReader(io.StringIO(text)):
                entries[r["path"]] = HashEntry(int(r["size_bytes"]), r["stamp"], r["sha256"])
        except (KeyError, ValueError, TypeError, csv.Error):
            return cls()
        return cls(entries)

    def save(self, where: Where) -> None:
        """Write the cache atomically (only when something was added since the last save)."""
        if not self.changed:
            return
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        writer.writerow(CACHE_COLUMNS)
        for path in sorted(self.entries):
            e = self.entries[path]
            writer.writerow((path, e.size_bytes, e.stamp, e.sha256))
        storage.write_bytes(where, buf.getvalue().encode("utf-8"))
        self.changed = False


def hash_inputs(sources: dict[str, Where], known: dict[str, HashEntry],
                local: dict[str, Where] | None = None
                ) -> tuple[dict[str, str], dict[str, HashEntry]]:
    """sha256 of each input, from ``known`` where its (size, stamp) is unchanged.

    Parameters
    ----------
    sources : dict
        Role -> location of the row's inputs as the manifest gives them.
    known : dict
        Path -> cached entry (the driver's cache for these inputs).
    local : dict, optional
        Role -> a local copy of a URL input to hash instead of streaming it again.

    Returns
    -------
    (hashes, entries)
        Role -> sha256, and path -> entry of every input (new ones for the cache).
    """
    hashes: dict[str, str] = {}
    entries: dict[str, HashEntry] = {}
    for role, where in sources.items():
        path = storage.host_path(where)
        key = storage.stat_key(where)
        entry = known.get(path)
        if entry is None or not entry.matches(key):
            copy = (local or {}).get(role)
            sha = storage.sha256_of(copy if copy is not None else where)
            # A file rewritten while it was hashed gets no cache entry (its key moved).
            entry = HashEntry(key[0], key[1], sha)
            if storage.stat_key(where) != key:
                hashes[role] = sha
                continue
        hashes[role] = entry.sha256
        entries[path] = entry
    return hashes, entries
