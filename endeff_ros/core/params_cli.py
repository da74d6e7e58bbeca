"""``endeff params``: print the parameter table, or the ROS parameter YAML generated from it."""

from __future__ import annotations

import argparse
import textwrap
from typing import Any

from .params import PRESETS, EndeffParams, describe, to_ros_yaml

#: Longest line of the table: a terminal or a review diff shows it without wrapping.
WIDTH = 99
COLUMNS = ('name', 'symbol', 'default', 'unit', 'range')


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--yaml', action='store_true',
                        help='print config/endeff.yaml as generated from the dataclass')
    parser.add_argument('--preset', choices=sorted(PRESETS),
                        help='with --yaml: a named preset (config/endeff_<preset>.yaml)')


def run(args: argparse.Namespace) -> int:
    if args.yaml:
        params = EndeffParams(**PRESETS[args.preset]) if args.preset else None
        print(to_ros_yaml(params), end='')
        return 0
    print(format_table(describe()))
    return 0


def format_table(rows: list[dict[str, Any]], width: int = WIDTH) -> str:
    """The parameters as a table: a header row, one aligned row per parameter (columns as wide
    as their longest cell), its description wrapped below it, indented, within ``width``
    columns. Below rather than beside: beside the 33-character names a description column
    would be about 25 characters wide."""
    cells = [{'name': r['name'], 'symbol': r['symbol'] or '', 'default': str(r['default']),
              'unit': r['unit'] or '',
              'range': f'[{r["lo"]}, {r["hi"]}]' if r['lo'] is not None else ''}
             for r in rows]
    widths = {c: max(len(c), *(len(x[c]) for x in cells)) for c in COLUMNS}

    def line(values: dict[str, str]) -> str:
        return '  '.join(f'{values[c]:{widths[c]}}' for c in COLUMNS).rstrip()

    lines = [line({c: c for c in COLUMNS}), line({c: '-' * widths[c] for c in COLUMNS})]
    for row, x in zip(rows, cells, strict=True):
        lines.append(line(x))
        lines += textwrap.wrap(row['doc'], width, initial_indent='    ',
                               subsequent_indent='    ', break_on_hyphens=False)
    return '\n'.join(lines)
