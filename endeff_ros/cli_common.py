"""Option helpers shared by the ``endeff`` subcommands, below :mod:`endeff_ros.cli`.

Subcommand modules (``endeff_ros.bag.process``, ``endeff_ros.evaluate``...) import these from
here rather than from the top-level CLI, so that a lower layer never imports the entry point.

Exit statuses, the same for every ``endeff`` command (a script can tell what went wrong
without reading the message, which is always one line on stderr naming what is wrong):

- 0 (:data:`EXIT_OK`): everything asked was done;
- 1 (:data:`EXIT_FAILED`): the work began and part of it failed (a bag that cannot be read, a
  sequence that failed, an output that could not be written); the rest was done;
- 2 (:data:`EXIT_USAGE`): refused before any work, as argparse does for bad options: an
  unusable option value (``--jobs 0``), an input path that does not exist or holds no bag,
  an output that cannot be written, a parameter file that cannot be loaded;
- 130 (:data:`EXIT_SIGINT`): interrupted by Ctrl-C (SIGINT), 143 (:data:`EXIT_SIGTERM`):
  by SIGTERM; the unfinished outputs are removed and no worker process is left.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_USAGE = 2
EXIT_SIGINT = 130
EXIT_SIGTERM = 143


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised (by :func:`raise_terminated`) where the main thread runs, so that the
    same cleanup as for Ctrl-C's KeyboardInterrupt runs; exit status 143 instead of 130."""


def interruption(err: BaseException | None) -> KeyboardInterrupt | None:
    """The Ctrl-C or SIGTERM (:class:`Terminated`) that ``err`` was raised from, or None: a
    signal taken while an extension module initialises reaches the caller as
    ``ImportError('initialization failed')`` caused by it, which must end the command, not
    be reported as a failed bag."""
    seen: set[int] = set()
    while err is not None and id(err) not in seen:
        if isinstance(err, KeyboardInterrupt):
            return err
        seen.add(id(err))
        err = err.__cause__ or err.__context__
    return None


def raise_terminated(signum: int, _frame: Any) -> None:
    """A SIGTERM handler: raise :class:`Terminated`."""
    raise Terminated(signum)


def positive_int(text: str) -> int:
    """argparse ``type`` of a count that must be at least 1 (``--jobs``): ``--jobs 0`` or
    ``-3`` is refused with a usage error (status 2) instead of silently meaning something."""
    try:
        value = int(text)
    except ValueError:
        msg = f'expected a whole number >= 1, got {text!r}'
        raise argparse.ArgumentTypeError(msg) from None
    if value < 1:
        msg = f'must be at least 1, got {value}'
        raise argparse.ArgumentTypeError(msg)
    return value


def usage_error(prog: str, message: str) -> SystemExit:
    """Print ``prog: message`` on stderr; the SystemExit (status 2) for the caller to raise."""
    print(f'{prog}: {message}', file=sys.stderr)
    return SystemExit(EXIT_USAGE)


def os_error_text(err: OSError) -> str:
    """One line for an OSError: the path(s) it names and the problem, without the errno."""
    names = [str(n) for n in (err.filename, err.filename2) if n is not None]
    problem = err.strerror or str(err) or type(err).__name__
    return f'{" -> ".join(names)}: {problem}' if names else problem


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
        raise usage_error(prog, f'cannot load parameters {path}: {err}') from err
