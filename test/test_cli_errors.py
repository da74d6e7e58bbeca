"""Bad command lines of every ``endeff`` command: one line on stderr naming what is wrong, no
traceback, and the same exit status for the same kind of error in every command
(:mod:`endeff_ros.cli_common`: 2 before any work, 1 when part of the work failed)."""

from __future__ import annotations

import errno
from pathlib import Path

import pytest
from bag_helpers import BagSpec, write_bag

from endeff_ros.bag import outputs
from endeff_ros.cli import main as cli_main


def _run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """``endeff ARGV`` in this process: (status, stdout, stderr); argparse's exit included."""
    try:
        status = cli_main(argv)
    except SystemExit as exc:
        status = exc.code if isinstance(exc.code, int) else 1
    cap = capsys.readouterr()
    return status, cap.out, cap.err


@pytest.fixture(scope='module')
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp('in') / 'bag'
    write_bag(path, BagSpec(frames=3))
    return path


@pytest.mark.parametrize('value', ['0', '-3', 'two'])
@pytest.mark.parametrize('command', ['process', 'eval', 'synth'])
def test_jobs_below_one_is_refused(tmp_path: Path, bag: Path, command: str, value: str,
                                   capsys: pytest.CaptureFixture[str]) -> None:
    argv = {'process': ['process', str(bag), '-o', str(tmp_path / 'out')],
            'eval': ['eval', str(bag)],
            'synth': ['synth', '--out', str(tmp_path / 'synth'), '--quick']}[command]
    status, out, err = _run([*argv, '--jobs', value], capsys)
    assert status == 2, err
    assert err.strip().splitlines()[-1].startswith(f'endeff {command}: error: argument --jobs')
    assert 'Traceback' not in err and out == ''
    assert list(tmp_path.iterdir()) == []  # refused before any work


@pytest.mark.parametrize('command', ['process', 'eval'])
def test_missing_input_is_one_line_and_status_2(tmp_path: Path, bag: Path, command: str,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    missing = tmp_path / 'nowhere'
    argv = [command, str(bag), str(missing)]
    if command == 'process':
        argv += ['-o', str(tmp_path / 'out')]
    status, out, err = _run(argv, capsys)
    assert status == 2
    assert err.splitlines() == [f'endeff {command}: {missing}: no such file or directory']
    assert out == ''  # no empty score table
    assert not (tmp_path / 'out').exists()


def _outputs(tmp_path: Path, bag: Path, blocked: Path) -> list[tuple[str, list[str]]]:
    """(command, argv) with an output below ``blocked``, one per output option."""
    target = str(blocked / 'x')
    return [('process', ['process', str(bag), '-o', target]),
            ('eval', ['eval', str(bag), '--json', target + '.json']),
            ('eval', ['eval', str(bag), '--plots', target]),
            ('synth', ['synth', '--out', target, '--quick', '--only', 'clapping',
                       '--jobs', '1'])]


def test_output_below_a_file_is_one_line(tmp_path: Path, bag: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    blocked = tmp_path / 'afile'
    blocked.write_text('not a folder')
    for command, argv in _outputs(tmp_path, bag, blocked):
        status, out, err = _run(argv, capsys)
        assert status == 2, (argv, err)
        assert len(err.splitlines()) == 1 and err.startswith(f'endeff {command}: output '), err
        assert str(blocked) in err and 'is a file, not a directory' in err, err
        assert out == ''


def test_unwritable_output_folder_is_one_line(tmp_path: Path, bag: Path,
                                              monkeypatch: pytest.MonkeyPatch,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    """A folder the user may not write in (simulated: the tests may run as root)."""
    def refuse(*_a: object, **_k: object) -> None:
        raise PermissionError(errno.EACCES, 'Permission denied')

    monkeypatch.setattr(outputs.tempfile, 'mkstemp', refuse)
    for command, argv in _outputs(tmp_path, bag, tmp_path / 'ro'):
        status, out, err = _run(argv, capsys)
        assert status == 2, (argv, err)
        assert err.splitlines() == [err.strip()] and 'Permission denied' in err, err
        assert err.startswith(f'endeff {command}: output {tmp_path / "ro"}'), err


def test_an_output_error_while_writing_is_one_line(tmp_path: Path, bag: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """An OSError a command does not handle itself (here ``endeff sheet``, whose output is
    not checked first) ends it with one line naming the path, status 1 (the work had
    begun)."""
    blocked = tmp_path / 'afile'
    blocked.write_text('not a folder')
    status, out, err = _run(['sheet', str(bag), '--out', str(blocked / 'sheet.png')], capsys)
    assert status == 1, err
    assert len(err.splitlines()) == 1 and err.startswith(f'endeff sheet: {blocked}'), err
    assert 'Traceback' not in err
