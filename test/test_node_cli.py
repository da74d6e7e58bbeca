"""``endeff_node`` as a user starts it: ``--help`` prints the usage instead of starting the node,
and a node without input says what it waits for and, later, which inputs stay silent."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tools.procs import ros_env

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parents[1]


def test_help_prints_the_usage_and_exits() -> None:
    t0 = time.monotonic()
    done = subprocess.run([sys.executable, '-m', 'endeff_ros.ros.node', '--help'], cwd=REPO,
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    out = done.stdout
    assert out.startswith('usage: endeff_node'), out
    for text in ('depth/image_raw', 'depth/camera_info', 'color/image_raw', 'end_effectors',
                 '--ros-args', '--params-file', '__ns:=', 'endeff params'):
        assert text in out, text
    assert max(map(len, out.splitlines())) <= 99
    assert 'waiting for' not in out + done.stderr  # the node was not started
    assert time.monotonic() - t0 < 30


def test_without_input_the_node_names_what_it_waits_for(tmp_path: Path,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """At start: the inputs it waits for (resolved names: namespace and remaps applied); after
    NO_INPUT_WARN_S without a message, a warning naming the silent inputs, repeated at that
    period, not more often."""
    from endeff_ros.ros.node import NO_INPUT_WARN_S

    log = tmp_path / 'node.log'
    env = ros_env(profile=False, domain_id=180 + os.getpid() % 20)
    with log.open('w') as fh:
        proc = subprocess.Popen(
            [sys.executable, '-m', 'endeff_ros.ros.node', '--ros-args', '-r', '__ns:=/quiet',
             '-r', 'depth/image_raw:=/elsewhere/depth', '-p', 'use_color:=false'],
            cwd=REPO, env=env, stdout=fh, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 3 * NO_INPUT_WARN_S + 30
        while time.monotonic() < deadline and proc.poll() is None and \
                log.read_text().count('no message for') < 2:
            time.sleep(0.1)
        text = log.read_text()
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=10)
    waiting = [line for line in text.splitlines() if 'waiting for' in line]
    assert waiting, text
    assert waiting[0].endswith('waiting for /elsewhere/depth and /quiet/depth/camera_info'), text
    warnings = [line for line in text.splitlines() if 'no message for' in line]
    assert len(warnings) == 2, text
    assert '[WARN]' in warnings[0] and '/elsewhere/depth' in warnings[0], warnings[0]
    assert '/quiet/depth/camera_info' in warnings[0] and 'color' not in warnings[0]
    stamps = [float(line.split('[')[2].split(']')[0]) for line in warnings]  # [LEVEL] [time]
    assert stamps[1] - stamps[0] >= NO_INPUT_WARN_S - 0.5  # rate-limited
