"""Copy a real source's frames and licence file from its repository into the local cache.

The raw frames are third-party files and are never committed: ``fetch`` copies the fixed
selection the labels were made on (:attr:`Source.files`) from the source's repository into
``CACHE/<source>/`` (default ``data/realdata-cache``, git-ignored), with the source's licence
file and our ``NOTICE.md`` beside them. Skeltrack's frames are stored gzip-compressed
(``gzip -9 -n``; lossless, 614400 bytes to 21-35 kB each), PCL's cloud as it is.

``--from`` takes a git URL (the default: the source's public repository, cloned shallow with
blobs fetched on demand), a local git directory (bare or with a work tree) or a plain folder
laid out like the repository; the copying is the mocap fetch's
(:func:`endeff_ros.synth.mocap.fetch.open_source`).

Every copied frame's SHA-256 (of the original, uncompressed bytes) is compared with the
version the labels were made on: a frame that differs is still copied but reported, and the
command exits with status 1, since its labels may no longer fit it.

    python -m endeff_ros.realdata fetch {skeltrack,five_people} [--from SRC] [--cache DIR]
"""

from __future__ import annotations

import gzip
import hashlib
import shutil
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from endeff_ros.realdata import DATA_DIR, DEFAULT_CACHE, SOURCES
from endeff_ros.realdata.sources import SourceError
from endeff_ros.synth.mocap.fetch import FetchResult, open_source
from endeff_ros.synth.mocap.kin import MocapError


@dataclass(frozen=True)
class FetchSource:
    """Where a source's files are: repository URL, cache file -> path in the repository, how a
    file is stored, licence files (cache name -> path), SHA-256 of the original frames."""

    url: str
    path: Callable[[str], str]
    store: Callable[[bytes], bytes]
    licences: dict[str, str]
    sha256: dict[str, str] = field(default_factory=dict)


def _gzip(raw: bytes) -> bytes:
    """``gzip -9 -n``: no name or time stamp, so the same frame always gives the same file."""
    return gzip.compress(raw, compresslevel=9, mtime=0)


FETCH_SOURCES: dict[str, FetchSource] = {
    'skeltrack': FetchSource(
        'https://github.com/joaquimrocha/Skeltrack.git',
        lambda f: f'tests/resources/{f.removesuffix(".gz")}', _gzip, {'COPYING': 'COPYING'}, {
            'depth-data-82823944.gz':
                '6ab3838808274099f3371d04c72b758b2ae386e8913b378185187676e8e08eda',
            'depth-data-1028894671.gz':
                'f1d351a83f2e45a9f8a72d8a6e18c38f74e88bb265e51320e1fd86de73a07918',
            'depth-data-1038901490.gz':
                '832eee17d440ebafd2cba6bd84db9b11b7a5c268c267ea7c07a0f32a5e982a9e',
            'depth-data-1045879925.gz':
                'eead1efb08c6792b70291f9ddc2bd2074cc57cfbce8f19b4b2e76c8660f0215b',
            'depth-data-1051883281.gz':
                '27e29f86d0eefd007f70504a0bba4ecf549cf3617eb6f7ea0eff8e7a122843db',
            'depth-data-1058893191.gz':
                '5c813cb8ab80e888dc347f8673e343da16bd63cb356d32bb886a3a1b14d82f01',
            'depth-data-1064898470.gz':
                'f43ee776ac19b0f15f40796b26f4a6ac5beeac928a38c9ba12f45ab2eb846f80',
            'depth-data-1070905432.gz':
                '07a6dbf200beca02087d0f09353c5ac4cebe65c50b1b65a442492d37d281be22',
            'depth-data-1078881076.gz':
                '76c0892ec6576fc4dbc95678740b942325a64707d107f759ac573352be1b4f7f',
            'depth-data-1166565565.gz':
                '545a0b4ce23f41785f9671b6d97659aed40af2b1b9faa9d718a30a137f3b9ee8',
            'depth-data-1234568668.gz':
                '982204efadd8b0f9bd6968b84d42f86c04dc95a1f36717baa831437cf6f27d56',
            'depth-data-1399145206.gz':
                'fb616fb2827690cd8f25223e5d83b7c26eec740c7bf200693e1908f7eae2c860',
        }),
    'five_people': FetchSource(
        'https://github.com/PointCloudLibrary/pcl.git',
        lambda f: f'test/{f}', bytes, {'LICENSE.txt': 'LICENSE.txt'}, {
            'five_people.pcd': '6f1ca66de5f88b035f6c4d16a2e737b6b1e0e98020fda91e7b2b8efae59ae1b7',
        }),
}


@dataclass
class RealFetchResult(FetchResult):
    """The mocap fetch's result plus the frames whose content differs from the labelled one."""

    changed: list[str] = field(default_factory=list)


def fetch(source: str, *, src: str | None = None, cache: str | Path = DEFAULT_CACHE
          ) -> RealFetchResult:
    """Copy ``source``'s frames and licence from ``src`` (default its public repository) into
    ``cache/<source>``; files the repository lacks are listed in ``missing``."""
    if source not in FETCH_SOURCES:
        msg = f'unknown source {source!r} (have {", ".join(FETCH_SOURCES)})'
        raise SourceError(msg)
    fs = FETCH_SOURCES[source]
    out = RealFetchResult(Path(cache) / source)
    frames = SOURCES[source].files
    wanted = [*((n, rel, bytes) for n, rel in fs.licences.items()),
              *((n, fs.path(n), fs.store) for n in frames)]
    try:
        with open_source(src or fs.url) as read:
            out.dest.mkdir(parents=True, exist_ok=True)
            for name, rel, store in wanted:
                try:
                    raw = read(rel)
                except FileNotFoundError:
                    out.missing.append(rel)
                    continue
                (out.dest / name).write_bytes(store(raw))
                if name in frames:
                    out.copied.append(name)
                    if hashlib.sha256(raw).hexdigest() != fs.sha256.get(name):
                        out.changed.append(name)
    except MocapError as err:
        raise SourceError(str(err)) from err
    shutil.copyfile(DATA_DIR / source / 'NOTICE.md', out.dest / 'NOTICE.md')
    return out


def run(source: str, src: str | None, cache: str | Path) -> int:
    """The ``fetch`` command: 0 when every file was copied and is the labelled version, 1 if
    some are missing or differ, 2 when the source cannot be read."""
    try:
        res = fetch(source, src=src, cache=cache)
    except (SourceError, OSError) as err:
        print(f'realdata fetch: {err}', file=sys.stderr)
        return 2
    print(f'{source}: {len(res.copied)} of {len(SOURCES[source].files)} frame files copied to '
          f'{res.dest}')
    status = 0
    if res.missing:
        print(f'{source}: missing in the source: {", ".join(res.missing)}',
              file=sys.stderr)
        status = 1
    if res.changed:
        print(f'{source}: differ from the labelled version (labels may not fit): '
              f'{", ".join(res.changed)}', file=sys.stderr)
        status = 1
    return status
