"""Option helpers shared by the ``endeff`` subcommands, below :mod:`endeff_ros.cli`.

Subcommand modules (``endeff_ros.bag.process``, ``endeff_ros.evaluate``...) import these from
here rather than from the top-level CLI, so that a lower layer never imports the entry point.
"""

from __future__ import annotations

import json
import sys
from typing import Any


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised (by :func:`raise_terminated`) where the main thread runs, so that the
    same cleanup as for Ctrl-C's KeyboardInterrupt runs; exit status 143 instead of 130."""


def raise_terminated(signum: int, _frame: Any) -> None:
    """A SIGTERM handler: raise :class:`Terminated`."""
    raise Terminated(signum)


def print_json(data: Any, path: str | None = None) -> None:
    """Print ``data`` as indented JSON; also write it to ``path`` when given."""
    text = json.dumps(data, indent=2, default=float)
    print(text)
    if path:
        with open(path, 'w', encoding='utf-8') as fh:
            fh.write(text + '\n')


def load_params_option(path: str | None, prog: str) -> Any:
    """The ``--params YAML`` option of a command: the parameter set, or None for defaults.

    A file that cannot be read or holds bad parameters ends the command with status 2 and a
    message naming the file.
    """
    if not path:
        return None
    from endeff_ros.core.errors import EndeffError
    from endeff_ros.core.params import load_yaml

    try:
        return load_yaml(path)
    except (OSError, EndeffError) as err:
        print(f'{prog}: cannot load parameters {path}: {err}', file=sys.stderr)
        raise SystemExit(2) from err
