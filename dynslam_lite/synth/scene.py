"""The synthetic office: room, furniture, articulated people and camera motion patterns.

World frame: z up, floor at z = 0; the camera's home is at (0, -1, 1.35) looking along +y.
Scene names mirror the TUM fr3 sequences the papers use.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry import se3_exp, so3_exp
from .raycast import Box, Group
from .textures import material

# the TUM fr3 analogues (the papers' sequences), then ours: scenes with the cases papers B and C
# are about: a carried board and box (not people, moving), a pushed box (a static class that
# moves), people standing still for a while, and a crowd passing close to the camera
TUM_SCENES = (
    "walking_static", "walking_xyz", "walking_rpy", "walking_halfsphere",
    "sitting_static", "sitting_xyz", "sitting_rpy", "sitting_halfsphere",
    "static_xyz",
)
OBJECT_SCENES = ("walking_carry", "walking_push", "crowd")
# scenes seen by a camera with automatic exposure (see generator.exposure_schedule) -> the scene
# whose camera path, people and objects they show
EXPOSURE_SCENES = {"walking_exposure": "walking_xyz"}
SCENES = TUM_SCENES + OBJECT_SCENES + tuple(EXPOSURE_SCENES)
_PATTERN = {"walking_carry": "xyz", "walking_push": "halfsphere", "crowd": "xyz"}

# object classes of the furniture (what an instance segmenter such as Mask R-CNN would label);
# boxes of one object share its name
FURNITURE = {"desk": "table", "screen": "tv", "desk_box": "box", "desk_books": "book", "shelf": "book",
             "cabinet": "cabinet", "poster_board": "poster", "poster": "poster", "side_cabinet": "cabinet",
             "side_books": "book", "chair": "chair"}


def _pose(R=None, t=(0.0, 0.0, 0.0)) -> np.ndarray:
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    T[:3, 3] = t
    return T


def _rz(a):
    return so3_exp([0.0, 0.0, a])


def _rx(a):
    return so3_exp([a, 0.0, 0.0])


def _box(centre, half, mat, yaw=0.0, **kw) -> Box:
    return Box(_pose(_rz(yaw), centre), np.asarray(half, float), material(mat), **kw)


def static_boxes() -> list[Box]:
    """Room (seen from inside) and furniture; all static. Furniture instances: see
    :func:`furniture_names` (same order)."""
    return [
        # room: x in [-3, 3], y in [-2.2, 3.4], z in [0, 2.8]; wall/floor/ceiling textures by face
        _box((0.0, 0.6, 1.4), (3.0, 2.8, 1.42), "wall", inside=True),
        _box((0.0, 0.6, -0.05), (3.0, 2.8, 0.05), "floor"),
        _box((0.0, 0.6, 2.85), (3.0, 2.8, 0.05), "ceiling"),
        # desk against the back wall, with a monitor, books and boxes on it
        _box((0.2, 2.6, 0.72), (0.9, 0.4, 0.03), "wood"),
        _box((-0.6, 2.6, 0.35), (0.04, 0.38, 0.35), "wood"),
        _box((1.0, 2.6, 0.35), (0.04, 0.38, 0.35), "wood"),
        _box((0.3, 2.75, 0.98), (0.28, 0.03, 0.2), "dark", no_depth=True),  # glossy screen
        _box((-0.35, 2.55, 0.82), (0.12, 0.08, 0.07), "cabinet", yaw=0.3),
        _box((0.85, 2.5, 0.8), (0.08, 0.15, 0.05), "books"),
        # bookshelf on the left of the back wall, cabinet on the right, poster board
        _box((-1.9, 3.15, 1.0), (0.6, 0.2, 1.0), "books"),
        _box((1.9, 3.1, 0.55), (0.45, 0.25, 0.55), "cabinet"),
        _box((1.9, 3.05, 1.35), (0.2, 0.15, 0.25), "poster", yaw=-0.2),
        _box((0.2, 3.38, 1.75), (0.8, 0.02, 0.45), "poster"),
        # side furniture
        _box((-2.7, 1.2, 0.45), (0.28, 0.7, 0.45), "cabinet"),
        _box((2.6, 0.8, 0.6), (0.35, 0.5, 0.6), "books", yaw=0.1),
        _box((-1.2, 1.9, 0.25), (0.25, 0.25, 0.25), "chair", yaw=0.5),
    ]


# --------------------------------------------------------------------------- people


@dataclass
class Person:
    """A human-sized articulated body (boxes for torso, head, arms and legs).

    Attributes
    ----------
    mode : 'walk' (back and forth along a line) or 'sit' (on a stool, moving head and limbs)
    base : (3,) float, walk: start point on the floor; sit: seat position on the floor
    direction : float, radians, walk: heading of the line; sit: facing direction
    span : float, metres, walk: length of the line walked back and forth
    speed : float, m/s, walking speed
    phase : float, seconds, offset of this person's motion in time
    shirt : str, material of the shirt
    carry : None, 'board' or 'box': an object carried in front of the body (not part of the
        person class: its own instance)
    pause : (start, duration) seconds during which a walking person stands still
    """

    mode: str
    base: tuple[float, float, float]
    direction: float
    span: float = 3.0
    speed: float = 0.8
    phase: float = 0.0
    shirt: str = "shirt_a"
    carry: str | None = None
    pause: tuple[float, float] | None = None

    def moving(self, s: float) -> bool:
        """Whether the person moves at time ``s`` (standing still during a pause)."""
        return self.pause is None or not self.pause[0] <= s < self.pause[0] + self.pause[1]

    def _clock(self, s: float) -> float:
        """Walking time: frozen during the pause."""
        if self.pause is None or s < self.pause[0]:
            return s
        return self.pause[0] if s < self.pause[0] + self.pause[1] else s - self.pause[1]

    def root_and_angles(self, s: float) -> tuple[np.ndarray, dict[str, float]]:
        """Body root pose (4, 4) in the world and joint angles (radians) at time ``s``."""
        s = self._clock(s) + self.phase
        if self.mode == "walk":
            period = 2.0 * self.span / self.speed
            u = (s % period) / period
            forward = u < 0.5
            dist = self.span * (2 * u if forward else 2 - 2 * u)
            heading = self.direction + (0.0 if forward else np.pi)
            d = np.array([np.cos(self.direction), np.sin(self.direction), 0.0])
            pos = np.asarray(self.base) + dist * d
            # body faces +y in its own frame; heading turns +y onto the walking direction
            R = _rz(heading - np.pi / 2)
            phi = 2.0 * np.pi * 0.9 * s  # 0.9 strides per second
            angles = {
                "hip_l": 0.45 * np.sin(phi), "hip_r": -0.45 * np.sin(phi),
                "knee_l": 0.6 * max(0.0, np.sin(phi + 1.2)), "knee_r": 0.6 * max(0.0, -np.sin(phi + 1.2)),
                "shoulder_l": -0.4 * np.sin(phi), "shoulder_r": 0.4 * np.sin(phi),
                "elbow_l": 0.3, "elbow_r": 0.3, "torso": 0.05, "head": 0.15 * np.sin(0.5 * phi),
                "bob": 0.02 * abs(np.sin(phi)),
            }
            return _pose(R, pos + [0.0, 0.0, angles["bob"]]), angles
        R = _rz(self.direction - np.pi / 2)
        angles = {  # seated: thighs forward, shins down, small movements of head, torso, arms
            "hip_l": 1.5, "hip_r": 1.5, "knee_l": -1.5, "knee_r": -1.5,
            "shoulder_l": 0.5 + 0.25 * np.sin(1.3 * s), "shoulder_r": 0.4 + 0.3 * np.sin(0.9 * s + 1),
            "elbow_l": 0.9 + 0.3 * np.sin(1.7 * s), "elbow_r": 1.0,
            "torso": 0.08 * np.sin(0.6 * s), "head": 0.35 * np.sin(0.8 * s + 0.5), "bob": 0.0,
        }
        return _pose(R, np.asarray(self.base) + [0.0, 0.0, -0.42]), angles

    def boxes(self, s: float, instance: int = 0, carried: int = 0) -> Group:
        """Body parts as boxes at time ``s``, grouped under one bounding box for culling;
        ``instance`` / ``carried``: instance ids of the body and of the carried object."""
        T_w_r, a = self.root_and_angles(s)
        parts: list[Box] = []

        def part(T_r_p, half, mat, inst=instance):
            parts.append(Box(T_w_r @ T_r_p, np.asarray(half, float), material(mat), dynamic=True, instance=inst))

        T_torso = _pose(_rx(a["torso"]), (0.0, 0.0, 0.87)) @ _pose(None, (0.0, 0.0, 0.28))
        part(T_torso, (0.18, 0.11, 0.28), self.shirt)
        T_head = T_torso @ _pose(so3_exp([0.0, 0.0, a["head"]]), (0.0, 0.0, 0.42))
        part(T_head, (0.09, 0.1, 0.11), "skin")
        for side, sx in (("l", -1.0), ("r", 1.0)):
            T_sh = T_torso @ _pose(_rx(a["shoulder_" + side]), (sx * 0.235, 0.0, 0.24))
            part(T_sh @ _pose(None, (0.0, 0.0, -0.15)), (0.05, 0.05, 0.15), self.shirt)
            T_el = T_sh @ _pose(_rx(a["elbow_" + side]), (0.0, 0.0, -0.3))
            part(T_el @ _pose(None, (0.0, 0.0, -0.13)), (0.04, 0.04, 0.13), "skin")
            T_hip = _pose(_rx(a["hip_" + side]), (sx * 0.1, 0.0, 0.87))
            part(T_hip @ _pose(None, (0.0, 0.0, -0.21)), (0.075, 0.08, 0.21), "trousers")
            T_kn = T_hip @ _pose(_rx(a["knee_" + side]), (0.0, 0.0, -0.42))
            part(T_kn @ _pose(None, (0.0, 0.0, -0.2)), (0.06, 0.07, 0.2), "trousers")
        if self.carry == "board":  # held upright in front of the chest, wider than the body
            part(_pose(None, (0.0, 0.3, 1.1)), (0.38, 0.02, 0.32), "poster", carried)
        elif self.carry == "box":
            part(_pose(None, (0.0, 0.32, 1.05)), (0.2, 0.16, 0.15), "cabinet", carried)
        # bounding box of the whole body: generous, centred on the root
        bound = Box(T_w_r @ _pose(None, (0.0, 0.0, 0.95)), np.array([0.75, 0.75, 1.0]), 0)
        return Group(bound, parts)


def furniture_names() -> list[str | None]:
    """The object (a key of :data:`FURNITURE`) each box of :func:`static_boxes` belongs to;
    None for the room."""
    return [None, None, None, "desk", "desk", "desk", "screen", "desk_box", "desk_books", "shelf", "cabinet",
            "poster_board", "poster", "side_cabinet", "side_books", "chair"]


def people_for(scene: str) -> list[Person]:
    """The people of a named scene (none for static_*)."""
    scene = EXPOSURE_SCENES.get(scene, scene)
    if scene == "walking_carry":
        return [  # one carries a board across the view, the other a box along the back
            Person("walk", (-1.9, 0.9, 0.0), 0.0, span=3.8, speed=0.75, phase=1.5, shirt="shirt_a", carry="board"),
            Person("walk", (1.6, 2.0, 0.0), np.pi - 0.15, span=3.2, speed=0.6, phase=0.0, shirt="shirt_b",
                   carry="box"),
        ]
    if scene == "walking_push":
        return [  # pushes the box (see movers_for); the other stands still for 2 s, then walks on
            Person("walk", PUSH_START - 0.55 * PUSH_DIR, float(np.arctan2(PUSH_DIR[1], PUSH_DIR[0])),
                   span=PUSH_SPAN, speed=PUSH_SPAN / (PUSH_T1 - PUSH_T0), phase=-PUSH_T0, shirt="shirt_b"),
            Person("walk", (1.6, 2.2, 0.0), np.pi - 0.15, span=3.0, speed=0.6, phase=0.5, shirt="shirt_a",
                   pause=(1.0, 2.0)),
        ]
    if scene == "crowd":
        return [  # one passes about 0.9 m in front of the camera, fast; two further back, one stops
            Person("walk", (-1.7, -0.1, 0.0), 0.0, span=3.4, speed=1.2, phase=0.3, shirt="shirt_b"),
            Person("walk", (-1.9, 0.9, 0.0), 0.0, span=3.8, speed=0.75, phase=1.5, shirt="shirt_a", pause=(2.5, 1.5)),
            Person("walk", (1.6, 2.0, 0.0), np.pi - 0.15, span=3.2, speed=0.6, phase=0.0, shirt="shirt_b"),
        ]
    if scene.startswith("walking"):
        return [
            # near person crossing the view about 2 m from the camera, far one behind
            Person("walk", (-1.9, 0.9, 0.0), 0.0, span=3.8, speed=0.75, phase=1.5, shirt="shirt_a"),
            Person("walk", (1.6, 2.0, 0.0), np.pi - 0.15, span=3.2, speed=0.6, phase=0.0, shirt="shirt_b"),
        ]
    if scene.startswith("sitting"):
        return [
            Person("sit", (-0.45, 1.95, 0.0), np.pi / 2 + 0.3, shirt="shirt_a"),
            Person("sit", (0.75, 1.85, 0.0), np.pi / 2 - 0.4, phase=2.0, shirt="shirt_b"),
        ]
    return []


# walking_push: a large box pushed 1.6 m across the floor, about 2 m ahead of the camera, between
# 1.0 s and 4.0 s. Textured (printed labels) and near: a dark chair further back held under 1 % of
# the matches and moved no pose, so it could not show what papers B and C do with a moving object
PUSH_START = np.array([-1.1, 0.9, 0.0])
PUSH_DIR = np.array([1.0, 0.15, 0.0]) / np.linalg.norm([1.0, 0.15, 0.0])
PUSH_SPAN = 1.6
PUSH_T0, PUSH_T1 = 1.0, 4.0


@dataclass
class Mover:
    """An object of a static class (a box, a chair) moved along the floor between t0 and t1 (seconds)."""

    cls: str
    half: tuple[float, float, float]
    mat: str
    start: np.ndarray
    direction: np.ndarray
    span: float
    t0: float
    t1: float

    def moving(self, s: float) -> bool:
        return self.t0 < s < self.t1

    def box(self, s: float, instance: int) -> Box:
        a = float(np.clip((s - self.t0) / (self.t1 - self.t0), 0.0, 1.0))
        centre = self.start + a * self.span * self.direction + [0.0, 0.0, self.half[2]]
        yaw = float(np.arctan2(self.direction[1], self.direction[0]))
        return _box(centre, self.half, self.mat, yaw=yaw, dynamic=True, instance=instance)


def movers_for(scene: str) -> list[Mover]:
    """Objects of static classes that move in a scene (walking_push's box, 0.64 x 0.56 x 0.8 m)."""
    if scene == "walking_push":
        return [Mover("box", (0.32, 0.28, 0.4), "poster", PUSH_START, PUSH_DIR, PUSH_SPAN, PUSH_T0, PUSH_T1)]
    return []


def chairs_for(scene: str) -> list[Box]:
    """Stools the seated people sit on."""
    if not scene.startswith("sitting"):
        return []
    return [_box((-0.45, 1.95, 0.22), (0.2, 0.2, 0.22), "chair"),
            _box((0.75, 1.85, 0.22), (0.2, 0.2, 0.22), "chair")]


# --------------------------------------------------------------------------- camera motion

CAMERA_HOME = np.array([0.0, -1.0, 1.35])
LOOK_TARGET = np.array([0.0, 1.6, 1.0])


def look_at(position: np.ndarray, target: np.ndarray) -> np.ndarray:
    """(4, 4) camera-to-world pose at ``position`` looking at ``target`` (x right, y down, z ahead)."""
    f = target - position
    f = f / np.linalg.norm(f)
    r = np.cross(f, [0.0, 0.0, 1.0])
    r = r / np.linalg.norm(r)
    down = np.cross(f, r)
    return _pose(np.stack([r, down, f], axis=1), position)


def camera_pose(pattern: str, s: float, jitter: np.ndarray) -> np.ndarray:
    """Camera-to-world pose of a motion pattern at time ``s`` seconds.

    Magnitudes follow the TUM fr3 sequences: 'static' nearly still (the camera on a tripod
    that is touched), 'xyz' translation along the three axes (about 0.2 m/s), 'rpy' rotation
    about the three axes (about 20-30 deg/s peaks), 'halfsphere' on a sphere around the desk.
    ``jitter`` (4, 3): amplitudes/frequencies/phases of small hand-held shake, from the seed.
    """
    home = look_at(CAMERA_HOME, LOOK_TARGET)
    shake = np.zeros(6)
    for amp, freq, ph in jitter:  # few-millimetre, sub-degree shake
        shake += amp * np.sin(2 * np.pi * freq * s + ph) * np.array([2e-3, 2e-3, 2e-3, 2e-3, 2e-3, 2e-3])
    if pattern == "static":
        delta = np.array([0.004 * np.sin(0.7 * s), 0.003 * np.sin(0.5 * s + 1), 0.004 * np.sin(0.3 * s),
                          0.004 * np.sin(0.4 * s), 0.005 * np.sin(0.6 * s + 2), 0.003 * np.sin(0.5 * s)])
        return home @ se3_exp(delta + shake)
    if pattern == "xyz":
        delta = np.array([0.35 * np.sin(2 * np.pi * s / 9.0), 0.15 * np.sin(2 * np.pi * s / 7.0 + 0.5),
                          0.3 * np.sin(2 * np.pi * s / 11.0 + 1.0), 0.0, 0.0, 0.0])
        return home @ se3_exp(delta + shake)
    if pattern == "rpy":
        delta = np.array([0.0, 0.0, 0.0, 0.22 * np.sin(2 * np.pi * s / 7.0),
                          0.3 * np.sin(2 * np.pi * s / 9.0 + 0.7), 0.2 * np.sin(2 * np.pi * s / 6.0 + 1.3)])
        return home @ se3_exp(delta + shake)
    if pattern == "halfsphere":
        target = LOOK_TARGET
        radius = np.linalg.norm(CAMERA_HOME - target)
        az = 0.45 * np.sin(2 * np.pi * s / 12.0)
        el = 0.25 * np.sin(2 * np.pi * s / 8.0 + 0.4)
        home_dir = (CAMERA_HOME - target) / radius
        base_az = np.arctan2(home_dir[1], home_dir[0])
        base_el = np.arcsin(home_dir[2])
        d = np.array([np.cos(base_el + el) * np.cos(base_az + az),
                      np.cos(base_el + el) * np.sin(base_az + az), np.sin(base_el + el)])
        return look_at(target + radius * d, target) @ se3_exp(shake)
    raise ValueError(f"unknown camera motion pattern {pattern!r}")


def pattern_of(scene: str) -> str:
    """Camera motion pattern of a scene: the part after the last underscore of the TUM analogues."""
    if scene not in SCENES:
        raise ValueError(f"unknown synthetic scene {scene!r}: choose one of {', '.join(SCENES)}")
    scene = EXPOSURE_SCENES.get(scene, scene)
    return _PATTERN.get(scene) or scene.rsplit("_", 1)[1]
