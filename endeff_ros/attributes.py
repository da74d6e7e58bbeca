"""Sequence attributes recorded in a bag's rosbag2 metadata, and the groups ``endeff eval``
forms from them.

A benchmark bag may describe itself in the ``custom_data`` mapping of its ``metadata.yaml``
(rosbag2 metadata version >= 6) under the key :data:`ATTRIBUTES_KEY`, whose value is a JSON
object such as ``{"source": "cmu", "family": "walk", "split": "dev", "view": "side",
"camera_height_m": 1.2, "distance_m": 3.0, "sensor": "azure_kinect_nfov", "people": 1,
"truncated": false}``. Bags without it simply have no attributes; a value that is not a JSON
object is reported as a warning naming the bag, never an error, because the attributes only
group the scores and must not stop a bag from being scored.

Bags rendered before an attribute existed lack it; :data:`DEFAULTS` gives such bags (those with
some attributes) the value they had: every bag of the suites was ``motion: active`` before the
still and slow cases came.

Groups are named ``key=value``. Continuous attributes would give one group per sequence, so the
ones in :data:`BINS` are binned (``camera_height_m`` by the heights of a table, a tripod at
chest height and a wall mount; ``distance_m`` by the near, middle and far part of a Kinect-class
sensor's range); other numbers are grouped by their value.

No ROS import: the custom data comes from the ``rosbags`` reader the bag is opened with.
"""

from __future__ import annotations

import json
import math
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence

ATTRIBUTES_KEY = 'endeff.attributes'
"""Key of the attributes in the rosbag2 metadata ``custom_data``."""

BINS: dict[str, tuple[float, ...]] = {
    'camera_height_m': (1.0, 1.6),
    'distance_m': (2.0, 3.5),
}
"""Bin edges (metres) of the numeric attributes that are binned: ``<a``, ``a-b``, ``>b``."""

DEFAULTS: dict[str, Any] = {'motion': 'active'}
"""Group values of attributes that a bag with attributes does not record (see above)."""


def custom_data(reader: Any) -> dict[str, str]:
    """The ``custom_data`` of a bag opened with ``rosbags`` (``AnyReader`` or rosbag2
    ``Reader``): merged over its storage readers, ``{}`` when there is none (metadata
    version < 6, a bare ``.mcap`` or ``.db3`` file)."""
    out: dict[str, str] = {}
    for sub in getattr(reader, 'readers', None) or [reader]:
        # rosbags 0.11 keeps the metadata on the reader's storage (a directory or a raw
        # storage file), 0.10 on the reader itself.
        for owner in (getattr(sub, 'storage', None), sub):
            custom = getattr(getattr(owner, 'metadata', None), 'custom', None)
            if isinstance(custom, dict):
                out.update({str(k): v for k, v in custom.items()})
                break
    return out


def parse_attributes(custom: Mapping[str, Any], bag: str) -> tuple[dict[str, Any], str | None]:
    """``(attributes, warning)`` from a bag's custom data.

    ``attributes`` is ``{}`` when the key is absent or its value is unusable; ``warning`` then
    names the bag and the problem (``None`` when all is well or the key is absent).
    """
    raw = custom.get(ATTRIBUTES_KEY)
    if raw is None:
        return {}, None
    try:
        value = json.loads(raw) if isinstance(raw, str | bytes) else raw
    except ValueError as err:
        return {}, f'{bag}: custom data {ATTRIBUTES_KEY!r} is not valid JSON ({err}); ' \
                   f'the bag is scored without attributes'
    if not isinstance(value, dict):
        return {}, (f'{bag}: custom data {ATTRIBUTES_KEY!r} must be a JSON object, got '
                    f'{type(value).__name__}; the bag is scored without attributes')
    return {str(k): v for k, v in value.items()}, None


def _bin_labels(edges: Sequence[float]) -> list[str]:
    """``['<a', 'a-b', ..., '>z']`` for edges ``a, b, ..., z`` (a bin holds both its edges,
    the lowest excepted)."""
    inner = [f'{lo:g}-{hi:g}' for lo, hi in zip(edges, edges[1:], strict=False)]
    return [f'<{edges[0]:g}', *inner, f'>{edges[-1]:g}']


def attribute_label(key: str, value: Any) -> str | None:
    """The group label of one attribute value (``None``: not groupable, e.g. a list or NaN)."""
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, int | float):
        if not math.isfinite(value):
            return None
        edges = BINS.get(key)
        if edges is None:
            return f'{value:g}'
        index = int(value >= edges[0]) + sum(value > e for e in edges[1:])
        return _bin_labels(edges)[index]
    if isinstance(value, str):
        return value
    return None


def attribute_groups(attributes: Sequence[tuple[str, Mapping[str, Any]]]
                     ) -> dict[str, dict[str, list[str]]]:
    """``{key: {"key=label": [sequence names]}}`` over ``(name, attributes)`` pairs.

    Keys in alphabetical order; labels in the order of their first sequence, except binned
    attributes, whose bins follow the numeric order. A sequence with attributes takes
    :data:`DEFAULTS` for those it lacks; one without any forms no group.
    """
    out: dict[str, dict[str, list[str]]] = {}
    for name, attrs in attributes:
        if attrs:
            attrs = {**DEFAULTS, **attrs}
        for key, value in attrs.items():
            label = attribute_label(key, value)
            if label is not None:
                out.setdefault(key, {}).setdefault(f'{key}={label}', []).append(name)
    for key, edges in BINS.items():
        if key in out:
            order = [f'{key}={label}' for label in _bin_labels(edges)]
            out[key] = {g: out[key][g] for g in order if g in out[key]}
    return {k: out[k] for k in sorted(out)}


def group_sections(groups: Mapping[str, Mapping[str, Any]], key: str | None = None,
                   ) -> list[tuple[str, list[str]]]:
    """The report's groups in table sections, ``[(title, group names)]``: the paper suite's
    named groups first (``groups``), then one section per attribute, in report order. With
    ``key``, only the groups that hold that report key."""
    sections: dict[str, list[str]] = {}
    for g, d in groups.items():
        if key is None or key in d:
            sections.setdefault(d.get('attribute') or 'groups', []).append(g)
    return list(sections.items())
