"""Starting and stopping ROS processes for the benchmarks, the demo and the tests.

``ros_env(profile=True)`` is the environment of a child process: Fast DDS as the RMW, and the
shared-memory profile ``config/fastdds_shm.xml`` as the default participant profile (or no
profile at all with ``profile=False``, to compare).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

_CHECKOUT = Path(__file__).resolve().parents[1]
PROFILE_NAME = 'fastdds_shm.xml'
_PROFILE_VARS = ('FASTDDS_DEFAULT_PROFILES_FILE', 'FASTRTPS_DEFAULT_PROFILES_FILE')


def profile_path() -> Path:
    """``config/fastdds_shm.xml`` of the source tree, else of the installed package share."""
    here = _CHECKOUT / 'config' / PROFILE_NAME
    if here.is_file():
        return here
    try:
        from ament_index_python.packages import get_package_share_directory

        share = Path(get_package_share_directory('endeff_ros')) / 'config' / PROFILE_NAME
    except (ImportError, LookupError, ValueError) as exc:
        msg = f'cannot find {PROFILE_NAME} in the source tree or the package share'
        raise FileNotFoundError(msg) from exc
    return share


def ros_env(*, profile: bool = True, domain_id: int | None = None,
            base: dict[str, str] | None = None) -> dict[str, str]:
    """Environment for a ROS child process (Fast DDS, with or without the SHM profile)."""
    env = dict(os.environ if base is None else base)
    env.setdefault('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp')
    env['PYTHONUNBUFFERED'] = '1'
    # Children run ``python -m tools.NAME`` from any working directory: the checkout first.
    env['PYTHONPATH'] = os.pathsep.join(p for p in (str(_CHECKOUT), env.get('PYTHONPATH')) if p)
    for var in _PROFILE_VARS:
        env.pop(var, None)
        if profile:
            env[var] = str(profile_path())
    if domain_id is not None:
        env['ROS_DOMAIN_ID'] = str(domain_id)
    return env


def start(args: list[str], env: dict[str, str], **kwargs: Any) -> subprocess.Popen:
    """Start ``python -m ...``-style child ``args`` (the current interpreter is prepended)."""
    return subprocess.Popen([sys.executable, *args], env=env, **kwargs)


def stop(proc: subprocess.Popen, timeout: float = 10.0) -> int | None:
    """SIGINT, then SIGTERM, then SIGKILL, each with a bounded wait; returns the exit code."""
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
        if proc.poll() is not None:
            break
        proc.send_signal(sig)
        try:
            proc.wait(timeout=timeout / 2 if sig != signal.SIGKILL else timeout)
        except subprocess.TimeoutExpired:
            continue
    return proc.poll()

