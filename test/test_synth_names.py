"""The mocap suite draws and names a clip's bags from the clip alone: a machine with only the
committed clips lists them exactly as one with the fetched cache does."""

from __future__ import annotations

import argparse

import pytest

from endeff_ros.synth import cli as synth_cli
from endeff_ros.synth.cases import suite_specs
from endeff_ros.synth.mocap.catalogue import CLIPS, SOURCES, load_clips
from endeff_ros.synth.mocap.clip import MotionClip
from endeff_ros.synth.proc_clips import sit_clip, walk_clip, wave_clip
from endeff_ros.synth.suite import catalogue_index


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


def _listing(monkeypatch, capsys, clips) -> list[str]:
    monkeypatch.setattr(synth_cli, 'load_suite_clips', lambda quick, cache: list(clips))
    parser = argparse.ArgumentParser()
    synth_cli.add_arguments(parser)
    assert synth_cli.run(parser.parse_args(['--suite', 'mocap', '--list'])) == 0
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
