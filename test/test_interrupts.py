"""Ctrl-C and SIGTERM end ``endeff process``, ``endeff eval`` and ``endeff synth`` with
``--jobs 2`` within seconds, with every worker gone: the real commands, real workers, signals
at different moments (workers starting, busy, one idle), to catch a race rather than one
lucky timing."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from bag_helpers import BagSpec, write_bag

#: Seconds the command may take to end after the signal (the workers' grace is 3 s).
EXIT_S = 8.0
#: Seconds its processes may outlive it.
ORPHAN_S = 5.0


def _stat(pid: int) -> list[str] | None:
    """Fields of /proc/PID/stat after the command name, None if the process is gone."""
    try:
        return Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    except OSError:
        return None


def _running(pid: int) -> bool:
    """The process exists and is not a zombie (ended, not yet reaped by init)."""
    fields = _stat(pid)
    return fields is not None and fields[0] != 'Z'


def _descendants(root: int) -> set[int]:
    """Every process below ``root`` (from /proc: the parent pid is the 2nd field after the
    name)."""
    parents: dict[int, int] = {}
    for stat in Path('/proc').glob('[0-9]*/stat'):
        fields = _stat(int(stat.parent.name))
        if fields is not None:
            parents[int(stat.parent.name)] = int(fields[1])
    found: set[int] = set()
    frontier = {root}
    while frontier:
        frontier = {pid for pid, ppid in parents.items() if ppid in frontier} - found
        found |= frontier
    return found


def _workers(root: int) -> set[int]:
    """Descendants of ``root`` that run jobs (multiprocessing's resource tracker is not one)."""
    out = set()
    for pid in _descendants(root):
        try:
            cmd = Path(f'/proc/{pid}/cmdline').read_bytes()
        except OSError:
            continue
        if b'resource_tracker' not in cmd:
            out.add(pid)
    return out


def _interrupt(tmp_path: Path, argv: list[str], sig: int, *, group: bool, delay: float,
               ready: str = '') -> tuple[int, str, float]:
    """Start ``endeff ARGV``; once two workers run (and ``ready`` exists, if given), wait
    ``delay`` s, send ``sig`` (to the process group, as a terminal's Ctrl-C, or to the command
    only, as a supervisor); return the exit status, stderr and the seconds it took to end.
    Fails if the command does not end within EXIT_S or leaves any process of its own behind."""
    err_path = tmp_path / f'stderr-{time.monotonic_ns()}.txt'
    with err_path.open('w') as err:
        # A shell starts background jobs with SIGINT ignored; a terminal's process has the
        # default disposition, as given back here.
        proc = subprocess.Popen(
            [sys.executable, '-m', 'endeff_ros.cli', *argv], stdout=subprocess.DEVNULL,
            stderr=err, start_new_session=True,
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    seen: set[int] = set()
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and proc.poll() is None and not (
                len(_workers(proc.pid)) >= 2 and (not ready or list(tmp_path.glob(ready)))):
            time.sleep(0.02)
        assert proc.poll() is None, f'ended before the signal: {err_path.read_text()}'
        assert len(_workers(proc.pid)) >= 2, 'the workers never started'
        end = time.monotonic() + delay
        while time.monotonic() < end:
            seen |= _descendants(proc.pid)
            time.sleep(0.02)
        seen |= _descendants(proc.pid)
        if group:
            os.killpg(proc.pid, sig)
        else:
            proc.send_signal(sig)
        t0 = time.monotonic()
        try:
            proc.wait(timeout=EXIT_S)
        except subprocess.TimeoutExpired:
            pytest.fail(f'still running {EXIT_S} s after {signal.Signals(sig).name}: '
                        f'{err_path.read_text()}')
        took = time.monotonic() - t0
        # Orphans end on their own once their parent is gone (the resource tracker at once,
        # workers of a killed command within their grace period).
        deadline = time.monotonic() + ORPHAN_S
        while [p for p in seen if _running(p)] and time.monotonic() < deadline:
            time.sleep(0.05)
        left = [p for p in seen if _running(p)]
        assert not left, f'processes left running after the command ended: {left}'
        return proc.returncode, err_path.read_text(), took
    finally:
        for pid in seen | ({proc.pid} if proc.poll() is None else set()):
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:
                pass
        proc.wait(timeout=10)


@pytest.fixture(scope='module')
def bags(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A short bag (its worker goes idle early) and two long ones (about 4 s each)."""
    root = tmp_path_factory.mktemp('in')
    for name, frames in (('short', 20), ('long_a', 900), ('long_b', 900)):
        write_bag(root / name, BagSpec(frames=frames))
    return root


@pytest.mark.parametrize(('sig', 'group', 'delay'), [
    (signal.SIGINT, True, 0.0),    # Ctrl-C while the workers start
    (signal.SIGINT, False, 0.6),   # `kill -INT` / `timeout -s INT`: the command only
    (signal.SIGTERM, False, 1.5),  # the short bag is done: one worker between jobs or idle
    (signal.SIGTERM, True, 0.3),
])
def test_process_ends_with_its_workers(tmp_path: Path, bags: Path, sig: int, group: bool,
                                       delay: float) -> None:
    out = tmp_path / 'out'
    status, err, took = _interrupt(tmp_path, ['process', str(bags), '-o', str(out),
                                              '--jobs', '2'], sig, group=group, delay=delay,
                                   ready='out/.long_*.partial-*')
    assert status == (130 if sig == signal.SIGINT else 143), err
    assert 'interrupted; outputs not finished were removed' in err, err
    assert 'Traceback' not in err, err
    assert not list(out.rglob('.*partial*')), 'a partial output was left'
    assert {p.name for p in out.iterdir()} <= {'short'}  # a finished bag may stay
    assert took < EXIT_S


def test_workers_end_when_the_command_is_killed(tmp_path: Path, bags: Path) -> None:
    """SIGKILL (the OOM killer, a supervisor's last resort) gives the command no chance to stop
    its workers: they notice on their own, stop, and remove their partial outputs."""
    out = tmp_path / 'out'
    status, err, _ = _interrupt(tmp_path, ['process', str(bags), '-o', str(out), '--jobs', '2'],
                                signal.SIGKILL, group=False, delay=0.3,
                                ready='out/.long_*.partial-*')
    assert status == -signal.SIGKILL
    deadline = time.monotonic() + ORPHAN_S
    while list(out.rglob('.*partial*')) and time.monotonic() < deadline:
        time.sleep(0.05)
    left = sorted(str(p.relative_to(out)) for p in out.rglob('*'))
    assert not list(out.rglob('.*partial*')), f'a partial output was left: {left}; {err}'


@pytest.mark.parametrize(('sig', 'group'), [(signal.SIGTERM, False), (signal.SIGINT, True)])
def test_eval_ends_with_its_workers(tmp_path: Path, bags: Path, sig: int, group: bool) -> None:
    report = tmp_path / 'report.json'
    status, err, _ = _interrupt(tmp_path, ['eval', str(bags), '--jobs', '2', '--json',
                                           str(report)], sig, group=group, delay=0.8)
    assert status == (130 if sig == signal.SIGINT else 143), err
    assert 'interrupted' in err and 'Traceback' not in err, err
    assert not report.exists()


@pytest.mark.parametrize(('sig', 'group'), [(signal.SIGINT, True), (signal.SIGTERM, False)])
def test_synth_ends_with_its_workers(tmp_path: Path, sig: int, group: bool) -> None:
    """...and the bags being written are removed: every bag left is complete (rosbags closes
    an interrupted writer as a bag that looks complete, with fewer frames)."""
    import yaml

    from endeff_ros.synth.frames import dropped_frames
    from endeff_ros.synth.sequences import QUICK_FRAMES

    status, err, _ = _interrupt(tmp_path, ['synth', '--out', str(tmp_path / 'synth'),
                                           '--quick', '--storage', 'mcap', '--jobs', '2'],
                                sig, group=group, delay=0.5, ready='synth/mcap/*')
    assert status == (130 if sig == signal.SIGINT else 143), err
    assert 'interrupted' in err and 'Traceback' not in err, err
    for bag in (tmp_path / 'synth' / 'mcap').iterdir():
        assert not bag.name.startswith('.'), f'a partial bag was left: {bag.name}; {err}'
        info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
        depth = [t['message_count'] for t in info['topics_with_message_count']
                 if t['topic_metadata']['name'].endswith('depth/image_raw')]
        # A complete bag lacks the depth frames its sensor model drops.
        complete = QUICK_FRAMES - len(dropped_frames(bag.name, QUICK_FRAMES)[1])
        assert depth == [complete], f'{bag.name} is not complete: {depth}; {err}'


def test_a_worker_sigterm_inside_the_import_machinery_is_taken_after_it(monkeypatch) -> None:
    """A SIGTERM that lands in the import machinery's weakref callback would be printed and
    swallowed there: the worker's handler sends it again instead of raising; anywhere else it
    unwinds the worker (Terminated)."""
    import types

    from endeff_ros import workers
    from endeff_ros.cli_common import Terminated

    sent = []
    monkeypatch.setattr(workers.os, 'kill', lambda pid, sig: sent.append((pid, sig)))
    monkeypatch.setattr(workers.signal, 'signal', lambda *args: None)
    in_import = types.SimpleNamespace(
        f_code=types.SimpleNamespace(co_filename='<frozen importlib._bootstrap>'))
    workers._on_sigterm(signal.SIGTERM, in_import)
    assert sent == [(os.getpid(), signal.SIGTERM)]
    elsewhere = types.SimpleNamespace(f_code=types.SimpleNamespace(co_filename=__file__))
    with pytest.raises(Terminated):
        workers._on_sigterm(signal.SIGTERM, elsewhere)
    assert len(sent) == 1


def test_a_sigterm_wrapped_by_an_extension_module_s_import_still_ends_the_job(
        monkeypatch, tmp_path: Path) -> None:
    """A SIGTERM taken while an extension module initialises reaches the job as
    ``ImportError('initialization failed')`` caused by Terminated: ``endeff eval``'s job
    raises the Terminated (the command ends, status 143) instead of reporting a failed bag
    with a traceback."""
    from endeff_ros import evaluate
    from endeff_ros.cli_common import Terminated, interruption

    def importing(*_args, **_kwargs):
        try:
            raise Terminated(signal.SIGTERM)
        except Terminated as err:
            raise ImportError('initialization failed') from err

    monkeypatch.setattr(evaluate, 'evaluate_bag', importing)
    with pytest.raises(Terminated):
        evaluate._eval_job((tmp_path / 'a', 'a', None, None, None, None))
    assert interruption(ValueError('a bag')) is None
