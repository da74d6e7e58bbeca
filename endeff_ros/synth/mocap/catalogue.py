"""The clip catalogue: every motion the ``mocap`` suite may use, with its family and split.

The tables below fix, per clip, its motion family and its split IN THE CODE, so that a split
never depends on which files happen to be present: roughly half of each source's clips and of
each family's clips are ``dev``, the rest ``test``, and a clip is never cut across both.
Committed sources (``SOURCES[...].committed``) live in ``data/<source>/`` beside this module and
load on a fresh clone; the others are copied by ``fetch`` into a local cache (default
``data/mocap-cache/<source>/`` under the working directory) and join the catalogue when present.

Run ``python -m endeff_ros.synth.mocap.catalogue [--cache DIR] [--committed-only]`` for the
statistics (clips and minutes per source, family and split).
"""

from __future__ import annotations

import argparse
import functools
import json
import sys
from collections.abc import Callable, Collection
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

from .clip import MotionClip
from .kin import F64, MocapError
from .retarget import FPS
from .sources import BVH_MAPS, load_bvh_positions, load_deepmimic_positions

#: Committed data, one folder per source, each with its licence notice.
DATA_DIR = Path(__file__).resolve().parent / 'data'
#: Where ``fetch`` puts the clips that may not be committed (relative to the working directory).
DEFAULT_CACHE = Path('data') / 'mocap-cache'


class Entry(NamedTuple):
    """One clip: the file in its source's folder, its family and split, an optional time
    window (start, end) s (long recordings are cut to a few tens of seconds)."""

    source: str
    file: str
    family: str
    split: str
    window: tuple[float, float] | None = None

    @property
    def name(self) -> str:
        return f'{self.source}/{Path(self.file).stem}'


@dataclass(frozen=True)
class Source:
    """A dataset: whether its clips are committed, its licence, how one file is loaded."""

    name: str
    committed: bool
    licence: str
    load: Callable[[Path, Entry, float | None], F64]


def _bvh(source: str, skip: int = 0) -> Callable[[Path, Entry, float | None], F64]:
    def load(path: Path, entry: Entry, loop_s: float | None) -> F64:
        return load_bvh_positions(path, BVH_MAPS[source], window=entry.window, skip=skip)
    return load


SOURCES: dict[str, Source] = {
    'deepmimic': Source('deepmimic', True, 'MIT (DeepMimic) and zlib (pybullet_data)',
                        lambda p, e, loop: load_deepmimic_positions(p, window=e.window,
                                                                    loop_s=loop)),
    'bandai': Source('bandai', False, 'CC BY-NC 4.0 (Bandai Namco Research Motiondataset)',
                     _bvh('bandai')),
    # The iClone conversion puts a T-pose before some clips' first frame: drop frame 0 always.
    'cmu': Source('cmu', False, 'CMU Graphics Lab Motion Capture Database terms', _bvh('cmu', 1)),
    'reactidle': Source('reactidle', False, 'MIT (ReActIdle dataset)', _bvh('reactidle')),
}


def _entries(source: str, rows: list[tuple]) -> list[Entry]:
    return [Entry(source, *row) for row in rows]


#: DeepMimic humanoid3d motions as pybullet_data ships them (walker/* renamed walker_*).
DEEPMIMIC = _entries('deepmimic', [
    ('humanoid3d_walk.txt', 'walk', 'dev'),
    ('walker_0walk_forward.txt', 'walk', 'test'),
    ('walker_turn_left0.txt', 'turn', 'dev'),
    ('walker_turn_right0.txt', 'turn', 'test'),
    ('walker_turn_left1.txt', 'turn', 'test'),
    ('walker_turn_right1.txt', 'turn', 'dev'),
    ('humanoid3d_run.txt', 'run', 'test'),
    ('humanoid3d_spinkick.txt', 'kick', 'dev'),
    ('humanoid3d_kick.txt', 'kick', 'test'),
    ('humanoid3d_punch.txt', 'punch', 'dev'),
    ('humanoid3d_crawl.txt', 'crawl', 'dev'),
    ('humanoid3d_roll.txt', 'roll', 'test'),
    ('humanoid3d_cartwheel.txt', 'acrobatic', 'dev'),
    ('humanoid3d_backflip.txt', 'acrobatic', 'test'),
    ('humanoid3d_jump.txt', 'jump', 'test'),
    ('humanoid3d_dance_a.txt', 'dance', 'dev'),
    ('humanoid3d_dance_b.txt', 'dance', 'test'),
    ('humanoid3d_spin.txt', 'dance', 'dev'),
    ('humanoid3d_getup_facedown.txt', 'other', 'dev'),
    ('humanoid3d_getup_faceup.txt', 'other', 'test'),
])

#: CMU subjects 1-7 (the iClone conversion); file NNN_TT.bvh is CMU trial NN_TT. Trial 01_01
#: is deliberately absent (kept out for an independent check).
CMU = _entries('cmu', [
    ('002_01.bvh', 'walk', 'dev'),
    ('007_01.bvh', 'walk', 'test'),
    ('007_04.bvh', 'walk', 'dev'),
    ('007_12.bvh', 'walk', 'test'),
    ('003_01.bvh', 'walk', 'dev'),
    ('002_03.bvh', 'run', 'dev'),
    ('002_04.bvh', 'jump', 'dev'),
    ('002_05.bvh', 'punch', 'test'),
    ('002_06.bvh', 'bend', 'dev'),
    ('002_07.bvh', 'other', 'test'),
    ('002_10.bvh', 'gesture', 'dev'),
    ('001_08.bvh', 'sit', 'test'),
    ('001_14.bvh', 'other', 'dev'),
    ('005_02.bvh', 'dance', 'dev'),
    ('005_05.bvh', 'dance', 'test'),
    ('005_18.bvh', 'dance', 'test'),
    ('006_02.bvh', 'other', 'test'),
    ('006_10.bvh', 'turn', 'dev'),
    ('006_11.bvh', 'turn', 'test'),
    ('006_14.bvh', 'reach', 'test'),
])

#: ReActIdle: standing idle motion of eight people (the livelier recordings), each cut to its
#: first 45 s.
REACTIDLE = _entries('reactidle', [
    ('000_genuine.bvh', 'other', 'dev', (0.0, 45.0)),
    ('001_acted.bvh', 'other', 'test', (0.0, 45.0)),
    ('004_acted.bvh', 'other', 'dev', (0.0, 45.0)),
    ('007_acted.bvh', 'other', 'test', (0.0, 45.0)),
    ('007_genuine.bvh', 'other', 'dev', (0.0, 45.0)),
    ('009_acted.bvh', 'other', 'test', (0.0, 45.0)),
    ('013_acted.bvh', 'other', 'dev', (0.0, 45.0)),
    ('012_genuine.bvh', 'other', 'test', (0.0, 45.0)),
])

#: Bandai Namco Research Motiondataset 1 and 2: every content, styles spread over the 15-19
#: acting styles (dataset-N_content_style_take).
BANDAI = _entries('bandai', [(f'{n}.bvh', f, s) for n, f, s in [
    ('dataset-1_bow_active_001', 'bend', 'dev'),
    ('dataset-1_bow_angry_001', 'bend', 'test'),
    ('dataset-1_bow_childish_001', 'bend', 'dev'),
    ('dataset-1_bow_chimpira_001', 'bend', 'test'),
    ('dataset-1_bow_feminine_001', 'bend', 'dev'),
    ('dataset-1_bow_giant_001', 'bend', 'test'),
    ('dataset-1_bow_happy_001', 'bend', 'dev'),
    ('dataset-1_bow_masculinity_001', 'bend', 'test'),
    ('dataset-1_bye_happy_001', 'wave', 'dev'),
    ('dataset-1_bye_masculinity_001', 'wave', 'test'),
    ('dataset-1_bye_musical_001', 'wave', 'dev'),
    ('dataset-1_bye_normal_001', 'wave', 'test'),
    ('dataset-1_bye_not-confident_001', 'wave', 'dev'),
    ('dataset-1_bye_old_001', 'wave', 'test'),
    ('dataset-1_bye_proud_001', 'wave', 'dev'),
    ('dataset-1_bye_sad_001', 'wave', 'test'),
    ('dataset-1_byebye_sad_001', 'wave', 'dev'),
    ('dataset-1_byebye_tired_001', 'wave', 'test'),
    ('dataset-1_byebye_active_001', 'wave', 'dev'),
    ('dataset-1_byebye_childish_001', 'wave', 'test'),
    ('dataset-1_byebye_chimpira_001', 'wave', 'dev'),
    ('dataset-1_byebye_feminine_001', 'wave', 'test'),
    ('dataset-1_byebye_giant_001', 'wave', 'dev'),
    ('dataset-1_byebye_happy_001', 'wave', 'test'),
    ('dataset-1_call_normal_001', 'gesture', 'dev'),
    ('dataset-1_call_normal_002', 'gesture', 'test'),
    ('dataset-1_dance-short_normal_001', 'dance', 'test'),
    ('dataset-1_dash_happy_001', 'run', 'dev'),
    ('dataset-1_dash_masculinity_001', 'run', 'test'),
    ('dataset-1_dash_musical_001', 'run', 'dev'),
    ('dataset-1_dash_not-confident_001', 'run', 'test'),
    ('dataset-1_dash_old_001', 'run', 'dev'),
    ('dataset-1_dash_proud_001', 'run', 'test'),
    ('dataset-1_dash_sad_001', 'run', 'dev'),
    ('dataset-1_dash_tired_001', 'run', 'test'),
    ('dataset-1_guide_sad_001', 'gesture', 'dev'),
    ('dataset-1_guide_tired_001', 'gesture', 'test'),
    ('dataset-1_guide_active_001', 'gesture', 'dev'),
    ('dataset-1_guide_angry_001', 'gesture', 'test'),
    ('dataset-1_guide_childish_001', 'gesture', 'dev'),
    ('dataset-1_guide_chimpira_001', 'gesture', 'test'),
    ('dataset-1_guide_feminine_001', 'gesture', 'dev'),
    ('dataset-1_guide_giant_001', 'gesture', 'test'),
    ('dataset-1_kick_normal_001', 'kick', 'dev'),
    ('dataset-1_punch_normal_001', 'punch', 'dev'),
    ('dataset-1_punch_normal_002', 'punch', 'test'),
    ('dataset-1_respond_normal_001', 'gesture', 'dev'),
    ('dataset-1_run_musical_001', 'run', 'dev'),
    ('dataset-1_run_not-confident_001', 'run', 'test'),
    ('dataset-1_run_old_001', 'run', 'dev'),
    ('dataset-1_run_proud_001', 'run', 'test'),
    ('dataset-1_run_sad_001', 'run', 'dev'),
    ('dataset-1_run_tired_001', 'run', 'test'),
    ('dataset-1_run_active_001', 'run', 'dev'),
    ('dataset-1_run_angry_001', 'run', 'test'),
    ('dataset-1_slash_normal_001', 'other', 'dev'),
    ('dataset-1_slash_normal_002', 'other', 'test'),
    ('dataset-1_walk_active_001', 'walk', 'dev'),
    ('dataset-1_walk_angry_001', 'walk', 'test'),
    ('dataset-1_walk_childish_001', 'walk', 'dev'),
    ('dataset-1_walk_chimpira_001', 'walk', 'test'),
    ('dataset-1_walk_feminine_001', 'walk', 'dev'),
    ('dataset-1_walk_giant_001', 'walk', 'test'),
    ('dataset-1_walk_happy_001', 'walk', 'dev'),
    ('dataset-1_walk_masculinity_001', 'walk', 'test'),
    ('dataset-1_walk_musical_001', 'walk', 'dev'),
    ('dataset-1_walk_normal_001', 'walk', 'test'),
    ('dataset-1_walk_not-confident_001', 'walk', 'dev'),
    ('dataset-1_walk_old_001', 'walk', 'test'),
    ('dataset-1_walk_proud_001', 'walk', 'dev'),
    ('dataset-1_walk_sad_001', 'walk', 'test'),
    ('dataset-1_walk_tired_001', 'walk', 'dev'),
    ('dataset-1_walk_active_002', 'walk', 'test'),
    ('dataset-1_walk_angry_002', 'walk', 'dev'),
    ('dataset-1_walk_childish_002', 'walk', 'test'),
    ('dataset-1_walk_chimpira_002', 'walk', 'dev'),
    ('dataset-1_walk_feminine_002', 'walk', 'test'),
    ('dataset-1_walk-back_angry_001', 'walk', 'dev'),
    ('dataset-1_walk-back_childish_001', 'walk', 'test'),
    ('dataset-1_walk-back_chimpira_001', 'walk', 'dev'),
    ('dataset-1_walk-back_feminine_001', 'walk', 'test'),
    ('dataset-1_walk-back_giant_001', 'walk', 'dev'),
    ('dataset-1_walk-back_happy_001', 'walk', 'test'),
    ('dataset-1_walk-back_masculinity_001', 'walk', 'dev'),
    ('dataset-1_walk-back_musical_001', 'walk', 'test'),
    ('dataset-1_walk-left_masculinity_001', 'walk', 'dev'),
    ('dataset-1_walk-left_musical_001', 'walk', 'test'),
    ('dataset-1_walk-left_normal_001', 'walk', 'dev'),
    ('dataset-1_walk-left_not-confident_001', 'walk', 'test'),
    ('dataset-1_walk-left_old_001', 'walk', 'dev'),
    ('dataset-1_walk-left_proud_001', 'walk', 'test'),
    ('dataset-1_walk-right_proud_001', 'walk', 'dev'),
    ('dataset-1_walk-right_sad_001', 'walk', 'test'),
    ('dataset-1_walk-right_tired_001', 'walk', 'dev'),
    ('dataset-1_walk-right_active_001', 'walk', 'test'),
    ('dataset-1_walk-right_angry_001', 'walk', 'dev'),
    ('dataset-1_walk-right_childish_001', 'walk', 'test'),
    ('dataset-2_walk-turn-left_elderly_001', 'turn', 'dev'),
    ('dataset-2_walk-turn-left_exhausted_001', 'turn', 'test'),
    ('dataset-2_walk-turn-left_feminine_001', 'turn', 'dev'),
    ('dataset-2_walk-turn-left_masculine_001', 'turn', 'test'),
    ('dataset-2_walk-turn-left_normal_001', 'turn', 'dev'),
    ('dataset-2_walk-turn-left_youthful_001', 'turn', 'test'),
    ('dataset-2_walk-turn-left_active_001', 'turn', 'dev'),
    ('dataset-2_walk-turn-left_elderly_002', 'turn', 'test'),
    ('dataset-2_walk-turn-left_exhausted_002', 'turn', 'dev'),
    ('dataset-2_walk-turn-left_feminine_002', 'turn', 'test'),
    ('dataset-2_walk-turn-left_masculine_002', 'turn', 'dev'),
    ('dataset-2_walk-turn-left_normal_002', 'turn', 'test'),
    ('dataset-2_walk-turn-right_youthful_001', 'turn', 'dev'),
    ('dataset-2_walk-turn-right_active_001', 'turn', 'test'),
    ('dataset-2_walk-turn-right_elderly_001', 'turn', 'dev'),
    ('dataset-2_walk-turn-right_exhausted_001', 'turn', 'test'),
    ('dataset-2_walk-turn-right_feminine_001', 'turn', 'dev'),
    ('dataset-2_walk-turn-right_masculine_001', 'turn', 'test'),
    ('dataset-2_walk-turn-right_normal_001', 'turn', 'dev'),
    ('dataset-2_walk-turn-right_youthful_002', 'turn', 'test'),
    ('dataset-2_walk-turn-right_active_002', 'turn', 'dev'),
    ('dataset-2_walk-turn-right_elderly_002', 'turn', 'test'),
    ('dataset-2_walk-turn-right_exhausted_002', 'turn', 'dev'),
    ('dataset-2_walk-turn-right_feminine_002', 'turn', 'test'),
    ('dataset-2_wave-both-hands_masculine_001', 'wave', 'dev'),
    ('dataset-2_wave-both-hands_normal_001', 'wave', 'test'),
    ('dataset-2_wave-both-hands_youthful_001', 'wave', 'dev'),
    ('dataset-2_wave-both-hands_active_001', 'wave', 'test'),
    ('dataset-2_wave-both-hands_elderly_001', 'wave', 'dev'),
    ('dataset-2_wave-both-hands_exhausted_001', 'wave', 'test'),
    ('dataset-2_wave-both-hands_feminine_001', 'wave', 'dev'),
    ('dataset-2_wave-both-hands_masculine_002', 'wave', 'test'),
    ('dataset-2_wave-both-hands_normal_002', 'wave', 'dev'),
    ('dataset-2_wave-both-hands_youthful_002', 'wave', 'test'),
    ('dataset-2_wave-both-hands_active_002', 'wave', 'dev'),
    ('dataset-2_wave-both-hands_elderly_002', 'wave', 'test'),
    ('dataset-2_wave-left-hand_active_001', 'wave', 'dev'),
    ('dataset-2_wave-left-hand_elderly_001', 'wave', 'test'),
    ('dataset-2_wave-left-hand_exhausted_001', 'wave', 'dev'),
    ('dataset-2_wave-left-hand_feminine_001', 'wave', 'test'),
    ('dataset-2_wave-left-hand_masculine_001', 'wave', 'dev'),
    ('dataset-2_wave-left-hand_normal_001', 'wave', 'test'),
    ('dataset-2_wave-left-hand_youthful_001', 'wave', 'dev'),
    ('dataset-2_wave-left-hand_active_002', 'wave', 'test'),
    ('dataset-2_wave-left-hand_elderly_002', 'wave', 'dev'),
    ('dataset-2_wave-left-hand_exhausted_002', 'wave', 'test'),
    ('dataset-2_wave-left-hand_feminine_002', 'wave', 'dev'),
    ('dataset-2_wave-left-hand_masculine_002', 'wave', 'test'),
    ('dataset-2_wave-right-hand_normal_001', 'wave', 'dev'),
    ('dataset-2_wave-right-hand_youthful_001', 'wave', 'test'),
    ('dataset-2_wave-right-hand_active_001', 'wave', 'dev'),
    ('dataset-2_wave-right-hand_elderly_001', 'wave', 'test'),
    ('dataset-2_wave-right-hand_exhausted_001', 'wave', 'dev'),
    ('dataset-2_wave-right-hand_feminine_001', 'wave', 'test'),
    ('dataset-2_wave-right-hand_masculine_001', 'wave', 'dev'),
    ('dataset-2_wave-right-hand_normal_002', 'wave', 'test'),
    ('dataset-2_wave-right-hand_youthful_002', 'wave', 'dev'),
    ('dataset-2_wave-right-hand_active_002', 'wave', 'test'),
    ('dataset-2_wave-right-hand_elderly_002', 'wave', 'dev'),
    ('dataset-2_wave-right-hand_exhausted_002', 'wave', 'test'),
    ('dataset-2_raise-up-both-hands_exhausted_001', 'reach', 'dev'),
    ('dataset-2_raise-up-both-hands_feminine_001', 'reach', 'test'),
    ('dataset-2_raise-up-both-hands_masculine_001', 'reach', 'dev'),
    ('dataset-2_raise-up-both-hands_normal_043', 'reach', 'test'),
    ('dataset-2_raise-up-both-hands_youthful_001', 'reach', 'dev'),
    ('dataset-2_raise-up-both-hands_elderly_001', 'reach', 'test'),
    ('dataset-2_raise-up-left-hand_normal_043', 'reach', 'dev'),
    ('dataset-2_raise-up-left-hand_youthful_002', 'reach', 'test'),
    ('dataset-2_raise-up-left-hand_elderly_001', 'reach', 'dev'),
    ('dataset-2_raise-up-left-hand_exhausted_001', 'reach', 'test'),
    ('dataset-2_raise-up-left-hand_feminine_009', 'reach', 'dev'),
    ('dataset-2_raise-up-left-hand_masculine_001', 'reach', 'test'),
    ('dataset-2_raise-up-right-hand_youthful_002', 'reach', 'dev'),
    ('dataset-2_raise-up-right-hand_elderly_001', 'reach', 'test'),
    ('dataset-2_raise-up-right-hand_exhausted_001', 'reach', 'dev'),
    ('dataset-2_raise-up-right-hand_feminine_001', 'reach', 'test'),
    ('dataset-2_raise-up-right-hand_masculine_001', 'reach', 'dev'),
    ('dataset-2_raise-up-right-hand_normal_024', 'reach', 'test'),
    ('dataset-2_run_elderly_001', 'run', 'dev'),
    ('dataset-2_run_exhausted_001', 'run', 'test'),
    ('dataset-2_run_feminine_001', 'run', 'dev'),
    ('dataset-2_run_masculine_001', 'run', 'test'),
    ('dataset-2_run_normal_001', 'run', 'dev'),
    ('dataset-2_run_youthful_001', 'run', 'test'),
    ('dataset-2_run_active_001', 'run', 'dev'),
    ('dataset-2_run_elderly_002', 'run', 'test'),
    ('dataset-2_run_exhausted_002', 'run', 'dev'),
    ('dataset-2_run_feminine_002', 'run', 'test'),
    ('dataset-2_run_masculine_002', 'run', 'dev'),
    ('dataset-2_run_normal_002', 'run', 'test'),
    ('dataset-2_walk_youthful_001', 'walk', 'dev'),
    ('dataset-2_walk_active_001', 'walk', 'test'),
    ('dataset-2_walk_elderly_001', 'walk', 'dev'),
    ('dataset-2_walk_exhausted_001', 'walk', 'test'),
    ('dataset-2_walk_feminine_001', 'walk', 'dev'),
    ('dataset-2_walk_masculine_001', 'walk', 'test'),
    ('dataset-2_walk_normal_001', 'walk', 'dev'),
    ('dataset-2_walk_youthful_002', 'walk', 'test'),
    ('dataset-2_walk_active_002', 'walk', 'dev'),
    ('dataset-2_walk_elderly_002', 'walk', 'test'),
    ('dataset-2_walk_exhausted_002', 'walk', 'dev'),
    ('dataset-2_walk_feminine_002', 'walk', 'test'),
    ('dataset-2_walk_masculine_002', 'walk', 'dev'),
    ('dataset-2_walk_normal_002', 'walk', 'test'),
    ('dataset-2_walk_youthful_003', 'walk', 'dev'),
    ('dataset-2_walk_active_003', 'walk', 'test'),
    ('dataset-2_walk_elderly_003', 'walk', 'dev'),
    ('dataset-2_walk_exhausted_003', 'walk', 'test'),
    ('dataset-2_walk_feminine_003', 'walk', 'dev'),
    ('dataset-2_walk_masculine_003', 'walk', 'test'),
    ('dataset-2_walk_normal_003', 'walk', 'dev'),
    ('dataset-2_walk_youthful_004', 'walk', 'test'),
    ('dataset-2_walk_active_004', 'walk', 'dev'),
    ('dataset-2_walk_elderly_004', 'walk', 'test'),
]])

CLIPS: tuple[Entry, ...] = tuple(DEEPMIMIC + CMU + REACTIDLE + BANDAI)


def cache_path(cache_dir: str | Path | None = None) -> Path:
    """The fetch cache folder (``DEFAULT_CACHE`` if None)."""
    return Path(cache_dir) if cache_dir is not None else DEFAULT_CACHE


def entry_path(entry: Entry, cache_dir: str | Path | None = None) -> Path:
    """Where ``entry``'s file lives: the committed data folder or the cache."""
    root = DATA_DIR if SOURCES[entry.source].committed else cache_path(cache_dir)
    return root / entry.source / entry.file


def load_clip(entry: Entry, cache_dir: str | Path | None = None, *,
              loop_s: float | None = None) -> MotionClip:
    """One catalogue entry as a ``MotionClip`` (30 Hz, body frame); ``loop_s`` see
    ``load_clips``. Clips are kept in memory per file (a suite run asks for the same clips
    many times); their ``positions`` are read-only for that reason."""
    path = entry_path(entry, cache_dir)
    if not path.is_file():
        msg = f'clip {entry.name}: file {path} is missing'
        raise MocapError(msg)
    stat = path.stat()
    return _load(entry, str(path.resolve()), stat.st_mtime_ns, stat.st_size, loop_s)


@functools.lru_cache(maxsize=512)
def _load(entry: Entry, path: str, _mtime_ns: int, _size: int,
          loop_s: float | None) -> MotionClip:
    src = SOURCES[entry.source]
    pos = src.load(Path(path), entry, loop_s)
    pos.flags.writeable = False
    return MotionClip(entry.name, entry.source, entry.family, entry.split, FPS, pos,
                      src.licence)


def load_clips(*, cache_dir: str | Path | None = None, committed_only: bool = False,
               names: Collection[str] | None = None,
               loop_s: float | None = None) -> list[MotionClip]:
    """Every committed clip, plus the fetched ones found in the cache (unless
    ``committed_only``), in table order; ``names`` keeps only those clips (``source/stem``).
    ``loop_s`` repeats the clips whose source file marks them as cycles (the short DeepMimic
    walks, runs, turns, ...) until they last that long; the statistics of the catalogue are
    measured without it. A committed file that is missing is an error; a fetched one that is
    missing is skipped (its source was not fetched)."""
    if names is not None:
        unknown = sorted(set(names) - {e.name for e in CLIPS})
        if unknown:
            msg = f'unknown clips {unknown}'
            raise MocapError(msg)
    out = []
    for entry in CLIPS:
        if names is not None and entry.name not in names:
            continue
        if not SOURCES[entry.source].committed:
            if committed_only or not entry_path(entry, cache_dir).is_file():
                continue
        out.append(load_clip(entry, cache_dir, loop_s=loop_s))
    return out


def stats(clips: list[MotionClip]) -> dict:
    """Clip counts and minutes in total and per source, family and split."""
    def group(key: Callable[[MotionClip], str]) -> dict[str, dict[str, float]]:
        out: dict[str, dict[str, float]] = {}
        for c in clips:
            g = out.setdefault(key(c), {'clips': 0, 'minutes': 0.0})
            g['clips'] += 1
            g['minutes'] += c.duration_s / 60.0
        return {k: {'clips': v['clips'], 'minutes': round(v['minutes'], 2)}
                for k, v in sorted(out.items())}

    return {
        'clips': len(clips),
        'minutes': round(sum(c.duration_s for c in clips) / 60.0, 2),
        'sources': group(lambda c: c.source),
        'families': group(lambda c: c.family),
        'splits': group(lambda c: c.split),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog='python -m endeff_ros.synth.mocap.catalogue',
        description='Print the mocap catalogue statistics (clips, minutes) as JSON.')
    parser.add_argument('--cache', default=None, help=f'fetch cache (default {DEFAULT_CACHE})')
    parser.add_argument('--committed-only', action='store_true',
                        help='only the committed clips')
    args = parser.parse_args(argv)
    try:
        clips = load_clips(cache_dir=args.cache, committed_only=args.committed_only)
    except MocapError as err:
        print(f'catalogue: {err}', file=sys.stderr)
        return 2
    print(json.dumps(stats(clips), indent=2))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
