"""The mocap and rooms suites draw and name a clip's bags from the clip alone: a machine with
only the committed clips lists them exactly as one with the fetched cache does."""

from __future__ import annotations

import argparse

import pytest

from endeff_ros.synth import cli as synth_cli
from endeff_ros.synth.cases import suite_specs
from endeff_ros.synth.mocap.catalogue import CLIPS, SOURCES, entry_path, load_clips
from endeff_ros.synth.mocap.clip import MotionClip
from endeff_ros.synth.proc_clips import sit_clip, walk_clip, wave_clip
from endeff_ros.synth.rooms_suite import (
    FULL_PANS,
    PAN_BAG_S,
    PAN_CLIPS,
    PAN_FAMILIES,
    _spread,
    pan_pool,
)
from endeff_ros.synth.suite import FPS, catalogue_index, resampled


def _stand_in(entry) -> MotionClip:
    """A procedural clip under a fetched catalogue entry's name, family and split (the
    cache itself is not in the repository)."""
    make = {'walk': walk_clip, 'run': walk_clip, 'sit': sit_clip}.get(entry.family, wave_clip)
    proc = make(60)
    return MotionClip(entry.name, entry.source, entry.family, entry.split, proc.fps,
                      proc.positions)


@pytest.fixture(scope='module')
def committed():
    return load_clips(committed_only=True, loop_s=synth_cli.LOOP_S)


@pytest.fixture(scope='module')
def fetched():
    return [_stand_in(e) for e in CLIPS if not SOURCES[e.source].committed]


def _listing(monkeypatch, capsys, clips, suite: str = 'mocap') -> list[str]:
    monkeypatch.setattr(synth_cli, 'load_suite_clips', lambda quick, cache: list(clips))
    parser = argparse.ArgumentParser()
    synth_cli.add_arguments(parser)
    assert synth_cli.run(parser.parse_args(['--suite', suite, '--list'])) == 0
    return capsys.readouterr().out.splitlines()[:-1]


def test_committed_bags_list_the_same_with_or_without_the_cache(monkeypatch, capsys,
                                                                committed, fetched):
    alone = _listing(monkeypatch, capsys, committed)
    cached = _listing(monkeypatch, capsys, committed + fetched)
    committed_names = {c.name.replace('/', '-') for c in committed}

    def of_committed(lines):
        return [line for line in lines if line.split('__')[1] in committed_names]

    assert len(cached) > len(alone) >= len(committed)
    assert of_committed(alone) == of_committed(cached)
    # The comparison compared something: ordinary bags and the still and slow ones.
    assert {'"case": "segment"', '"motion": "still"', '"motion": "slow"'} <= {
        part for line in of_committed(alone) for part in
        ('"case": "segment"', '"motion": "still"', '"motion": "slow"') if part in line}
    # With the cache, multi-person bags exist; their first person is a fetched clip.
    assert any('"people": 2' in line for line in cached)


def test_the_bag_index_is_the_catalogue_position(committed, fetched):
    everything = sorted(e.name for e in CLIPS)
    index = catalogue_index(committed)
    assert [index[n] for n in everything] == list(range(len(everything)))
    specs = {s.people[0].clip: s for s in suite_specs(committed)
             if len(s.people) == 1 and s.attributes['case'] == 'segment'}
    for clip in committed:
        assert f'__{everything.index(clip.name):03d}-' in specs[clip.name].name
    # A clip outside the catalogue follows it, whatever else is loaded.
    extra = walk_clip(40, name='zz_extra')
    assert catalogue_index([extra])['zz_extra'] == len(everything)
    assert catalogue_index(committed + [extra])['zz_extra'] == len(everything)


def test_a_multi_person_bag_keeps_its_own_draw_when_partners_change(fetched):
    full = [s for s in suite_specs(fetched) if len(s.people) > 1]
    fewer_clips = [c for k, c in enumerate(fetched) if k % 3 or c.name in
                   {s.people[0].clip for s in full}]
    fewer = {s.name: s for s in suite_specs(fewer_clips) if len(s.people) > 1}
    assert full and set(fewer) == {s.name for s in full}
    for spec in full:
        other = fewer[spec.name]
        assert other.people[0] == spec.people[0]
        assert (other.sensor, other.room, other.frames) == (spec.sensor, spec.room,
                                                            spec.frames)


def test_committed_rooms_pairs_list_the_same_with_or_without_the_cache(monkeypatch, capsys,
                                                                      committed, fetched):
    alone = _listing(monkeypatch, capsys, committed, 'rooms')
    cached = _listing(monkeypatch, capsys, committed + fetched, 'rooms')
    committed_names = {c.name.replace('/', '-') for c in committed}
    # Alone, the committed clips' pairs only, each line (name, number, attributes) as in the
    # listing with the cache: no pair moves to a committed clip when fetched ones are missing.
    assert alone == [line for line in cached if line.split('__')[1] in committed_names]
    assert len(cached) > len(alone)
    static = [line for line in alone if '"case": "segment"' in line]
    assert static and all('"camera": "static"' in line for line in static)
    assert any('"motion": "still"' in line for line in alone)
    assert any('"motion": "slow"' in line for line in alone)
    # The pan pairs are those of PAN_CLIPS (fetched clips) and exist with the cache only.
    pans = {line.split('__')[1] for line in cached if '"camera": "pan"' in line}
    assert pans == {n.replace('/', '-') for names in PAN_CLIPS.values() for n in names}


def _cache_complete() -> bool:
    return all(entry_path(e).is_file() for e in CLIPS)


@pytest.mark.skipif(not _cache_complete(), reason='needs the whole fetched clip cache')
def test_the_fixed_pan_clips_are_the_spread_of_the_clips_that_stay_in_place():
    clips = load_clips(names={e.name for e in CLIPS if e.family in PAN_FAMILIES},
                       loop_s=synth_cli.LOOP_S)
    pos = {c.name: resampled(c) for c in clips}
    for split, names in PAN_CLIPS.items():
        pool = sorted((c for c in clips if c.split == split), key=lambda c: (c.family, c.name))
        chosen = _spread(pan_pool(pool, pos, round(PAN_BAG_S * FPS)), FULL_PANS)
        assert tuple(c.name for c in chosen) == names
