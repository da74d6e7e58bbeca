"""The ``endeff`` command: one entry point, one subcommand module each.

Subcommands register themselves in ``SUBCOMMANDS`` as ``name -> 'module:function'``; the module
is imported only when that subcommand runs, so ``endeff synth`` never imports rclpy and
``endeff --help`` stays fast. Each module provides ``add_arguments(parser)`` and
``run(args) -> int`` (the exit status: :mod:`endeff_ros.cli_common` lists them).

An OSError that a subcommand did not handle (an output that became unwritable while it ran, a
disk that filled up) ends the command with one line naming the path and the problem, status 1,
instead of a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import signal
import sys
import threading
from typing import Any

from endeff_ros.cli_common import (
    EXIT_FAILED,
    EXIT_SIGINT,
    EXIT_SIGTERM,
    EXIT_USAGE,
    Terminated,
    os_error_text,
    raise_terminated,
)

SUBCOMMANDS: dict[str, tuple[str, str]] = {
    'synth': ('endeff_ros.synth.cli', 'Generate synthetic RGB-D benchmark bags.'),
    'sheet': ('endeff_ros.synth.sheet', 'Draw a contact sheet (PNG) of benchmark bags.'),
    'eval': ('endeff_ros.evaluate', 'Score single-frame and temporal estimators on bags.'),
    'process': ('endeff_ros.bag.process', 'Run the tracker on rosbag2 bags, write results.'),
    'play': ('endeff_ros.bag.play', 'Publish a bag over DDS with its /clock, for a running node.'),
    'params': ('endeff_ros.core.params_cli', 'Print the parameter table or config YAML.'),
    'mocap-fetch': ('endeff_ros.synth.mocap.fetch',
                    'Copy motion-capture clips of one source into the local cache.'),
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='endeff', description='endeff_ros tools: end-effectors of people and articulated '
        'entities in RGB-D data (Lin, Pardas & Casas, 2016). `endeff COMMAND -h` for help.')
    sub = parser.add_subparsers(dest='command', metavar='COMMAND', required=True)
    for name, (_, helptext) in SUBCOMMANDS.items():
        sub.add_parser(name, help=helptext, add_help=False)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    if not argv or argv[0] not in SUBCOMMANDS:
        parser.parse_args(argv)  # prints usage / error and exits
        return EXIT_USAGE
    name, rest = argv[0], argv[1:]
    module = importlib.import_module(SUBCOMMANDS[name][0])
    sub = argparse.ArgumentParser(prog=f'endeff {name}', description=SUBCOMMANDS[name][1])
    module.add_arguments(sub)
    args = sub.parse_args(rest)
    # SIGTERM (a `timeout`, a supervisor) unwinds like Ctrl-C: a command's workers are
    # stopped and its partial outputs removed, instead of the process dying around them.
    previous = _on_sigterm(raise_terminated)
    try:
        return int(module.run(args) or 0)
    except KeyboardInterrupt as err:
        print(f'endeff {name}: interrupted', file=sys.stderr)
        return EXIT_SIGTERM if isinstance(err, Terminated) else EXIT_SIGINT
    except BrokenPipeError:  # stdout read by `head` or a pager that quit: not an error to report
        _silence_stdout()
        return EXIT_FAILED
    except OSError as err:
        print(f'endeff {name}: {os_error_text(err)}', file=sys.stderr)
        return EXIT_FAILED
    finally:
        _on_sigterm(previous)


def _silence_stdout() -> None:
    """Point stdout at /dev/null, so that flushing it at exit does not raise BrokenPipeError
    again (the recipe of Python's signal documentation)."""
    import os

    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)


def _on_sigterm(handler: Any) -> Any:
    """Install ``handler`` for SIGTERM and return the previous one; None where no handler can
    be installed (not the main thread) or ``handler`` is None."""
    if handler is None or threading.current_thread() is not threading.main_thread():
        return None
    return signal.signal(signal.SIGTERM, handler)


if __name__ == '__main__':
    sys.exit(main())
