"""``endeff params``: the parameter table is readable (header, aligned columns, wrapped
descriptions, short lines) and complete."""

from __future__ import annotations

import pytest

from endeff_ros.cli import main as cli_main
from endeff_ros.core.params import describe

COLUMNS = ['name', 'symbol', 'default', 'unit', 'range']
WIDTH = 100  # a terminal or a review diff shows the lines without wrapping


def test_table_has_a_header_aligned_columns_and_short_lines(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert cli_main(['params']) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split() == COLUMNS
    assert set(lines[1]) == {'-', ' '}
    assert max(map(len, lines)) <= WIDTH
    starts = [lines[0].index(c) for c in COLUMNS]
    rows = {line.split()[0]: line for line in lines[2:] if not line.startswith(' ')}
    params = describe()
    assert list(rows) == [p['name'] for p in params]  # one row per parameter, in order
    for p in params:
        row = rows[p['name']]
        # Each cell starts under its heading (the widest name used to push a row out of line).
        assert row[starts[2]:].split()[0] == str(p['default']), row
        assert row[starts[2] - 2:starts[2]] == '  ', row
        if p['lo'] is not None:
            assert row[starts[4]:] == f'[{p["lo"]}, {p["hi"]}]', row


def test_every_description_is_wrapped_whole_below_its_row(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert cli_main(['params']) == 0
    lines = capsys.readouterr().out.splitlines()[2:]
    docs: dict[str, list[str]] = {}
    name = ''
    for line in lines:
        if line.startswith('    '):
            docs[name].append(line.strip())
        else:
            name = line.split()[0]
            docs[name] = []
    for p in describe():
        assert ' '.join(docs[p['name']]) == ' '.join(p['doc'].split()), p['name']
    assert any(len(d) > 1 for d in docs.values())  # long descriptions do wrap
