"""Furniture for the ``mocap`` suite: tables, chairs, shelves, a floor lamp, boxes.

Furniture is background: every piece is an ``Entity`` without ground truth (no end-effectors),
built in the scene frame of ``render.py`` (y up, metres) standing on the floor at (x, z) and
turned by ``yaw`` (0 = its front towards +z, the camera). A room's pieces are merged into one
static entity that the renderer draws once per bag (``render.static_layer``).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from .body import Color, Entity
from .shapes import Primitive, box, capsule, ellipsoid, rot_x, rot_y

ROOMS = ('empty', 'furnished', 'wall')
PIECES = ('table', 'chair', 'shelf', 'lamp', 'boxes')
WOOD: Color = (0.55, 0.36, 0.20)


def background_entity(prims: list[Primitive]) -> Entity:
    """An entity of ``prims`` with no ground truth (furniture, carried objects)."""
    return Entity(list(prims), np.zeros((0, 3)), np.zeros(0, np.uint32), np.zeros(0, np.int64),
                  np.zeros(0))


def _placed(prims: list[Primitive], x: float, z: float, yaw: float) -> list[Primitive]:
    rot = rot_y(yaw)
    return [p.transformed(rot, np.array([x, 0.0, z])) for p in prims]


def table(x: float, z: float, yaw: float = 0.0, *, width: float = 1.2, depth: float = 0.7,
          height: float = 0.74, color: Color = WOOD, tex: int = 300) -> list[Primitive]:
    """A table: top (3 cm thick) at ``height`` m and four 5 cm legs."""
    eye = np.eye(3)
    w, d = 0.5 * width, 0.5 * depth
    prims = [box([0, height - 0.015, 0], eye, [w, 0.015, d], color, tex, 'table_top')]
    for sx in (-1, 1):
        for sz in (-1, 1):
            prims.append(box([sx * (w - 0.05), 0.5 * (height - 0.03), sz * (d - 0.05)], eye,
                             [0.025, 0.5 * (height - 0.03), 0.025], color, tex + 1, 'table_leg'))
    return _placed(prims, x, z, yaw)


def chair(x: float, z: float, yaw: float = 0.0, *, seat: float = 0.46,
          color: Color = (0.40, 0.30, 0.25), tex: int = 320) -> list[Primitive]:
    """A chair with its seat (45 x 44 cm) at ``seat`` m and a backrest 0.5 m above it."""
    eye = np.eye(3)
    prims = [box([0, seat - 0.025, 0], eye, [0.225, 0.025, 0.22], color, tex, 'chair_seat')]
    for sx in (-1, 1):
        for sz in (-1, 1):
            prims.append(box([sx * 0.2, 0.5 * (seat - 0.05), sz * 0.195], eye,
                             [0.02, 0.5 * (seat - 0.05), 0.02], color, tex + 1, 'chair_leg'))
        prims.append(box([sx * 0.2, seat + 0.2, -0.2], eye, [0.02, 0.2, 0.02], color, tex + 1,
                         'chair_post'))
    prims.append(box([0, seat + 0.32, -0.2], eye, [0.22, 0.13, 0.02], color, tex + 2,
                     'chair_back'))
    return _placed(prims, x, z, yaw)


def shelf(x: float, z: float, yaw: float = 0.0, *, width: float = 0.8, height: float = 1.8,
          depth: float = 0.35, color: Color = (0.70, 0.62, 0.50), tex: int = 340
          ) -> list[Primitive]:
    """An open shelf: two sides, a back panel and five boards, front towards +z."""
    eye = np.eye(3)
    w, h, d = 0.5 * width, 0.5 * height, 0.5 * depth
    prims = [box([sx * (w - 0.01), h, 0], eye, [0.01, h, d], color, tex, 'shelf_side')
             for sx in (-1, 1)]
    prims.append(box([0, h, -d + 0.005], eye, [w, h, 0.005], color, tex + 1, 'shelf_back'))
    for k in range(5):
        y = 0.05 + k * (height - 0.07) / 4
        prims.append(box([0, y, 0], eye, [w - 0.02, 0.01, d], color, tex + 2, 'shelf_board'))
    prims.append(box([-0.15, 0.05 + (height - 0.07) / 4 + 0.12, 0.02], eye, [0.12, 0.11, 0.1],
                     (0.2, 0.3, 0.6), tex + 3, 'shelf_item'))
    return _placed(prims, x, z, yaw)


def lamp(x: float, z: float, yaw: float = 0.0, *, height: float = 1.6, tex: int = 360
         ) -> list[Primitive]:
    """A floor lamp: flat round base, pole, and a wide shade at the top."""
    grey = (0.25, 0.25, 0.27)
    prims = [ellipsoid([0, 0.02, 0], np.eye(3), [0.16, 0.02, 0.16], grey, tex, 'lamp_base'),
             capsule([0, 0.03, 0], [0, height - 0.15, 0], 0.015, [1, 0, 0], grey, tex + 1,
                     'lamp_pole'),
             ellipsoid([0, height - 0.1, 0], rot_x(0.0), [0.22, 0.13, 0.22],
                       (0.92, 0.88, 0.74), tex + 2, 'lamp_shade')]
    return _placed(prims, x, z, yaw)


def boxes(x: float, z: float, yaw: float = 0.0, *, count: int = 2, tex: int = 380
          ) -> list[Primitive]:
    """``count`` cardboard boxes stacked, each a little smaller and turned."""
    prims, y = [], 0.0
    for k in range(count):
        half = np.array([0.25, 0.17, 0.2]) * (1.0 - 0.15 * k)
        prims.append(box([0.03 * k, y + half[1], 0], rot_y(0.3 * k), half, (0.62, 0.47, 0.30),
                         tex + k, 'box'))
        y += 2 * half[1]
    return _placed(prims, x, z, yaw)


BUILDERS = {'table': table, 'chair': chair, 'shelf': shelf, 'lamp': lamp, 'boxes': boxes}
#: Footprint radius (m) of each piece, to keep pieces out of each other and off the walkways.
FOOTPRINT = {'table': 0.7, 'chair': 0.35, 'shelf': 0.45, 'lamp': 0.25, 'boxes': 0.32}


def scatter(rng: np.random.Generator, keep_clear: npt.ArrayLike, count: int,
            x_range: tuple[float, float], z_range: tuple[float, float],
            clear_m: float = 0.45, half_fov: float | None = None
            ) -> list[tuple[str, list[Primitive]]]:
    """Up to ``count`` pieces placed at random in the floor area ``x_range`` x ``z_range``
    (scene frame, m), at least ``clear_m`` (plus the piece's footprint) from every point of
    ``keep_clear`` (K, 2) (x, z) (the people's paths) and from each other.

    ``half_fov`` (rad): draw each piece's bearing from the camera (at the origin, looking along
    -z) within +-``half_fov`` instead of x within ``x_range`` (which still bounds it), so that
    every piece stands in the camera's horizontal field of view."""
    clear = np.asarray(keep_clear, dtype=np.float64).reshape(-1, 2)
    placed: list[tuple[float, float, float]] = []
    out = []
    for _ in range(count):
        kind = PIECES[int(rng.integers(len(PIECES)))]
        for _try in range(20):
            if half_fov is None:
                x = float(rng.uniform(*x_range))
                z = float(rng.uniform(*z_range))
            else:
                bearing = float(rng.uniform(-half_fov, half_fov))
                z = float(rng.uniform(*z_range))
                x = -z * float(np.tan(bearing))
                if not x_range[0] <= x <= x_range[1]:
                    continue
            r = FOOTPRINT[kind]
            if len(clear) and np.min(np.hypot(clear[:, 0] - x, clear[:, 1] - z)) < r + clear_m:
                continue
            if any(np.hypot(px - x, pz - z) < r + pr + 0.1 for px, pz, pr in placed):
                continue
            yaw = float(rng.uniform(-0.6, 0.6)) + (np.pi if kind == 'chair' and
                                                   rng.random() < 0.5 else 0.0)
            placed.append((x, z, r))
            out.append((kind, BUILDERS[kind](x, z, yaw, tex=int(rng.integers(300, 900)))))
            break
    return out


def sight_lines(targets: npt.ArrayLike, step_m: float = 0.25) -> npt.NDArray[np.float64]:
    """Floor points (K, 2) (x, z) every ``step_m`` along the lines from the camera (the
    origin) to each of ``targets`` (N, 2) (x, z): kept clear (``scatter``'s ``keep_clear``),
    they keep furniture from standing between the camera and the people, so that furniture
    stands beside or behind them and never hides them."""
    t = np.asarray(targets, dtype=np.float64).reshape(-1, 2)
    if not len(t):
        return np.zeros((0, 2))
    n = max(2, int(np.ceil(np.linalg.norm(t, axis=1).max() / step_m)) + 1)
    f = np.linspace(0.0, 1.0, n)
    return (f[None, :, None] * t[:, None, :]).reshape(-1, 2)
