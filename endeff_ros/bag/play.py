"""``endeff play BAG``: publish a recorded bag over DDS with its clock, for a running node.

With ROS 2 installed from apt, ``ros2 bag play --clock BAG`` does this; the venv has no
``ros2`` command (rclpy's PyPI wheels carry no rosbag2), so a user of the venv had no way to
play a recording into ``endeff_node`` and watch it. This publishes every message of the bag
on its recorded topic with its recorded type, raw (CDR bytes as stored: no decoding, so
``sensor_msgs/Image``, image_transport's ``CompressedImage`` and any other type whose Python
message package is importable), in recording order, paced by the recording times (``--rate``
scales them), and the recording time on ``/clock`` (``rosgraph_msgs/Clock``) for a node run
with ``use_sim_time``. Topics whose type cannot be imported are skipped, with one line each.

Publishers are reliable, keep last 10: they match both reliable and best-effort subscribers
(the node's inputs are best effort by default). Before the first message it waits up to
``--wait`` s for a subscriber of any of the bag's topics, then until its matches have held
still for a second (:func:`settle`), for a node started at the same time would otherwise miss
the first frames while DDS discovery runs.

No rosbag2: bags are read by :mod:`rosbags` (mcap or sqlite3, a directory or a file).
"""

from __future__ import annotations

import importlib
import sys
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from endeff_ros.bag.errors import BagError
from endeff_ros.cli_common import EXIT_FAILED, EXIT_OK, usage_error

if TYPE_CHECKING:
    import argparse
    from collections.abc import Callable, Iterator
    from pathlib import Path

CLOCK_TOPIC = '/clock'
#: ``/clock`` is published at least this often (Hz) while the player waits between messages,
#: as ``ros2 bag play --clock`` does by default (40 Hz): timers of a node on sim time run.
CLOCK_HZ = 40.0
#: After the first subscriber, the matches must hold still this long (s) before the first
#: message, and the wait ends after at most SETTLE_LIMIT_S (:func:`settle`).
SETTLE_S = 1.0
SETTLE_LIMIT_S = 5.0


def spin_for(executor: Any, seconds: float) -> None:
    """Spin in bounded steps for ``seconds`` (callbacks keep running)."""
    end = time.monotonic() + seconds
    while True:
        left = end - time.monotonic()
        if left <= 0:
            return
        executor.spin_once(timeout_sec=min(left, 0.005))


def spin_until(executor: Any, condition: Callable[[], bool], timeout: float) -> bool:
    """Spin until ``condition()`` or ``timeout`` s; returns whether it became true."""
    end = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > end:
            return False
        executor.spin_once(timeout_sec=0.01)
    return True


def settle(executor: Any, player: BagPlayer, quiet: float, limit: float) -> None:
    """Spin until the player's matches have not changed for ``quiet`` s (at most ``limit``
    s). A publisher that sees a subscription does not mean the subscriber sees the publisher
    yet: DDS discovers each side on its own, and a reliable, volatile reader drops what comes
    before it matched. A subscriber's topics match one by one, so the wait starts again at
    each new match; 0.5 s after the first one lost a frame on every topic now and then on a
    loaded machine."""
    end = time.monotonic() + limit
    seen = player.matched()
    still_since = time.monotonic()
    while True:
        now = time.monotonic()
        if now - still_since >= quiet or now >= end:
            return
        executor.spin_once(timeout_sec=0.01)
        current = player.matched()
        if current != seen:
            seen, still_since = current, time.monotonic()


def message_class(msgtype: str) -> Any:
    """The rclpy message class of ``pkg/msg/Name`` (None when its package is not
    importable: a custom type of the recording)."""
    pkg, _, name = msgtype.partition('/msg/')
    if not pkg or not name:
        return None
    try:
        return getattr(importlib.import_module(f'{pkg}.msg'), name)
    except (ImportError, AttributeError):
        return None


@dataclass
class PlayStats:
    """What a play published."""

    messages: int = 0
    per_topic: dict[str, int] = field(default_factory=dict)
    skipped_topics: dict[str, str] = field(default_factory=dict)  # topic -> its type
    clock_ticks: int = 0
    bag_seconds: float = 0.0
    seconds: float = 0.0


class BagPlayer:
    """Publishers for the topics of an open :class:`~endeff_ros.bag.reader.BagReader`, and
    the ``/clock`` publisher (``clock``)."""

    def __init__(self, node: Any, reader: Any, *, topics: list[str] | None = None,
                 clock: bool = True) -> None:
        from rclpy.qos import QoSProfile, ReliabilityPolicy

        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self.node = node
        self.reader = reader
        self.pubs: dict[str, Any] = {}
        self.stats = PlayStats()
        self.connections = []
        for conn in reader.connections:
            if topics and conn.topic not in topics:
                continue
            cls = message_class(conn.msgtype)
            if cls is None:
                self.stats.skipped_topics[conn.topic] = conn.msgtype
                continue
            if conn.topic not in self.pubs:
                self.pubs[conn.topic] = node.create_publisher(cls, conn.topic, qos)
            self.connections.append(conn)
        self.clock_pub = None
        if clock:
            from rosgraph_msgs.msg import Clock

            self.clock_pub = node.create_publisher(Clock, CLOCK_TOPIC, qos)

    def subscribed(self) -> bool:
        """Some topic of the bag has a subscriber."""
        return any(p.get_subscription_count() > 0 for p in self.pubs.values())

    def matched(self) -> dict[str, int]:
        """Subscribers per topic, as this player's publishers see them."""
        return {t: p.get_subscription_count() for t, p in self.pubs.items()}

    def publish_clock(self, stamp_ns: int) -> None:
        """``/clock`` at ``stamp_ns`` (a recording time), if the clock is on."""
        if self.clock_pub is None:
            return
        from rosgraph_msgs.msg import Clock

        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = divmod(int(stamp_ns), 1_000_000_000)
        self.clock_pub.publish(msg)
        self.stats.clock_ticks += 1

    def messages(self) -> Iterator[tuple[str, int, bytes]]:
        """(topic, recording time ns, CDR bytes) in recording order."""
        for conn, stamp, raw in self.reader.messages(connections=self.connections):
            yield conn.topic, int(stamp), bytes(raw)

    def play(self, executor: Any, *, rate: float = 1.0,
             max_seconds: float | None = None) -> PlayStats:
        """Publish every message at its recording time divided by ``rate`` (from the first
        message), ``/clock`` before each and every 1/:data:`CLOCK_HZ` s between them; stop
        after ``max_seconds`` of recording time."""
        stats = self.stats
        t_start = time.monotonic()
        first = None
        tick = 1.0 / CLOCK_HZ
        for topic, stamp, raw in self.messages():
            if first is None:
                first = stamp
            offset = (stamp - first) / 1e9
            if max_seconds is not None and offset > max_seconds:
                break
            due = t_start + offset / rate
            while True:  # wait for the message's time, the clock running meanwhile
                now = time.monotonic()
                if now >= due:
                    break
                self.publish_clock(first + round((now - t_start) * rate * 1e9))
                spin_for(executor, min(tick, due - now))
            self.publish_clock(stamp)
            self.pubs[topic].publish(raw)
            stats.messages += 1
            stats.per_topic[topic] = stats.per_topic.get(topic, 0) + 1
            stats.bag_seconds = offset
            executor.spin_once(timeout_sec=0)
        stats.seconds = time.monotonic() - t_start
        return stats


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``endeff play``."""
    parser.description = (
        'Publish a recorded bag (rosbag2 directory, .mcap or .db3) over DDS with its clock, '
        'as `ros2 bag play --clock` does: every topic with its recorded type, raw and '
        'image_transport-compressed images alike, paced by the recording times, the '
        'recording time on /clock. Start the node with use_sim_time (`endeff_node --ros-args '
        '-r __ns:=/camera -p use_sim_time:=true`) in its namespace. Ctrl-C stops.')
    parser.add_argument('bag', metavar='BAG', help='the bag to play')
    parser.add_argument('--rate', type=float, default=1.0, metavar='FACTOR',
                        help='speed factor of the recording times (default 1; 0.5 half speed)')
    parser.add_argument('--topics', nargs='+', metavar='TOPIC',
                        help='play only these topics (default: all)')
    parser.add_argument('--no-clock', action='store_true',
                        help='do not publish /clock (a node on wall time)')
    parser.add_argument('--wait', type=float, default=5.0, metavar='S',
                        help='seconds to wait for a subscriber of any of its topics before the '
                             'first message (default 5; 0: no wait)')
    parser.add_argument('--max-seconds', type=float, default=None, metavar='S',
                        help='stop after S seconds of recording time')


def run(args: argparse.Namespace) -> int:
    """``endeff play``: 0 when the bag was played, 1 when it could not be read, 2 for a bad
    option or a missing bag; 130/143 when interrupted (:func:`endeff_ros.cli.main`)."""
    if not args.rate > 0:
        raise usage_error('endeff play', f'--rate must be above 0, got {args.rate:g}')
    if args.wait < 0:
        raise usage_error('endeff play', f'--wait must be 0 or more, got {args.wait:g}')
    from endeff_ros.bag.reader import find_bags

    try:
        paths = find_bags([args.bag])
    except BagError as err:
        raise usage_error('endeff play', str(err)) from err
    if len(paths) != 1:
        raise usage_error('endeff play', f'{args.bag} holds {len(paths)} bags; play one')
    return _play(paths[0], args)


def open_bag(path: Path) -> Any:
    """An open rosbags ``AnyReader`` of ``path`` (:class:`BagError` if it cannot be read).
    Any recording, not only the camera layouts that ``endeff eval`` recognises; the Jazzy
    typestore stands in for message definitions a bag does not carry."""
    from rosbags.highlevel import AnyReader

    from endeff_ros.bag.reader import resolve_bag, typestore

    try:
        reader = AnyReader([resolve_bag(path)], default_typestore=typestore())
        reader.open()
    except BagError:
        raise
    except Exception as err:  # rosbags, sqlite3, mcap, yaml errors alike
        raise BagError(path, f'cannot open bag: {err}') from err
    return reader


def _play(path: Path, args: argparse.Namespace) -> int:
    """Play ``path``; Ctrl-C and SIGTERM unwind through :func:`endeff_ros.cli.main`."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    try:
        reader = open_bag(path)
    except BagError as err:
        print(f'endeff play: {err}', file=sys.stderr)
        return EXIT_FAILED
    rclpy.init()
    node = rclpy.create_node('endeff_play')
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    try:
        player = BagPlayer(node, reader, topics=args.topics, clock=not args.no_clock)
        for topic, msgtype in player.stats.skipped_topics.items():
            print(f'endeff play: skipping {topic}: no Python message package for {msgtype}',
                  file=sys.stderr)
        if not player.pubs:
            print(f'endeff play: {path}: no topic to play', file=sys.stderr)
            return EXIT_FAILED
        if args.wait > 0 and not spin_until(executor, player.subscribed, args.wait):
            print(f'endeff play: no subscriber of any of its topics after {args.wait:g} s; '
                  'playing anyway', file=sys.stderr)
        elif args.wait > 0:
            settle(executor, player, SETTLE_S, SETTLE_LIMIT_S)
        stats = player.play(executor, rate=args.rate, max_seconds=args.max_seconds)
        print(f'{path}: {stats.messages} messages on {len(stats.per_topic)} topics, '
              f'{stats.bag_seconds:.1f} s of recording in {stats.seconds:.1f} s'
              + ('' if args.no_clock else f', {stats.clock_ticks} /clock messages'))
        return EXIT_OK
    finally:
        reader.close()
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
