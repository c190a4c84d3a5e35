"""Write a synthetic dynamic RGB-D sequence in the TUM layout.

Output folder::

    rgb/, depth/, rgb.txt, depth.txt   colour 8-bit / depth 16-bit (5000 per metre) PNGs
    groundtruth.txt                    camera-to-world at 100 Hz (mocap-like, exact)
    masks/, masks.txt                  ground-truth moving-object masks, 255 = moving
    instances/, instances.json         object instance ids per pixel (8-bit, 0 = room), each id's
                                       class (person, board, box, chair, table, ...) and per frame
                                       the ids that move
    background/, background.txt        (with background=True) frames without the people
    camera.txt                         fx fy cx cy width height depth_scale
    exposure.txt                       (scenes with automatic exposure) per colour frame the gain
                                       and bias applied to the image brightness
    scene.json                         scene, seed, frame count, generator version

Colour timestamps are 30 Hz with 1.5 ms jitter; depth timestamps are up to 8 ms away from
them, so colour and depth must be associated as with real TUM data.
"""
from __future__ import annotations

import json
import os
import shutil
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from ..errors import ConfigError
from ..geometry import PinholeCamera
from ..io import Trajectory, format_trajectory
from .raycast import pixel_rays, render
from .scene import (EXPOSURE_SCENES, FURNITURE, SCENES, camera_pose, chairs_for, furniture_names, movers_for, pattern_of,
                    people_for, static_boxes)
from .sensor import degrade_depth, degrade_rgb
from .textures import make_textures

# fr3-like intrinsics (TUM fr3 calibration), 640x480
SYNTH_CAMERA = PinholeCamera(535.4, 539.2, 320.1, 247.6, 640, 480, 5000.0, name="synthetic")
FPS = 30.0
GT_RATE_HZ = 100.0
T0 = 1600000000.0
GENERATOR_VERSION = 3
# scenes changed since version 3 carry their own version; files of the others stay valid
SCENE_VERSION = {"walking_push": 4}  # 4: the pushed object is a large printed box (was a dark chair)


def version_of(scene: str) -> int:
    """The generator version written into (and expected in) a scene's ``scene.json``."""
    return SCENE_VERSION.get(scene, GENERATOR_VERSION)


def exposure_schedule(scene: str, seed: int, frames: int) -> tuple[np.ndarray, np.ndarray]:
    """Per frame the (gain, bias) of the image brightness, ``I' = clip(gain I + bias, 0, 1)``
    before the sensor noise; (1, 0) throughout for the scenes without automatic exposure.

    A camera with automatic exposure (:data:`EXPOSURE_SCENES`) changes it every 10-13 frames:
    the gain by 4-10 % (within exp(+-0.2) of 1), the bias to a new value in [-0.025, 0.025]:
    the median intensity of the room moves by 0.02-0.08 (5-20 grey levels) at a change, as on
    the Bonn dev clip (up to 0.074 there). Frame i's values depend on the seed and i alone, not on
    the frame count.
    """
    gain, bias = np.ones(frames), np.zeros(frames)
    if scene not in EXPOSURE_SCENES:
        return gain, bias
    rng = np.random.default_rng([seed, 5])
    g, i = 1.0, int(rng.integers(10, 14))
    while i < frames:
        step = rng.uniform(0.04, 0.10) * rng.choice((-1.0, 1.0))
        if abs(np.log(g) + step) > 0.2:
            step = -step
        g *= np.exp(step)
        gain[i:], bias[i:] = g, rng.uniform(-0.025, 0.025)
        i += int(rng.integers(10, 14))
    return gain, bias


LIGHT_W = np.array([0.3, -0.5, 0.81]) / np.linalg.norm([0.3, -0.5, 0.81])


@dataclass
class SynthStats:
    """What a generator run did: folder, frames written and seconds spent."""

    path: Path
    frames: int
    seconds: float

    @property
    def frames_per_s(self) -> float:
        return self.frames / max(self.seconds, 1e-9)


class SceneRenderer:
    """Renders frames of one named scene; deterministic for (scene, seed)."""

    def __init__(self, scene: str, seed: int = 0, camera: PinholeCamera = SYNTH_CAMERA):
        self.scene = scene
        self.pattern = pattern_of(scene)
        self.seed = int(seed)
        self.camera = camera
        self.textures = make_textures(self.seed)
        self.people = people_for(scene)
        self.movers = movers_for(scene)
        # instance ids: people, their carried objects, moved objects, then the furniture
        self.classes: dict[int, str] = {}
        self.person_ids = [self._new_id("person") for _ in self.people]
        self.carried_ids = [self._new_id(p.carry) if p.carry else 0 for p in self.people]
        self.mover_ids = [self._new_id(m.cls) for m in self.movers]
        self.static = static_boxes() + chairs_for(scene)
        names = furniture_names() + ["chair"] * (len(self.static) - len(furniture_names()))
        ids: dict[str, int] = {}
        for k, (box, name) in enumerate(zip(self.static, names)):
            if name is not None:
                key = name if k < len(furniture_names()) else f"stool{k}"
                if key not in ids:
                    ids[key] = self._new_id(FURNITURE.get(name, name))
                box.instance = ids[key]
        rng = np.random.default_rng([self.seed, 1])
        self.jitter = np.stack(
            [rng.uniform(0.3, 1.0, 4), rng.uniform(0.5, 3.0, 4), rng.uniform(0, 2 * np.pi, 4)], axis=1
        )
        self.rays = pixel_rays(camera)

    def _new_id(self, cls: str) -> int:
        k = len(self.classes) + 1
        self.classes[k] = cls
        return k

    def pose(self, s: float) -> np.ndarray:
        """(4, 4) camera-to-world at ``s`` seconds after the first frame."""
        return camera_pose(self.pattern, s, self.jitter)

    def moving_ids(self, s: float) -> list[int]:
        """Instance ids of the objects that move at time ``s`` (a person standing still does not;
        a carried object moves with its carrier)."""
        out = []
        for p, pid, cid in zip(self.people, self.person_ids, self.carried_ids):
            if p.moving(s):
                out += [pid] + ([cid] if cid else [])
        return out + [mid for m, mid in zip(self.movers, self.mover_ids) if m.moving(s)]

    def frame(self, index: int, s: float, with_people: bool = True):
        """Render frame ``index`` at time ``s``: (rgb uint8, depth float32 m, moving mask bool,
        instance ids uint8). Without people, the moving objects are left out too (the background)."""
        groups = ([p.boxes(s, pid, cid) for p, pid, cid in zip(self.people, self.person_ids, self.carried_ids)]
                  if with_people else [])
        boxes = self.static + ([m.box(s, mid) for m, mid in zip(self.movers, self.mover_ids)] if with_people else [])
        rgb, depth, _, no_depth, instance = render(
            self.camera, self.pose(s), boxes, groups, self.textures, LIGHT_W, self.rays
        )
        if self.scene in EXPOSURE_SCENES:
            gain, bias = (float(x[index]) for x in exposure_schedule(self.scene, self.seed, index + 1))
            rgb = np.clip(np.float32(gain) * rgb + np.float32(bias), 0.0, 1.0)
        moving = np.isin(instance, self.moving_ids(s))
        rng = np.random.default_rng([self.seed, 2, index])  # per frame: order-independent
        return degrade_rgb(rgb, rng), degrade_depth(depth, no_depth, rng), moving, instance


def _timestamps(frames: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng([seed, 3])
    t_rgb = T0 + np.arange(frames) / FPS + rng.normal(0.0, 0.0015, frames).clip(-0.005, 0.005)
    t_depth = t_rgb + rng.uniform(-0.008, 0.008, frames)
    return t_rgb, t_depth


def generate(
    out_dir: str | Path,
    scene: str,
    frames: int = 300,
    seed: int = 0,
    background: bool = False,
    progress: bool = False,
    people_from: Path | None = None,
) -> SynthStats:
    """Generate a synthetic sequence into ``out_dir`` (replaced as a whole when complete).

    Parameters
    ----------
    scene : one of :data:`SCENES`
    frames : number of frames (30 Hz)
    seed : textures, sensor noise, camera shake and timestamps derive from it
    background : also write every frame rendered without the people, colour (``background/``)
        and depth (``background_depth/``, same names), for inpainting scores
    people_from : a folder this generator wrote for the same scene, frames and seed without the
        background: its frames are copied, not rendered again (every frame depends on the
        scene, seed and index alone, so the files are the same)
    """
    if scene not in SCENES:
        raise ConfigError(f"unknown synthetic scene {scene!r}: choose one of {', '.join(SCENES)}")
    if frames <= 0:
        raise ConfigError(f"frames must be positive, got {frames}")
    out_dir = Path(out_dir)
    if out_dir.exists() and any(out_dir.iterdir()) and not (out_dir / "scene.json").is_file():
        raise FileExistsError(f"{out_dir}: exists and is not a synthetic sequence; not overwriting")
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=out_dir.parent, prefix=f".{out_dir.name}.tmp-"))
    start = time.perf_counter()
    try:
        renderer = SceneRenderer(scene, seed)
        cam = renderer.camera
        for sub in ("rgb", "depth", "masks", "instances") + (("background", "background_depth") if background else ()):
            (tmp / sub).mkdir()
        t_rgb, t_depth = _timestamps(frames, seed)
        # zlib strategies measured on these frames: Huffman coding alone for the noisy colour
        # (smaller and faster to write and read than LZ77), run lengths for depth and labels
        png = [cv2.IMWRITE_PNG_COMPRESSION, 1, cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_HUFFMAN_ONLY]
        png_rle = [cv2.IMWRITE_PNG_COMPRESSION, 1, cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_RLE]
        names = [f"{t:.6f}.png" for t in t_rgb]
        dnames = [f"{t:.6f}.png" for t in t_depth]
        moving_ids: list[list[int]] = []
        iterator = range(frames)
        if progress:
            from tqdm import tqdm

            iterator = tqdm(iterator, desc=f"synth {scene}", unit="frame")
        for i in iterator:
            s = t_rgb[i] - T0
            if people_from is not None:
                for sub, name in (("rgb", names[i]), ("depth", dnames[i]), ("masks", names[i]), ("instances", names[i])):
                    shutil.copyfile(Path(people_from) / sub / name, tmp / sub / name)
            else:
                rgb, depth, moving, instance = renderer.frame(i, s)
                cv2.imwrite(str(tmp / "rgb" / names[i]), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), png)
                cv2.imwrite(str(tmp / "depth" / dnames[i]), np.round(depth * 5000).astype(np.uint16), png_rle)
                cv2.imwrite(str(tmp / "masks" / names[i]), moving.astype(np.uint8) * 255, png_rle)
                cv2.imwrite(str(tmp / "instances" / names[i]), instance, png_rle)
            moving_ids.append(renderer.moving_ids(s))
            if background:
                bg, bg_depth, _, _ = renderer.frame(i, s, with_people=False)
                cv2.imwrite(str(tmp / "background" / names[i]), cv2.cvtColor(bg, cv2.COLOR_RGB2BGR), png)
                cv2.imwrite(str(tmp / "background_depth" / names[i]),
                            np.round(bg_depth * 5000).astype(np.uint16), png_rle)

        def listing(title, sub, stamps, files):
            rows = [f"# {title}", "# timestamp filename"]
            rows += [f"{t:.6f} {sub}/{f}" for t, f in zip(stamps, files)]
            (tmp / f"{sub}.txt").write_text("\n".join(rows) + "\n")

        listing("color images", "rgb", t_rgb, names)
        listing("depth maps", "depth", t_depth, dnames)
        listing("ground-truth moving-object masks (255 = moving)", "masks", t_rgb, names)
        if background:
            listing("colour frames rendered without moving objects", "background", t_rgb, names)
        (tmp / "instances.json").write_text(json.dumps(
            {"classes": {str(k): c for k, c in renderer.classes.items()},
             "moving": {f"{t:.6f}": ids for t, ids in zip(t_rgb, moving_ids)}}, indent=1) + "\n")
        t_gt = np.arange(t_rgb[0] - 0.1, t_rgb[-1] + 0.1, 1.0 / GT_RATE_HZ)
        gt = Trajectory(t_gt, np.stack([renderer.pose(t - T0) for t in t_gt]))
        (tmp / "groundtruth.txt").write_text(
            "# ground truth trajectory (synthetic, exact)\n" + format_trajectory(gt)
        )
        if scene in EXPOSURE_SCENES:
            gain, bias = exposure_schedule(scene, seed, frames)
            (tmp / "exposure.txt").write_text("# image brightness of each colour frame: I' = gain I + bias\n"
                                              "# timestamp gain bias\n" + "".join(
                f"{t:.6f} {g:.6f} {b:.6f}\n" for t, g, b in zip(t_rgb, gain, bias)))
        (tmp / "camera.txt").write_text(
            "# fx fy cx cy width height depth_scale\n"
            f"{cam.fx} {cam.fy} {cam.cx} {cam.cy} {cam.width} {cam.height} {cam.depth_scale:g}\n"
        )
        (tmp / "scene.json").write_text(json.dumps(
            {"scene": scene, "frames": frames, "seed": seed, "background": background,
             "generator_version": version_of(scene)}, indent=2) + "\n")
        if out_dir.exists():
            shutil.rmtree(out_dir)
        os.replace(tmp, out_dir)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return SynthStats(out_dir, frames, time.perf_counter() - start)


def ensure_scene(
    cache_dir: str | Path, scene: str, frames: int, seed: int = 0, background: bool = False
) -> Path:
    """Path of a generated scene in ``cache_dir``, generating it only when missing or stale."""
    plain = Path(cache_dir) / f"{scene}_n{frames}_s{seed}"
    path = plain.with_name(plain.name + "_bg") if background else plain

    def current(folder: Path) -> bool:
        meta = folder / "scene.json"
        return meta.is_file() and json.loads(meta.read_text()).get("generator_version") == version_of(scene)

    if not current(path):
        # with the background: the frames with people are copied from the plain scene when it exists
        generate(path, scene, frames, seed, background, people_from=plain if background and current(plain) else None)
    return path
