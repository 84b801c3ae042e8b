"""A minimal stand-in for an animated scene, as the scene model's contract names it, and camera arcs.

The stateful renderers walk a sequence through ``scene.frame_count``,
``scene.at_frame(i)`` (a still :class:`cornell_harness.scenes.model.Scene`) and
``scene.animation.offset(name, i)`` (an object's translation) /
``scene.animation.camera_at(i)``; :class:`StandIn` gives exactly these over a
list of still scenes, so the renderers' tests need no animated scene file.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from cornell_harness.scenes.model import Camera, Scene


class StandInAnimation:
    def __init__(self, frames: list[Scene], offsets: dict[str, list] | None = None):
        self.frames, self.offsets, self.fps = len(frames), offsets or {}, 30.0
        self._cameras = [s.camera for s in frames]

    def camera_at(self, i: int) -> Camera:
        return self._cameras[i]

    def offset(self, name: str, i: int) -> np.ndarray:
        track = self.offsets.get(name)
        return np.zeros(3) if track is None else np.asarray(track[i], dtype=np.float64)


class StandIn:
    """An animated scene made of its frames' still scenes (frame i: ``frames[i]``)."""

    def __init__(self, frames: list[Scene], offsets: dict[str, list] | None = None):
        self.frames = list(frames)
        self.animation = StandInAnimation(self.frames, offsets)
        self.name = frames[0].name
        self.camera = frames[0].camera

    @property
    def frame_count(self) -> int:
        return len(self.frames)

    def at_frame(self, i: int) -> Scene:
        return self.frames[i]

    def object_names(self) -> tuple[str, ...]:
        return self.frames[0].object_names()


def orbit(camera: Camera, degrees: float, centre=(0.0, 0.0, 0.0)) -> Camera:
    """``camera`` turned by ``degrees`` about the vertical axis through ``centre`` (position and look-at): a step
    of a camera's arc around a static scene."""
    a = math.radians(degrees)
    rot = np.array([[math.cos(a), 0.0, math.sin(a)], [0.0, 1.0, 0.0], [-math.sin(a), 0.0, math.cos(a)]])
    c = np.asarray(centre, dtype=np.float64)

    def turn(p):
        return tuple(float(v) for v in rot @ (np.asarray(p, dtype=np.float64) - c) + c)

    return dataclasses.replace(camera, position=turn(camera.position), look_at=turn(camera.look_at))


def still_sequence(scene: Scene, frames: int) -> StandIn:
    """``scene`` unchanged for ``frames`` frames: a static sequence."""
    return StandIn([scene] * frames)


def arc_sequence(scene: Scene, degrees_per_frame: float, frames: int) -> StandIn:
    """``scene`` seen by a camera that orbits it, ``degrees_per_frame`` per frame."""
    return StandIn([dataclasses.replace(scene, camera=orbit(scene.camera, i * degrees_per_frame))
                    for i in range(frames)])
