"""Copy the catalogue's clips of one source from that source's distribution into place.

Sources whose licence forbids redistribution (Bandai Namco: CC BY-NC) and the ones that are
simply too large to commit (CMU, ReActIdle) go into the local cache, by default
``data/mocap-cache/<source>/`` (``data/`` is git-ignored); the DeepMimic motions are small and
MIT/zlib licensed, and go into the committed ``data/deepmimic/`` (compacted, see its notice).
Only the files the catalogue names are copied, with the source's licence beside them.

``--from`` takes a git URL (the default: the source's public repository, cloned shallow with
blobs fetched on demand), a local git directory (bare or with a work tree), a plain folder laid
out like the repository, or for ``deepmimic`` a pybullet wheel or a ``pybullet_data`` folder
(default: the installed pybullet's).

    python -m endeff_ros.synth.mocap.fetch bandai [--from SRC] [--cache DIR]
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
import zipfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

from .catalogue import CLIPS, DATA_DIR, SOURCES, cache_path
from .kin import MocapError

Reader = Callable[[str], bytes]

#: Clip names that must never enter the catalogue: they are kept out for an independent check
#: (CMU trial 01_01 in all its spellings, LAFAN1 test files, bvhtoolbox's test_mocapbank).
EXCLUDED = re.compile(r'(^|[^0-9])0*1_0*1([^0-9]|$)|mocapbank|lafan|subject\d', re.IGNORECASE)


@dataclass(frozen=True)
class FetchSource:
    """Where a source's files are: default location, file -> path in it, licence files."""

    url: str
    path: Callable[[str], str]
    licences: dict[str, str] = field(default_factory=dict)
    notice: str = ''


def _bandai_path(file: str) -> str:
    part = file.split('_', 1)[0][-1]
    return f'dataset/Bandai-Namco-Research-Motiondataset-{part}/data/{file}'


def _deepmimic_path(file: str) -> str:
    stem = file.removeprefix('walker_')
    sub = 'walker/' if stem != file else ''
    return f'data/motions/{sub}{stem}'


FETCH_SOURCES: dict[str, FetchSource] = {
    'bandai': FetchSource(
        'https://github.com/BandaiNamcoResearchInc/Bandai-Namco-Research-Motiondataset.git',
        _bandai_path,
        {'LICENSE-dataset-1': 'dataset/Bandai-Namco-Research-Motiondataset-1/LICENSE',
         'LICENSE-dataset-2': 'dataset/Bandai-Namco-Research-Motiondataset-2/LICENSE'},
        'Bandai Namco Research Motiondataset (Bandai Namco Research Inc.), CC BY-NC 4.0: '
        'local use only, never commit or redistribute these files.'),
    'cmu': FetchSource(
        'https://github.com/DragonForgedTheArtist/IClone-CMU-Mocap.git',
        lambda f: f'All_BVH/subjects/{f[:3]}/{f}',
        {},
        'CMU Graphics Lab Motion Capture Database (mocap.cs.cmu.edu), converted to BVH by the '
        'IClone-CMU-Mocap project. CMU: the data may be used and redistributed freely but not '
        'resold; publications should say "The data used in this project was obtained from '
        'mocap.cs.cmu.edu. The database was created with funding from NSF EIA-0196217."'),
    'reactidle': FetchSource(
        'https://github.com/Enekoassets/ReActIdle.git',
        lambda f: f'{"acted" if "acted" in f else "genuine"}/{f}',
        {'LICENSE': 'LICENSE.txt'},
        'ReActIdle dataset (E. Atxa Landa et al., "Evaluating Idle Animation Believability: a '
        'User Perspective", 2025), MIT licence (LICENSE beside this file).'),
    'deepmimic': FetchSource('', _deepmimic_path),
}


@dataclass
class FetchResult:
    """Files written and catalogue files the source did not have."""

    dest: Path
    copied: list[str] = field(default_factory=list)
    missing: list[str] = field(default_factory=list)


def _is_git_dir(path: Path) -> Path | None:
    if (path / 'HEAD').is_file() and (path / 'objects').is_dir():
        return path
    if (path / '.git').exists():
        return path / '.git'
    return None


def _git_reader(git_dir: Path) -> Reader:
    def read(rel: str) -> bytes:
        done = subprocess.run(['git', f'--git-dir={git_dir}', 'show', f'HEAD:{rel}'],
                              capture_output=True, check=False)
        if done.returncode != 0:
            raise FileNotFoundError(rel)
        return done.stdout
    return read


@contextmanager
def open_source(spec: str) -> Iterator[Reader]:
    """A reader ``relative path -> bytes`` (``FileNotFoundError`` if absent) of ``spec``."""
    path = Path(spec)
    if path.is_dir():
        git_dir = _is_git_dir(path)
        if git_dir is not None:
            yield _git_reader(git_dir)
        else:
            yield lambda rel: (path / rel).read_bytes()
    elif path.is_file() and zipfile.is_zipfile(path):
        with zipfile.ZipFile(path) as zf:
            names = set(zf.namelist())

            def read(rel: str) -> bytes:
                for cand in (rel, f'pybullet_data/{rel}'):
                    if cand in names:
                        return zf.read(cand)
                raise FileNotFoundError(rel)
            yield read
    elif re.match(r'^(https?|git|ssh|file)://|^git@', spec):
        with tempfile.TemporaryDirectory(prefix='mocap-fetch-') as tmp:
            done = subprocess.run(['git', 'clone', '--quiet', '--depth', '1', '--filter=blob:none',
                                   '--no-checkout', spec, tmp], capture_output=True, text=True,
                                  check=False)
            if done.returncode != 0:
                msg = f'cannot clone {spec}: {done.stderr.strip()}'
                raise MocapError(msg)
            yield _git_reader(Path(tmp) / '.git')
    else:
        msg = f'source {spec!r} is neither a folder, a git directory, a wheel nor a git URL'
        raise MocapError(msg)


def compact_deepmimic(raw: bytes) -> bytes:
    """A DeepMimic motion rewritten with 6 decimals and one frame per line (same content to
    within 5e-7; the pybullet_data files pad every number to 10 decimals)."""
    data = json.loads(raw)
    rows = [','.join(f'{v:.6f}'.rstrip('0').rstrip('.') if v != int(v) else str(int(v))
                     for v in row) for row in data['Frames']]
    head = f'{{"Loop":{json.dumps(data.get("Loop", "none"))},"Frames":[\n'
    return (head + ',\n'.join(f'[{r}]' for r in rows) + '\n]}\n').encode()


def _default_deepmimic() -> str:
    try:
        import pybullet_data
    except ImportError:
        msg = 'deepmimic: give --from (a pybullet wheel or pybullet_data folder)'
        raise MocapError(msg) from None
    return pybullet_data.getDataPath()


def fetch(source: str, *, src: str | None = None, dest: str | Path | None = None) -> FetchResult:
    """Copy the catalogue's files of ``source`` from ``src`` into ``dest``.

    ``dest`` defaults to the cache (``cache_path()/source``) or, for a committed source, its
    data folder. Files the source lacks are listed in ``FetchResult.missing``.
    """
    if source not in FETCH_SOURCES:
        msg = f'unknown source {source!r}; known: {", ".join(FETCH_SOURCES)}'
        raise MocapError(msg)
    fs = FETCH_SOURCES[source]
    if dest is None:
        dest = (DATA_DIR if SOURCES[source].committed else cache_path()) / source
    out = FetchResult(Path(dest))
    files = [e.file for e in CLIPS if e.source == source]
    bad = [f for f in files if EXCLUDED.search(f)]
    if bad:
        msg = f'{source}: catalogue names excluded clips {bad}'
        raise MocapError(msg)
    spec = src or (_default_deepmimic() if source == 'deepmimic' else fs.url)
    with open_source(spec) as read:
        out.dest.mkdir(parents=True, exist_ok=True)
        for name, rel in fs.licences.items():
            try:
                (out.dest / name).write_bytes(read(rel))
            except FileNotFoundError:
                out.missing.append(rel)
        for f in files:
            try:
                raw = read(fs.path(f))
            except FileNotFoundError:
                out.missing.append(fs.path(f))
                continue
            (out.dest / f).write_bytes(compact_deepmimic(raw) if source == 'deepmimic' else raw)
            out.copied.append(f)
    if fs.notice:
        (out.dest / 'NOTICE.md').write_text(f'# {source}\n\n{fs.notice}\n', encoding='utf-8')
    return out


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('source', choices=sorted(FETCH_SOURCES), help='which source to copy')
    parser.add_argument('--from', dest='src', default=None,
                        help='git URL, git directory, folder, or (deepmimic) pybullet wheel / '
                        'pybullet_data folder; default: the public repository')
    parser.add_argument('--cache', default=None,
                        help='cache folder (default data/mocap-cache); the clips go to '
                        'CACHE/SOURCE (ignored for the committed deepmimic source)')


def run(args: argparse.Namespace) -> int:
    dest = None
    if args.cache is not None and not SOURCES[args.source].committed:
        dest = Path(args.cache) / args.source
    try:
        res = fetch(args.source, src=args.src, dest=dest)
    except MocapError as err:
        print(f'mocap-fetch: {err}', file=sys.stderr)
        return 2
    print(f'{args.source}: {len(res.copied)} clips copied to {res.dest}')
    if res.missing:
        print(f'{args.source}: missing in the source: {", ".join(res.missing)}', file=sys.stderr)
        return 1
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog='python -m endeff_ros.synth.mocap.fetch',
                                     description=__doc__.split('\n\n')[0])
    add_arguments(parser)
    return run(parser.parse_args(argv))


if __name__ == '__main__':
    raise SystemExit(main())
