"""tools.fingerprint: per-frame hashes of what the estimators publish, and their comparison."""

from __future__ import annotations

import dataclasses

import pytest

from endeff_ros.core.params import EndeffParams
from tools import fingerprint


def test_the_same_code_gives_the_same_fingerprint(room_bag):
    bag, _ = room_bag
    a = fingerprint.fingerprint_bag(bag)
    b = fingerprint.fingerprint_bag(bag)
    assert a == b
    assert a['frames'] == len(a['frame_hashes']) > 10
    assert len(set(a['frame_hashes'])) > 1  # frames publish different things


def test_a_change_in_what_is_published_is_found_at_its_first_frame(room_bag):
    bag, _ = room_bag
    old = {'bags': [fingerprint.fingerprint_bag(bag)]}
    one_end = dataclasses.replace(EndeffParams(), max_end_effectors=1)
    new = {'bags': [fingerprint.fingerprint_bag(bag, one_end)]}
    status, lines = fingerprint.compare(old, new)
    assert status == 1
    first = next(i for i, (x, y) in enumerate(zip(old['bags'][0]['frame_hashes'],
                                                   new['bags'][0]['frame_hashes'])) if x != y)
    assert lines[0] == (f'{bag.name}: differs from frame {first} on '
                        f'({old["bags"][0]["frames"]} / {new["bags"][0]["frames"]} frames)')
    assert lines[-1] == '0 of 1 bags identical'
    assert fingerprint.compare(old, old) == (0, ['1 of 1 bags identical'])


def test_a_track_moved_by_a_micrometre_changes_the_hash():
    track = type('T', (), {'id': 3, 'state': 0, 'position': [0.1, 0.2, 2.0]})
    moved = type('T', (), {'id': 3, 'state': 0, 'position': [0.1, 0.2, 2.000001]})
    renamed = type('T', (), {'id': 4, 'state': 0, 'position': [0.1, 0.2, 2.0]})
    base = fingerprint._frame_hash([track], [[0.1, 0.2, 2.0]])
    assert fingerprint._frame_hash([moved], [[0.1, 0.2, 2.0]]) != base
    assert fingerprint._frame_hash([renamed], [[0.1, 0.2, 2.0]]) != base
    assert fingerprint._frame_hash(None, [[0.1, 0.2, 2.0]]) != base  # rejected frame
    assert fingerprint._frame_hash([track], [[0.1, 0.2, 2.0]]) == base


def test_command_line_compare_exit_status(room_bag, tmp_path, capsys):
    bag, _ = room_bag
    report = tmp_path / 'old.json'
    assert fingerprint.main([str(bag), '--json', str(report)]) == 0
    assert fingerprint.main([str(bag), '--compare', str(report)]) == 0
    assert '1 of 1 bags identical' in capsys.readouterr().out
    params = tmp_path / 'one.yaml'
    params.write_text('max_end_effectors: 1\n')
    assert fingerprint.main([str(bag), '--params', str(params), '--compare', str(report)]) == 1
    assert 'differs from frame' in capsys.readouterr().out
    assert fingerprint.main([str(bag), '--compare', str(tmp_path / 'missing.json')]) == 2
    assert 'cannot read' in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:  # argparse: --compare needs its report
        fingerprint.main([str(bag), '--compare'])
    assert exc.value.code == 2
    assert '--compare' in capsys.readouterr().err


def test_a_corrupt_bag_is_named_and_never_counted_identical(room_bag, tmp_path, capsys):
    bag, _ = room_bag
    broken = tmp_path / 'broken.mcap'
    broken.write_bytes(b'\x89MCAP0\r\n not a bag')
    assert fingerprint.main([str(broken), '--json', str(tmp_path / 'b.json')]) == 2
    assert 'broken.mcap' in capsys.readouterr().err
    entry = fingerprint.fingerprint_bag(broken)
    assert entry['digest'] is None and entry['error']
    status, lines = fingerprint.compare({'bags': [entry]}, {'bags': [entry]})
    assert status == 2
    assert lines[-1] == '0 of 1 bags identical'
    good = fingerprint.fingerprint_bag(bag)
    assert fingerprint.compare({'bags': [good, entry]}, {'bags': [good, entry]})[0] == 2
