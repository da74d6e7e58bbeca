"""``endeff play`` over DDS, and the subscriber of docs/output.md against the node.

A user of the venv has no ``ros2 bag play``: ``endeff play`` must publish every topic of a
recording (raw and image_transport-compressed images, camera info) with its clock, and the
node must answer with ``end_effectors``; the Python example that docs/output.md shows must be
the file that runs, and must print the kinds the node publishes.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tools.procs import ros_env, start, stop

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / 'examples' / 'end_effectors_subscriber.py'
DOC = ROOT / 'docs' / 'output.md'
ENDEFF = [str(Path(sys.executable).with_name('endeff'))]


def test_the_doc_shows_the_example_verbatim():
    """The Python block under "A minimal Python subscriber" is the example file, byte for
    byte, so the code a reader copies is the code the DDS test below runs."""
    text = DOC.read_text(encoding='utf-8')
    section = text.split('## A minimal Python subscriber', 1)[1]
    block = re.search(r'```python\n(.*?)```', section, re.DOTALL)
    assert block is not None
    assert block.group(1) == EXAMPLE.read_text(encoding='utf-8')


def test_the_doc_lists_every_field_of_the_cloud_with_its_offset():
    from endeff_ros.ros import convert

    text = DOC.read_text(encoding='utf-8')
    names = {'FLOAT32': convert.FLOAT32, 'UINT32': convert.UINT32, 'UINT8': convert.UINT8}
    rows = {}
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip('|').split('|')]
        if len(cells) == 5 and cells[1] in names:
            for name, offset in zip(re.findall(r'`(\w+)`', cells[0]), cells[2].split(', ')):
                rows[name] = (names[cells[1]], int(offset))
    assert rows == {n: (d, o) for n, o, d, _ in convert.ENDEFF_FIELDS}
    assert f'`point_step` {convert.ENDEFF_DTYPE.itemsize} bytes' in text



def _domain() -> int:
    return 150 + os.getpid() % 30


def _graph_ready(topic: str, domain_id: int, timeout: float) -> bool:
    """Wait until ``topic`` has a publisher and a subscriber in the graph of ``domain_id``."""
    import rclpy

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id)
    node = rclpy.create_node('play_test_graph', context=context)
    try:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if node.count_publishers(topic) and node.count_subscribers(topic):
                return True
            time.sleep(0.2)
        return False
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)


@pytest.fixture(scope='module')
def person_bag(tmp_path_factory):
    from endeff_ros.synth.cli import generate_one

    out = tmp_path_factory.mktemp('synth')
    generate_one('two_people', out, ['mcap'], True, 0)
    return out / 'mcap' / 'two_people'


@pytest.fixture(scope='module')
def compressed_bag(tmp_path_factory):
    from bag_helpers import BagSpec
    from test_bag_compressed import write_compressed_bag

    path = tmp_path_factory.mktemp('compressed') / 'bag'
    write_compressed_bag(path, BagSpec(frames=6, storage='mcap'))
    return path


def _bag_messages(path: Path) -> dict[str, list[int]]:
    """Recording times (ns) per topic."""
    from endeff_ros.bag.play import open_bag

    reader = open_bag(path)
    try:
        out: dict[str, list[int]] = {}
        for conn, stamp, _ in reader.messages():
            out.setdefault(conn.topic, []).append(int(stamp))
        return out
    finally:
        reader.close()

def test_play_waits_until_the_matches_hold_still():
    """The first message waits for the subscriber's last topic to match, and a quiet time
    after it; never longer than the limit."""
    from endeff_ros.bag.play import settle

    class Executor:
        def spin_once(self, timeout_sec: float) -> None:
            time.sleep(timeout_sec)

    class Player:
        def __init__(self, changes: list[float]) -> None:
            self.start, self.changes = time.monotonic(), changes

        def matched(self) -> dict[str, int]:
            t = time.monotonic() - self.start
            return {'/a': 1, '/b': sum(c <= t for c in self.changes)}

    player = Player([0.0, 0.15, 0.3])  # three topics match, 0.15 s apart
    settle(Executor(), player, 0.2, 5.0)
    waited = time.monotonic() - player.start
    assert 0.5 <= waited < 1.5
    player = Player([0.1 * k for k in range(100)])  # never quiet: the limit ends it
    settle(Executor(), player, 0.2, 0.4)
    assert 0.4 <= time.monotonic() - player.start < 1.0



@pytest.mark.integration
def test_play_publishes_every_topic_and_the_recording_clock(compressed_bag):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rosgraph_msgs.msg import Clock

    from endeff_ros.bag.play import message_class

    expected = _bag_messages(compressed_bag)
    assert any(t.endswith('/compressed') for t in expected)
    assert any(t.endswith('/compressedDepth') for t in expected)
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=_domain())
    node = rclpy.create_node('play_listener', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    got: dict[str, int] = {}
    clock: list[int] = []
    from endeff_ros.bag.play import open_bag

    reader = open_bag(compressed_bag)
    types = {c.topic: c.msgtype for c in reader.connections}
    reader.close()
    for topic, msgtype in types.items():
        node.create_subscription(message_class(msgtype), topic,
                                 lambda _m, t=topic: got.__setitem__(t, got.get(t, 0) + 1),
                                 qos, raw=True)
    node.create_subscription(Clock, '/clock', lambda m: clock.append(
        m.clock.sec * 1_000_000_000 + m.clock.nanosec), qos)
    env = ros_env(profile=True, domain_id=_domain())
    proc = subprocess.Popen([*ENDEFF, 'play', str(compressed_bag), '--wait', '30',
                             '--rate', '0.5'], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 90
        while proc.poll() is None and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        end = time.monotonic() + 3
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.05)
        out = proc.communicate(timeout=10)[0] if proc.poll() is not None else ''
    finally:
        stop(proc)
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)
    assert proc.returncode == 0, out
    assert got == {t: len(s) for t, s in expected.items()}, out
    times = sorted(s for stamps in expected.values() for s in stamps)
    assert set(times) <= set(clock)  # the clock told every message's recording time
    assert clock == sorted(clock)
    assert f'{sum(len(s) for s in expected.values())} messages' in out


@pytest.mark.integration
def test_the_node_answers_a_played_bag_and_the_example_prints_its_kinds(person_bag, tmp_path):
    """The node on sim time, the documented subscriber, ``endeff play`` with the clock:
    the node answers with end_effectors, and the example prints heads, hands and feet."""
    env = ros_env(profile=True, domain_id=_domain() + 30)
    logs = {n: open(tmp_path / f'{n}.log', 'w+', encoding='utf-8')  # noqa: SIM115
            for n in ('node', 'example')}
    node = start(['-m', 'endeff_ros.ros.node', '--ros-args', '-r', '__ns:=/camera',
                  '-p', 'use_sim_time:=true'], env, stdout=logs['node'],
                 stderr=subprocess.STDOUT)
    example = start([str(EXAMPLE), '--kind', 'any', '--count', '4'], env,
                    stdout=logs['example'], stderr=subprocess.STDOUT)
    try:
        # ``play --wait`` waits for the node only: a quick bag plays in seconds, so on a slow
        # machine the example could still be starting when the last cloud goes out.
        assert _graph_ready('/camera/end_effectors', int(env['ROS_DOMAIN_ID']), 90), \
            'the node and the example did not meet on /camera/end_effectors within 90 s'
        play = subprocess.run([*ENDEFF, 'play', str(person_bag), '--wait', '60',
                               '--rate', '0.25'], env=env, capture_output=True, text=True,
                              timeout=240, check=False)
        try:
            example.wait(timeout=60)
        except subprocess.TimeoutExpired:
            pass
    finally:
        stop(example)
        stop(node)
    text = {}
    for name, fh in logs.items():
        fh.seek(0)
        text[name] = fh.read()
        fh.close()
    assert play.returncode == 0, play.stdout + play.stderr
    assert '/clock messages' in play.stdout
    both = f'{text["example"]}\n--- node ---\n{text["node"][-3000:]}'
    assert example.returncode == 0, both
    lines = [line for line in text['example'].splitlines() if ' of entity ' in line]
    kinds = {line.split(': ', 1)[1].split()[0] for line in lines}
    assert {'head', 'hand', 'foot'} <= kinds, both
    # The cloud's stamp is the bag's (sim time), its frame the depth image's.
    assert all(re.match(r'\d{10}\.\d{3} camera_color_optical_frame: ', line)
               for line in lines), lines[:3]
