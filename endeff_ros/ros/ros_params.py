"""Parameter descriptors and QoS profiles of endeff_node, built from the parameter tables."""

from __future__ import annotations

from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from endeff_ros.ros.processing import describe_text

_TYPES = {'float': ParameterType.PARAMETER_DOUBLE, 'int': ParameterType.PARAMETER_INTEGER,
          'bool': ParameterType.PARAMETER_BOOL, 'str': ParameterType.PARAMETER_STRING}


def descriptor(row: dict[str, Any]) -> ParameterDescriptor:
    """ParameterDescriptor of one parameter-table row (type, description, range, read-only).

    ``row`` is a row of :func:`endeff_ros.core.params.describe` or
    :data:`endeff_ros.ros.processing.NODE_PARAMS`; parameters whose ``runtime`` is False are
    read-only (fixed at start-up).
    """
    d = ParameterDescriptor(name=row['name'], type=_TYPES[row['type']],
                            description=describe_text(row), read_only=not row['runtime'])
    if row['lo'] is not None and row['hi'] is not None:
        if row['type'] == 'float':
            d.floating_point_range = [FloatingPointRange(
                from_value=float(row['lo']), to_value=float(row['hi']), step=0.0)]
        elif row['type'] == 'int':
            d.integer_range = [IntegerRange(from_value=int(row['lo']), to_value=int(row['hi']),
                                            step=1)]
    return d


def qos(reliability: str, depth: int) -> QoSProfile:
    """Keep-last, volatile QoS with ``reliability`` 'best_effort' (sensor data) or 'reliable'."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=int(depth),
                      durability=DurabilityPolicy.VOLATILE,
                      reliability=ReliabilityPolicy.RELIABLE if reliability == 'reliable'
                      else ReliabilityPolicy.BEST_EFFORT)
