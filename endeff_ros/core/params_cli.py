"""``endeff params``: print the parameter table, or the ROS parameter YAML generated from it."""

from __future__ import annotations

import argparse

from .params import PRESETS, EndeffParams, describe, to_ros_yaml


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
    for row in describe():
        rng = f'[{row["lo"]}, {row["hi"]}]' if row['lo'] is not None else ''
        print(f'{row["name"]:24} {row["symbol"]:5} {row["default"]!s:10} {row["unit"]:4} '
              f'{rng:18} {row["doc"]}')
    return 0
