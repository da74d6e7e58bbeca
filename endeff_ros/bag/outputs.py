"""Output paths of the offline tools: checked before any work, written aside, never clobbered.

:func:`check_output_path` finds every problem an output can have (it exists, it is the input,
its parent is a file, the directory cannot be written) before a bag is read, so a command fails
in its first second with one line naming the path instead of after minutes of processing.
``endeff process`` writes each output bag inside a hidden sibling directory
(:func:`partial_dir`) and renames it into place when complete; an interrupted run removes it,
and a run killed outright (SIGKILL) leaves it for the next run to sweep
(:func:`sweep_stale_partials`: directories whose process id is no longer alive).

Bags written by ``endeff process`` carry ``endeff.writer: endeff process`` in the rosbag2
``custom_data`` of ``metadata.yaml`` (:data:`WRITER_KEY`); ``--force`` replaces only those (or
a bag whose topics are only the process outputs, or a single ``.mcap`` / ``.db3`` file), never
a recording, a regular file or a folder of something else.
"""

from __future__ import annotations

import errno
import os
import re
import shutil
import sqlite3
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

from .errors import BagError

if TYPE_CHECKING:
    from collections.abc import Iterable

#: rosbag2 ``custom_data`` key marking a bag written by ``endeff process``.
WRITER_KEY = 'endeff.writer'
WRITER = 'endeff process'
_BAG_SUFFIXES = ('.mcap', '.db3')
#: Below this much free space an output is refused before any work (a bag's metadata alone
#: is a few kB; writing would fail at once with ENOSPC).
MIN_FREE_BYTES = 1 << 20


class OutputError(BagError):
    """An output path cannot be written; the message names the path and the problem."""


def check_output_path(path: str | Path, *, force: bool = False, kind: str = 'bag',
                      inputs: Iterable[str | Path] = (),
                      own_topics: Iterable[str] = ()) -> Path:
    """Raise :class:`OutputError` unless ``path`` can be written; return it as a Path.

    ``kind='bag'``: an output bag (a directory) that exists is replaced only with ``force``
    and only if it is an earlier output (see the module docstring) and neither is nor
    contains one of ``inputs``. ``kind='file'`` (a report): an existing regular file is
    overwritten, a directory is an error. ``kind='dir'`` (a folder of outputs): it may exist.
    In every case the nearest existing ancestor must be a directory we can create files in.
    """
    out = Path(path)
    if kind not in ('bag', 'file', 'dir'):
        msg = f'unknown output kind {kind!r}'
        raise ValueError(msg)
    exists = out.exists() or out.is_symlink()
    if exists:
        _check_existing(out, force=force, kind=kind, inputs=inputs, own_topics=own_topics)
    elif any(_same(out, i) for i in inputs):
        raise OutputError(out, 'output is the input bag')
    _check_writable(out if kind == 'dir' and out.is_dir() else out.parent, out)
    return out


def _same(a: Path, b: str | Path) -> bool:
    return a.resolve() == Path(b).resolve()


def _check_existing(out: Path, *, force: bool, kind: str, inputs: Iterable[str | Path],
                    own_topics: Iterable[str]) -> None:
    if kind == 'dir':
        if not out.is_dir():
            raise OutputError(out, 'exists and is not a directory')
        return
    if kind == 'file':
        if out.is_dir():
            raise OutputError(out, 'is a directory, not a file')
        if not os.access(out, os.W_OK):
            raise OutputError(out, 'exists and is not writable')
        return
    resolved = out.resolve()
    for i in inputs:
        inp = Path(i).resolve()
        if inp == resolved or resolved in inp.parents:
            raise OutputError(out, 'is or contains the input bag: not replacing it')
    if not force:
        raise OutputError(out, 'exists (use --force to replace an earlier output bag)')
    if out.is_dir():
        if any(out.iterdir()) and not is_own_bag(out, own_topics):
            raise OutputError(out, 'exists and is not a bag written by endeff process: not '
                                   'replacing it, even with --force')
    elif out.suffix not in _BAG_SUFFIXES:
        raise OutputError(out, 'exists and is a file, not an output bag: not replacing it, '
                               'even with --force')


def is_own_bag(path: Path, own_topics: Iterable[str] = ()) -> bool:
    """A bag directory written by ``endeff process`` (its custom_data mark), or one whose
    topics are all in ``own_topics`` (an output bag of an earlier version)."""
    meta = path / 'metadata.yaml'
    if not meta.is_file():
        return False
    import yaml

    try:
        info = yaml.safe_load(meta.read_text(encoding='utf-8'))['rosbag2_bagfile_information']
    except Exception:  # noqa: BLE001 - unreadable metadata: not provably ours
        return False
    if (info.get('custom_data') or {}).get(WRITER_KEY) == WRITER:
        return True
    topics = {t.get('topic_metadata', {}).get('name')
              for t in info.get('topics_with_message_count') or []}
    own = set(own_topics)
    return bool(own) and bool(topics) and topics <= own


def _check_writable(directory: Path, out: Path) -> None:
    """The nearest existing ancestor of ``directory`` is a directory we can create files in."""
    probe = directory
    while not (probe.exists() or probe.is_symlink()):
        if probe.parent == probe:
            break
        probe = probe.parent
    if not probe.is_dir():
        raise OutputError(out, f'cannot create it: {probe} is a file, not a directory')
    try:
        fd, name = tempfile.mkstemp(prefix='.endeff-probe-', dir=probe)
    except OSError as err:
        raise OutputError(out, f'cannot write in {probe}: {err.strerror or err}') from err
    os.close(fd)
    os.unlink(name)
    free = shutil.disk_usage(probe).free
    if free < MIN_FREE_BYTES:
        raise OutputError(out, f'no space left on device ({free} bytes free in {probe})')


def check_output_option(path: str | None, prog: str, *, kind: str = 'file') -> None:
    """For a command's output option (``--json FILE``, ``--plots DIR``): on a problem print
    ``prog: output PATH: problem`` to stderr and exit with status 2, before any work."""
    if not path:
        return
    import sys

    try:
        check_output_path(path, kind=kind)
    except OutputError as err:
        print(f'{prog}: output {err}', file=sys.stderr)
        raise SystemExit(2) from err


# --------------------------------------------------------------------------------------------
# Written aside, moved into place
# --------------------------------------------------------------------------------------------

_PARTIAL = re.compile(r'^\.(?P<name>.+)\.partial-(?P<pid>\d+)$')


def partial_dir(out: Path, pid: int | None = None) -> Path:
    """The hidden sibling directory in which ``out`` is written by process ``pid``."""
    return out.parent / f'.{out.name}.partial-{os.getpid() if pid is None else pid}'


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def sweep_stale_partials(out: Path, *, include_own: bool = False) -> list[Path]:
    """Remove ``out``'s hidden partial directories left by dead processes; returns them.

    ``include_own`` also removes this process's own (after an interrupt).
    """
    removed: list[Path] = []
    parent = out.parent
    if not parent.is_dir():
        return removed
    for child in parent.iterdir():
        m = _PARTIAL.match(child.name)
        if not m or m['name'] != out.name:
            continue
        pid = int(m['pid'])
        if (include_own and pid == os.getpid()) or not _alive(pid):
            remove(child)
            removed.append(child)
    return removed


def remove(path: Path) -> None:
    """Delete a file, symlink or directory tree (no error if it is gone)."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    elif path.exists() or path.is_symlink():
        path.unlink(missing_ok=True)


def replace_into_place(new: Path, out: Path, scratch: Path) -> None:
    """Move ``new`` to ``out``; an existing ``out`` is first moved into ``scratch`` (removed by
    the caller), so that an interrupt never leaves neither the old nor the new output."""
    if out.exists() or out.is_symlink():
        out.rename(scratch / f'.replaced-{out.name}')
    new.rename(out)


def write_error(out: Path, err: BaseException) -> OutputError | None:
    """An :class:`OutputError` for a storage failure while writing ``out``, else None.

    ``ENOSPC`` (mcap, a plain ``OSError``) and SQLite's "database or disk is full" both become
    ``no space left on device``.
    """
    if isinstance(err, OSError):
        if err.errno == errno.ENOSPC:
            return OutputError(out, 'no space left on device while writing (nothing written)')
        return OutputError(out, f'cannot write: {err.strerror or err} (nothing written)')
    if isinstance(err, sqlite3.OperationalError) and 'full' in str(err):
        return OutputError(out, 'no space left on device while writing (nothing written)')
    return None
