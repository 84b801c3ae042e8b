"""Animated scenes: a scene file's ``[animation]``, and the still scene of each frame.

An animated scene is a still scene (the file's geometry, camera and lights) plus :class:`Animation`:
``frames`` frames shown at ``fps`` frames per second, and

- **object tracks** (``[animation.objects]``, ``NAME = [{frame = 0, translate = [x, y, z]}, ...]``): the named
  mesh or sphere (the light is a mesh) is translated by the keyed offset, relative to its position in the file;
- a **camera track** (``animation.camera = [{frame = 0, position = [...], look_at = [...]}, ...]``): the camera's
  position and its look-at target are keyed; its orientation is the one looking from ``position`` to ``look_at``
  with the file's ``up``, so keying the target rotates it. Field of view and resolution stay the file's;
- **light switches** (``[[animation.switches]]``, ``object``, ``frame``, ``on``): the named emitter is off (its
  radiance 0) or on (the file's radiance) from ``frame`` on, until the next switch; every light is on at frame 0
  unless a switch at frame 0 says otherwise.

Tracks are piecewise linear in the frame number between their keys (keys at increasing integer frames in
``[0, frames)``) and hold their first and last keys' values before and after them. Frame ``i`` is at time
``i / fps`` seconds; the keys are given in frames so that a frame's scene is exact, not a rounded time.

:meth:`Animation.scene_at` makes frame ``i``'s still scene (``Scene.at_frame``): its
:attr:`~cornell_harness.scenes.model.Scene.frame` is ``i``, which enters its content hash. Named regions stay where
the file puts them.

**Frames that share a reference.** What an animation sets at a frame is its **state** (:meth:`Animation.state`):
each tracked object's offset, the camera's keyed position and target, each switched emitter on or off, computed at
that frame (not read off the keys). Two frames with equal states are the same still scene but for the frame index,
so they have the same expected image and share one reference: the earliest such frame's
(:meth:`Animation.reference_frame`; :func:`reference_still` is that frame's still scene). A light at rest after its
motion is one reference for every frame of the rest; a light switched back on where it was shares the reference of
the frames before it went off; a camera that moves every frame shares nothing.
"""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass

import numpy as np

from cornell_harness.schemas.reader import key_text
from cornell_harness.scenes.model import Camera, Scene, one_line
from cornell_harness.suggest import closest

#: The folder of an animated scene's per-frame references, beside its file: ``frames/0007/`` for frame 7.
FRAMES_FOLDER = "frames"


@dataclass(frozen=True)
class Track:
    """A piecewise linear function of the frame number: ``values[k]`` at ``frames[k]`` (increasing)."""

    frames: tuple[int, ...]
    values: tuple[tuple[float, ...], ...]

    def at(self, i: float) -> np.ndarray:
        """The value at frame ``i``: interpolated linearly between keys, held outside them (float64)."""
        return self.over([i])[0]

    def over(self, frames) -> np.ndarray:
        """The values at each of ``frames``, a row per frame: :meth:`at`'s, in one pass (float64)."""
        v, f = np.asarray(self.values, dtype=np.float64), np.asarray(frames, dtype=np.float64)
        return np.stack([np.interp(f, self.frames, v[:, d]) for d in range(v.shape[1])], axis=-1)

    def scaled(self, s: float) -> "Track":
        return Track(self.frames, tuple(tuple(x * s for x in row) for row in self.values))


@dataclass(frozen=True)
class Switch:
    """The emitter ``object`` is on (``on``) or off from ``frame`` on, until its next switch."""

    object: str
    frame: int
    on: bool


@dataclass(frozen=True)
class Animation:
    """What moves in an animated scene, and when; the still scene of a frame is :meth:`Scene.at_frame`'s."""

    frames: int
    fps: float
    camera: Camera  # the file's camera: what camera_at keys position and look_at of
    camera_track: Track | None = None  # values: position (3) then look_at (3)
    objects: dict[str, Track] = dataclasses.field(default_factory=dict)  # translations, by object name
    switches: tuple[Switch, ...] = ()  # by object, then frame

    def check_frame(self, i: int) -> int:
        """``i`` as an int, refused (IndexError) outside ``[0, frames)``."""
        if not (isinstance(i, (int, np.integer)) and 0 <= i < self.frames):
            raise IndexError(f"frame {i!r} is outside the animation's frames 0..{self.frames - 1}")
        return int(i)

    def camera_at(self, i: int) -> Camera:
        """The camera of frame ``i``: the file's, with the camera track's position and look-at target."""
        self.check_frame(i)
        if self.camera_track is None:
            return self.camera
        v = self.camera_track.at(i)
        return dataclasses.replace(self.camera, position=tuple(map(float, v[:3])), look_at=tuple(map(float, v[3:])))

    def offset(self, name: str, i: int) -> np.ndarray:
        """The translation (3,) of object ``name`` at frame ``i`` from its position in the file; zeros without a track."""
        self.check_frame(i)
        track = self.objects.get(name)
        return np.zeros(3) if track is None else track.at(i)

    def light_on(self, name: str, i: int) -> bool:
        """Whether emitter ``name`` shines at frame ``i``: the last switch at or before ``i`` says; on without one."""
        self.check_frame(i)
        state = True
        for s in self.switches:
            if s.object == name and s.frame <= i:
                state = s.on
        return state

    def states(self, frames) -> np.ndarray:
        """Everything this animation sets at each of ``frames``, a row (float64) per frame: each tracked object's
        offset (by name), the camera track's position and target, each switched emitter's 1 (on) or 0 (off) (by
        name), as :meth:`offset`, :meth:`camera_at` and :meth:`light_on` compute them. Frames with equal rows are
        the same still scene but for their index."""
        frames = [self.check_frame(i) for i in frames]
        tracks = [self.objects[name] for name in sorted(self.objects)] + [t for t in [self.camera_track] if t]
        columns = [t.over(frames) for t in tracks]
        columns += [np.array([[float(self.light_on(name, i))] for i in frames])
                    for name in sorted({s.object for s in self.switches})]
        return np.concatenate([np.zeros((len(frames), 0)), *columns], axis=1)

    def reference_frame(self, i: int) -> int:
        """The frame whose reference frame ``i`` reads: the smallest ``j <= i`` whose state (:meth:`states`) equals
        frame ``i``'s, exactly (a track holding its value, or between two equal keys, gives the same floats every
        frame; what only rounds alike is not shared)."""
        states = self.states(range(self.check_frame(i) + 1))
        return int(np.flatnonzero(np.all(states == states[-1], axis=1))[0])

    def reference_frames(self) -> list[int]:
        """The distinct references' frames, in order: each frame that is its own :meth:`reference_frame`."""
        return [i for i in range(self.frames) if self.reference_frame(i) == i]

    def scene_at(self, scene: Scene, i: int) -> Scene:
        """The still scene of frame ``i`` of ``scene`` (whose animation this is): objects moved, camera keyed,
        lights switched (``Scene.at_frame``), with the frame whose reference it shares (:meth:`reference_frame`)."""
        i = self.check_frame(i)
        meshes = []
        for m in scene.meshes:
            if m.name in self.objects:
                m = dataclasses.replace(m, vertices=m.vertices + self.offset(m.name, i))
            if m.is_emitter and not self.light_on(m.name, i):
                m = dataclasses.replace(m, radiance=(0.0, 0.0, 0.0))
            meshes.append(m)
        spheres = tuple(dataclasses.replace(s, center=tuple(map(float, np.add(s.center, self.offset(s.name, i)))))
                        if s.name in self.objects else s for s in scene.spheres)
        return dataclasses.replace(scene, camera=self.camera_at(i), meshes=tuple(meshes), spheres=spheres,
                                   animation=None, frame=i, reference_frame=self.reference_frame(i))

    def with_camera(self, camera: Camera) -> "Animation":
        return dataclasses.replace(self, camera=camera)

    def scaled(self, s: float) -> "Animation":
        """The animation with every length times ``s`` (the file's ``length_scale``); ``camera`` is replaced apart."""
        return dataclasses.replace(
            self, camera_track=self.camera_track.scaled(s) if self.camera_track else None,
            objects={k: t.scaled(s) for k, t in self.objects.items()})

    def hash_payload(self) -> dict:
        """What enters an animated scene's content hash (the file's camera is the scene's own)."""
        track = (lambda t: None if t is None else {"frames": list(t.frames), "values": [list(v) for v in t.values]})
        return {"frames": self.frames, "fps": self.fps, "camera": track(self.camera_track),
                "objects": {k: track(t) for k, t in sorted(self.objects.items())},
                "switches": [dataclasses.asdict(s) for s in self.switches]}


def parse_animation(err, t: dict, scene: Scene, scale: float = 1.0) -> Animation:
    """The ``[animation]`` table ``t`` (checked by the scene schema) of the loaded ``scene`` (its lengths already
    times the file's ``length_scale``, ``scale``); ``err(field, message)`` is the loader's error of the file.

    Checked here: key frames below ``frames`` and increasing, names of objects and emitters, and the camera's
    frame at every frame (look_at not its position, up not along the view)."""
    frames = t["frames"]
    objects = [m.name for m in scene.meshes] + [s.name for s in scene.spheres]
    tracks = {}
    for name, keys in t.get("objects", {}).items():
        w = f"animation.objects.{key_text(name)}"
        if name not in objects:
            raise err(w, f"no object named {one_line(name, 60)!r}{_hint(name, objects)}")
        tracks[name] = _track(err, w, keys, frames, lambda k: k["translate"], scale)
    camera_track = None
    if "camera" in t:
        camera_track = _track(err, "animation.camera", t["camera"], frames, lambda k: [*k["position"], *k["look_at"]],
                              scale)
    emitters = [m.name for m in scene.emitters]
    switches = []
    for j, s in enumerate(t.get("switches", [])):
        w = f"animation.switches[{j}]"
        if s["object"] not in emitters:
            raise err(f"{w}.object", f"no emitter named {one_line(s['object'], 60)!r}{_hint(s['object'], emitters)}")
        if s["frame"] >= frames:
            raise err(f"{w}.frame", f"frame {s['frame']} is past the last frame, {frames - 1}")
        if scene.spectral is not None:
            raise err(w, "a spectral scene's lights cannot be switched: their emission spectra stay on")
        switches.append(Switch(s["object"], s["frame"], s["on"]))
    anim = Animation(frames, float(t["fps"]), scene.camera, camera_track, tracks,
                     tuple(sorted(switches, key=lambda s: (s.object, s.frame))))
    for i in range(frames if camera_track else 0):
        _check_camera(err, anim.camera_at(i), i)
    return anim


def _hint(name: str, known: list[str]) -> str:
    close = closest(name, known)
    return f"; did you mean {close!r}?" if close else f"; known: {', '.join(known) or '(none)'}"


def _track(err, where: str, keys: list, frames: int, value, scale: float) -> Track:
    previous = -1
    for k, key in enumerate(keys):
        if key["frame"] >= frames:
            raise err(f"{where}[{k}].frame", f"frame {key['frame']} is past the last frame, {frames - 1}")
        if key["frame"] <= previous:
            raise err(f"{where}[{k}].frame", f"frame {key['frame']} is not after the previous key's, {previous}")
        previous = key["frame"]
    return Track(tuple(k["frame"] for k in keys), tuple(tuple(float(x) * scale for x in value(k)) for k in keys))


def _check_camera(err, camera: Camera, i: int) -> None:
    forward = np.subtract(camera.look_at, camera.position)
    if np.linalg.norm(forward) == 0.0:
        raise err("animation.camera", f"at frame {i} look_at equals position")
    if np.linalg.norm(np.cross(forward, camera.up)) <= 1e-9 * np.linalg.norm(forward) * np.linalg.norm(camera.up):
        raise err("animation.camera", f"at frame {i} camera.up is parallel to the viewing direction")


_RANGE = re.compile(r"\s*(\d+)\s*(?:-\s*(\d+)\s*)?")


def frame_list(text: str, count: int) -> list[int]:
    """The frames a ``--frames`` text names (``0-3,7``: 0, 1, 2, 3 and 7), sorted, each once; ValueError with
    one line when one is malformed or outside ``[0, count)``."""
    frames: set[int] = set()
    for part in text.split(","):
        match = _RANGE.fullmatch(part)
        if not match:
            raise ValueError(f"{part.strip()!r} is not a frame or a range A-B of frames (e.g. 0-3,7)")
        lo = int(match.group(1))
        hi = int(match.group(2)) if match.group(2) is not None else lo
        if lo > hi or hi >= count:
            raise ValueError(f"{part.strip()!r}: frames are 0..{count - 1}, a range A-B with A <= B")
        frames.update(range(lo, hi + 1))
    return sorted(frames)


def reference_still(still: Scene) -> Scene:
    """The still scene whose reference ``still`` reads: ``still`` itself, or for a frame of an animated scene
    (``Scene.at_frame``) the frame it shares its reference with (:meth:`Animation.reference_frame`), which is the
    same still scene but for ``frame``."""
    if still.frame is None or still.reference_frame in (None, still.frame):
        return still
    return dataclasses.replace(still, frame=still.reference_frame)


def frame_folder(i: int) -> str:
    """The per-frame reference folder's path beside the scene file: ``frames/0007``."""
    return f"{FRAMES_FOLDER}/{i:04d}"
