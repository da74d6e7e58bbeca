"""Output paths of ``endeff process`` / ``endeff eval``: checked first, never clobbered, and
nothing half-written left behind (disk full, SIGINT, SIGTERM, SIGKILL of an earlier run)."""

from __future__ import annotations

import errno
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
from bag_helpers import BagSpec, FakeTracker, storage_file, write_bag

from endeff_ros.bag import outputs
from endeff_ros.bag.errors import BagError
from endeff_ros.bag.outputs import OutputError, check_output_option, check_output_path
from endeff_ros.bag.process import OUTPUT_TOPICS, process_bag
from endeff_ros.cli import main as cli_main

TEST_DIR = Path(__file__).resolve().parent


def _leftovers(root: Path) -> list[str]:
    return sorted(p.name for p in root.rglob('.*partial*'))


def test_check_output_path_problems(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / 'afile').write_text('x')
    with pytest.raises(OutputError, match='afile is a file, not a directory'):
        check_output_path(tmp_path / 'afile' / 'out')
    with pytest.raises(OutputError, match='exists and is a file'):
        check_output_path(tmp_path / 'afile', force=True)
    with pytest.raises(OutputError, match=r'exists \(use --force'):
        check_output_path(tmp_path / 'afile')
    # New folders below an existing writable one are fine; nothing is created by the check.
    assert check_output_path(tmp_path / 'a' / 'b' / 'out') == tmp_path / 'a' / 'b' / 'out'
    assert not (tmp_path / 'a').exists()
    with pytest.raises(OutputError, match='is a directory'):
        check_output_path(tmp_path, kind='file')
    check_output_path(tmp_path / 'afile', kind='file')  # a report is overwritten

    def refuse(*_a: object, **_k: object) -> None:
        raise PermissionError(errno.EACCES, 'Permission denied')

    monkeypatch.setattr(outputs.shutil, 'disk_usage', lambda _p: SimpleNamespace(free=512))
    with pytest.raises(OutputError, match=r'no space left on device \(512 bytes free'):
        check_output_path(tmp_path / 'new')
    monkeypatch.undo()
    monkeypatch.setattr(outputs.tempfile, 'mkstemp', refuse)
    with pytest.raises(OutputError, match='cannot write in .*Permission denied'):
        check_output_path(tmp_path / 'new.json', kind='file')


def test_force_replaces_only_earlier_outputs(tmp_path: Path) -> None:
    src = tmp_path / 'in'
    write_bag(src, BagSpec(frames=3))
    ours = tmp_path / 'ours'
    process_bag(src, ours, tracker_factory=FakeTracker)
    assert outputs.is_own_bag(ours) and not outputs.is_own_bag(src, OUTPUT_TOPICS)
    check_output_path(ours, force=True, own_topics=OUTPUT_TOPICS)
    with pytest.raises(OutputError, match='not a bag written by endeff process'):
        check_output_path(src, force=True, own_topics=OUTPUT_TOPICS)  # a recording
    single = storage_file(src)
    check_output_path(single, force=True)  # a bag file
    with pytest.raises(OutputError, match='is or contains the input'):
        check_output_path(tmp_path, force=True, inputs=[src])
    empty = tmp_path / 'empty'
    empty.mkdir()
    check_output_path(empty, force=True)


def test_check_output_option_is_one_line_and_status_2(tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]
                                                      ) -> None:
    (tmp_path / 'afile').write_text('x')
    with pytest.raises(SystemExit) as info:
        check_output_option(str(tmp_path / 'afile' / 'report.json'), 'endeff eval')
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and err.startswith('endeff eval: output ')
    check_output_option(None, 'endeff eval')
    check_output_option(str(tmp_path / 'report.json'), 'endeff eval')


def test_cli_output_problems_before_any_work(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    from endeff_ros.bag.reader import BagReader

    src = tmp_path / 'in'
    write_bag(src, BagSpec(frames=3))
    (tmp_path / 'afile').write_text('x')

    def no_work(*_a: object, **_k: object) -> None:
        raise AssertionError('a bag was read before the outputs were checked')

    monkeypatch.setattr(BagReader, 'records', no_work)
    for out, pattern in [(tmp_path / 'afile' / 'out', 'is a file, not a directory'),
                         (tmp_path / 'afile', 'exists'), (src, 'input')]:
        assert cli_main(['process', str(src), '-o', str(out), '--force']) == 2
        err = capsys.readouterr().err
        assert pattern in err and err.count('\n') == 1 and 'Traceback' not in err


def test_disk_full_while_writing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                 capsys: pytest.CaptureFixture[str]) -> None:
    from rosbags.rosbag2 import Writer

    import endeff_ros.core.tracker as tracker_mod

    src = tmp_path / 'in'
    write_bag(src, BagSpec(frames=4))
    calls = []

    def full(self: object, *args: object) -> None:
        calls.append(args)
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(Writer, 'write', full)
    with pytest.raises(BagError, match='no space left on device'):
        process_bag(src, tmp_path / 'out', tracker_factory=FakeTracker)
    assert calls and sorted(p.name for p in tmp_path.iterdir()) == ['in']
    monkeypatch.setattr(tracker_mod, 'Tracker', FakeTracker)
    assert cli_main(['process', str(src), '-o', str(tmp_path / 'out')]) == 1
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and 'no space left on device' in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ['in']


def test_stale_partials_of_killed_runs_are_swept(tmp_path: Path) -> None:
    src = tmp_path / 'in'
    write_bag(src, BagSpec(frames=3))
    dead = subprocess.run([sys.executable, '-c', 'import os; print(os.getpid())'],
                          capture_output=True, text=True, check=True)
    stale = outputs.partial_dir(tmp_path / 'out', int(dead.stdout))
    (stale / 'out').mkdir(parents=True)
    alive = outputs.partial_dir(tmp_path / 'out', os.getppid())  # a live process: kept
    alive.mkdir()
    other = outputs.partial_dir(tmp_path / 'other', int(dead.stdout))  # another output
    other.mkdir()
    process_bag(src, tmp_path / 'out', tracker_factory=FakeTracker)
    assert not stale.exists() and alive.exists() and other.exists()
    assert (tmp_path / 'out' / 'metadata.yaml').is_file()


_SLOW_RUN = """
import sys, time
sys.path.insert(0, {test_dir!r})
from bag_helpers import FakeTracker
import endeff_ros.core.tracker as t

class Slow(FakeTracker):
    def update(self, frame):
        time.sleep(0.05)
        return super().update(frame)

t.Tracker = Slow
if __name__ == '__main__':
    from endeff_ros.cli import main
    sys.exit(main(sys.argv[1:]))
"""


def _slow_endeff(tmp_path: Path) -> list[str]:
    """The command line of ``endeff`` with a slow fake tracker. A script file, not ``-c``: the
    spawned workers run its top level again (as ``__mp_main__``), so they get the patch too."""
    script = tmp_path / 'slow_endeff.py'
    script.write_text(_SLOW_RUN.format(test_dir=str(TEST_DIR)), encoding='utf-8')
    return [sys.executable, str(script)]


@pytest.mark.parametrize(('sig', 'status', 'jobs'), [(signal.SIGINT, 130, 1),
                                                     (signal.SIGTERM, 143, 1),
                                                     (signal.SIGTERM, 143, 2)])
def test_interrupt_leaves_nothing(tmp_path: Path, sig: int, status: int, jobs: int) -> None:
    """SIGINT/SIGTERM mid-run: the unfinished outputs vanish, no hidden partial dirs stay."""
    ins = []
    for k in range(jobs):
        ins.append(tmp_path / 'in' / f'bag{k}')
        write_bag(ins[-1], BagSpec(frames=120, width=32, height=24, fx=10.0, blob_px=1))
    out = tmp_path / 'out'
    # A shell starts background jobs with SIGINT ignored, and Python then installs no handler
    # for it: the child gets the default disposition back, as a terminal's process has.
    proc = subprocess.Popen([*_slow_endeff(tmp_path), 'process', *map(str, ins), '-o',
                             str(out), '--jobs', str(jobs)], stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 60
    parent = out.parent if jobs == 1 else out
    while len(_leftovers(parent)) < jobs and time.monotonic() < deadline:
        time.sleep(0.05)
    assert len(_leftovers(parent)) == jobs, 'the run never started writing'
    time.sleep(0.3)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == status, err
    assert 'interrupted' in err and 'Traceback' not in err
    assert _leftovers(tmp_path) == []
    assert not out.exists() or not any(out.iterdir())


def test_sigterm_with_an_idle_worker_keeps_the_finished_bag(tmp_path: Path) -> None:
    """One worker has finished its bag and waits for work when SIGTERM comes: it exits without
    a traceback, its bag stays complete, the other bag's partial output is removed."""
    short, long_ = tmp_path / 'in' / 'bag0', tmp_path / 'in' / 'bag1'
    write_bag(short, BagSpec(frames=3, width=32, height=24, fx=10.0, blob_px=1))
    write_bag(long_, BagSpec(frames=200, width=32, height=24, fx=10.0, blob_px=1))
    out = tmp_path / 'out'
    proc = subprocess.Popen([*_slow_endeff(tmp_path),
                             'process', str(short), str(long_), '-o', str(out), '--jobs', '2'],
                            stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not ((out / 'bag0' / 'metadata.yaml').is_file() and _leftovers(out)) \
            and time.monotonic() < deadline:
        time.sleep(0.05)
    assert (out / 'bag0' / 'metadata.yaml').is_file() and _leftovers(out), 'never got there'
    time.sleep(0.3)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    assert 'interrupted' in err and 'Traceback' not in err and 'Exception' not in err, err
    assert _leftovers(tmp_path) == []
    assert sorted(p.name for p in out.iterdir()) == ['bag0']
    assert (out / 'bag0' / 'metadata.yaml').is_file()


def _children(pid: int) -> list[int]:
    """Child processes of ``pid`` (from /proc: the parent pid is the 4th field of stat)."""
    kids = []
    for stat in Path('/proc').glob('[0-9]*/stat'):
        try:
            fields = stat.read_text().rsplit(')', 1)[1].split()
        except OSError:  # the process ended meanwhile
            continue
        if int(fields[1]) == pid:
            kids.append(int(stat.parent.name))
    return kids


def _running(pid: int) -> bool:
    """Whether process ``pid`` still runs: it exists and is not a zombie (an ended child that
    the parent or, once it is gone, init has not reaped yet)."""
    try:
        return Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()[0] != 'Z'
    except OSError:
        return False


def _all_ended(pids: list[int], within_s: float = 5.0) -> bool:
    """Whether every process of ``pids`` has ended within ``within_s`` (the spawned workers'
    resource tracker ends a moment after the parent)."""
    deadline = time.monotonic() + within_s
    while any(_running(p) for p in pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    return not any(_running(p) for p in pids)


def _started_with_workers(tmp_path: Path, command: str, args: list[str],
                          **popen: Any) -> tuple[subprocess.Popen[str], list[int]]:
    """``endeff COMMAND`` on three slow bags with ``--jobs 2`` (and ``args``), once its two
    workers have run for a second: the process and its workers' pids."""
    ins = [tmp_path / 'in' / f'bag{k}' for k in range(3)]
    for bag in ins:
        write_bag(bag, BagSpec(frames=200, width=32, height=24, fx=10.0, blob_px=1))
    proc = subprocess.Popen([*_slow_endeff(tmp_path),
                             command, *map(str, ins), *args, '--jobs', '2'],
                            stderr=subprocess.PIPE, text=True, **popen)
    deadline = time.monotonic() + 60
    while len(_children(proc.pid)) < 2 and time.monotonic() < deadline:
        time.sleep(0.05)
    workers = _children(proc.pid)
    assert len(workers) >= 2, 'no workers started'
    time.sleep(1.0)
    return proc, workers


@pytest.mark.parametrize('command', ['process', 'eval'])
def test_ctrl_c_to_the_process_group_stops_every_worker_quietly(tmp_path: Path,
                                                                command: str) -> None:
    """Ctrl-C in a terminal reaches the parent and its workers at once: the command ends with
    status 130 and one line, no traceback from any process, nothing left behind."""
    out = tmp_path / ('out' if command == 'process' else 'report.json')
    args = ['-o', str(out)] if command == 'process' else ['--json', str(out)]
    proc, _ = _started_with_workers(
        tmp_path, command, args, start_new_session=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert 'interrupted' in err and 'Traceback' not in err and 'Exception' not in err, err
    assert _leftovers(tmp_path) == []
    assert not out.exists() or not any(out.iterdir())


def test_sigterm_to_eval_stops_its_workers(tmp_path: Path) -> None:
    """`endeff eval --jobs 2` told to terminate (a `timeout`, a supervisor) ends with one line
    and status 143, and takes its workers with it: none is left running on its own."""
    proc, workers = _started_with_workers(tmp_path, 'eval', [])
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    assert 'interrupted' in err and 'Traceback' not in err, err
    assert _all_ended(workers)


def test_sigkill_leftover_is_removed_by_the_next_run(tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    import endeff_ros.core.tracker as tracker_mod

    src = tmp_path / 'in'
    write_bag(src, BagSpec(frames=120, width=32, height=24, fx=10.0, blob_px=1))
    out = tmp_path / 'out'
    proc = subprocess.Popen([*_slow_endeff(tmp_path), 'process', str(src), '-o', str(out)],
                            stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 60
    while not _leftovers(tmp_path) and time.monotonic() < deadline:
        time.sleep(0.05)
    proc.kill()
    proc.wait(timeout=30)
    assert len(_leftovers(tmp_path)) == 1 and not out.exists()  # SIGKILL cannot clean up
    monkeypatch.setattr(tracker_mod, 'Tracker', FakeTracker)
    assert cli_main(['process', str(src), '-o', str(out)]) == 0
    assert _leftovers(tmp_path) == [] and (out / 'metadata.yaml').is_file()
