"""Read a rosbag2 bag whose index is gone: a file cut short by a crash, a full disk or a copy.

``rosbags`` opens a bag through its index (the MCAP summary at the end of the file; SQLite's
page count in the database header), so a cut file does not open at all although most of its
messages are intact. :class:`SalvageReader` reads such a bag in storage order instead:

- MCAP with the ``mcap`` package's :class:`~mcap.stream_reader.StreamReader`, record by record
  from the start; a chunk cut in the middle (the last one) and everything after it is lost;
- SQLite with ``PRAGMA writable_schema = ON``, which lets SQLite open a database whose header
  lists more pages than the file holds, then the ``messages`` table row by row until the first
  missing page.

The reader quacks like the part of ``rosbags.highlevel.AnyReader`` that
:class:`~endeff_ros.bag.reader.BagReader` uses (``topics``, ``connections``, ``messages``,
``deserialize``, ``typestore``); a storage error ends :meth:`SalvageReader.messages` by raising,
and the bag reader turns that into its truncation warning. Message counts come from
``metadata.yaml`` when the bag has one (they are what was expected), else they are unknown.
Messages are deserialised with the Jazzy typestore (the bag's own definitions may be lost).
"""

from __future__ import annotations

import sqlite3
from pathlib import Path
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from collections.abc import Iterator


class SalvageReader:
    """Messages of a truncated bag directory or storage file, in storage order."""

    def __init__(self, source: Path, typestore: Any) -> None:
        self.typestore = typestore
        self.files, storage, expected, self._decompress = _layout(Path(source))
        self._storage = storage
        names: dict[str, str] = {}
        self._channels: dict[Any, str] = {}  # storage channel/topic id -> topic
        if storage == 'sqlite3':
            for f in self.files:
                with _sqlite(f) as con:
                    for tid, name, typ in con.execute('SELECT id, name, type FROM topics'):
                        names[name] = typ
                        self._channels[(f, tid)] = name
        else:
            self._scan_mcap(names)
        from rosbags.interfaces import MessageDefinitionFormat

        self.connections = [
            SimpleNamespace(id=k, topic=name, msgtype=typ, digest=None, ext=None,
                            msgdef=SimpleNamespace(format=MessageDefinitionFormat.NONE,
                                                   data=''))
            for k, (name, typ) in enumerate(sorted(names.items()))]
        self._by_topic = {c.topic: c for c in self.connections}
        self.topics = {c.topic: SimpleNamespace(msgtype=c.msgtype, msgcount=expected.get(c.topic))
                       for c in self.connections}

    def _scan_mcap(self, names: dict[str, str]) -> None:
        """Topics and types from the channel and schema records that can still be read."""
        from mcap.records import Channel, Schema

        schemas: dict[int, str] = {}
        try:
            for f, rec in self._mcap_records():
                if isinstance(rec, Schema):
                    schemas[rec.id] = rec.name
                elif isinstance(rec, Channel):
                    names[rec.topic] = schemas.get(rec.schema_id, '')
                    self._channels[(f, rec.id)] = rec.topic
        except Exception:  # noqa: BLE001, S110 - the cut: keep what was found before it
            pass
        if not names:
            msg = 'no readable channel records'
            raise ValueError(msg)

    def _mcap_records(self) -> Iterator[tuple[Path, Any]]:
        from mcap.stream_reader import StreamReader

        for f in self.files:
            with f.open('rb') as fh:
                for rec in StreamReader(fh, validate_crcs=True).records:
                    yield f, rec

    def messages(self, connections: list[Any] | None = None
                 ) -> Iterator[tuple[Any, int, bytes]]:
        """``(connection, log time ns, raw CDR)`` in storage order; raises at the cut."""
        wanted = {c.topic for c in (connections or self.connections)}
        if self._storage == 'sqlite3':
            yield from self._sqlite_messages(wanted)
            return
        from mcap.records import Message

        for f, rec in self._mcap_records():
            if isinstance(rec, Message):
                topic = self._channels.get((f, rec.channel_id))
                if topic in wanted:
                    yield self._by_topic[topic], int(rec.log_time), self._decompress(rec.data)

    def _sqlite_messages(self, wanted: set[str]) -> Iterator[tuple[Any, int, bytes]]:
        for f in self.files:
            with _sqlite(f) as con:
                rows = con.execute('SELECT topic_id, timestamp, data FROM messages ORDER BY id')
                for tid, stamp, data in rows:
                    topic = self._channels.get((f, tid))
                    if topic in wanted:
                        yield self._by_topic[topic], int(stamp), self._decompress(bytes(data))

    def deserialize(self, raw: bytes, msgtype: str) -> Any:
        """CDR -> message with the Jazzy typestore."""
        return self.typestore.deserialize_cdr(raw, msgtype)

    def close(self) -> None:
        """Nothing stays open between calls."""


class _sqlite:  # noqa: N801 - a context manager used like a function
    """A read-only connection that tolerates a database shorter than its header says."""

    def __init__(self, path: Path) -> None:
        self.con = sqlite3.connect(f'file:{path}?mode=ro', uri=True)
        self.con.execute('PRAGMA writable_schema = ON')

    def __enter__(self) -> sqlite3.Connection:
        return self.con

    def __exit__(self, *exc: object) -> None:
        self.con.close()


def _layout(source: Path) -> tuple[list[Path], str, dict[str, int], Any]:
    """(storage files, storage id, topic -> listed count, per-message decompressor)."""
    meta_path = source / 'metadata.yaml' if source.is_dir() else None
    if meta_path is None or not meta_path.is_file():
        storage = 'sqlite3' if source.suffix == '.db3' else 'mcap'
        return [source], storage, {}, bytes
    import yaml

    info = yaml.safe_load(meta_path.read_text(encoding='utf-8'))['rosbag2_bagfile_information']
    storage = str(info.get('storage_identifier') or 'sqlite3')
    files = [source / p for p in info.get('relative_file_paths') or []]
    expected = {t['topic_metadata']['name']: int(t['message_count'])
                for t in info.get('topics_with_message_count') or []}
    mode = str(info.get('compression_mode') or '').lower()
    if mode == 'file':
        msg = 'file-compressed bags cannot be read past a cut'
        raise ValueError(msg)
    decompress: Any = bytes
    if mode == 'message':
        import zstandard

        decompress = zstandard.ZstdDecompressor().decompress
    return [f for f in files if f.exists()], storage, expected, decompress
