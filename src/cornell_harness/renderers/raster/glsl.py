"""Our GLSL shaders: package data under ``shaders/``, written out with their constants.

pyrender compiles shaders from files in a folder (``ShaderProgramCache(
shader_dir=...)``) and picks them by name: ``mesh.vert``/``mesh.frag`` for
the colour pass and ``mesh_depth.vert``/``mesh_depth.frag`` for shadow maps.
Each ``shaders/NAME.glsl`` is written as ``NAME`` into such a folder, with
its ``@CONSTANT@`` placeholders replaced by numbers (``%.9e``), since they
are per-scene and pyrender sets no uniforms of ours. pyrender itself then
turns ``#ifdef NAME`` into ``#if 1``/``#if 0`` and replaces each define's name
by its value (``NORMAL_LOC``, ``INST_M_LOC``, ``MAX_SPOT_LIGHTS``, ...).

(This module is not called ``shaders`` because the folder of ``.glsl``
files is.)
"""

from __future__ import annotations

import importlib.resources
import os

#: Shadow-test bias on the distance to the light, in shadow-map texels at the shaded
#: point: SLOPE_BIAS * tan(angle of incidence) + CONST_BIAS. Tuned against Mitsuba's
#: direct lighting (max_depth 2) on the Cornell box: no acne, penumbrae within ~1%.
SHADOW_BIAS = {"SLOPE_BIAS": 2.0, "CONST_BIAS": 1.0}

#: The direct-lighting shaders, under the names pyrender looks for.
DIRECT_LIGHTING = ("mesh.vert", "mesh.frag", "mesh_depth.vert", "mesh_depth.frag")


def shader_source(name: str) -> str:
    """The text of ``shaders/<name>.glsl``, placeholders and all."""
    return (importlib.resources.files(__package__) / "shaders" / f"{name}.glsl").read_text(encoding="utf-8")


def write_shaders(folder: str, names: tuple[str, ...], constants: dict[str, float]) -> None:
    """Write each ``shaders/<name>.glsl`` to ``folder/<name>`` with ``@KEY@`` replaced by ``constants[KEY]``."""
    subs = {f"@{k}@": f"{v:.9e}" for k, v in constants.items()}
    for name in names:
        text = shader_source(name)
        for k, v in subs.items():
            text = text.replace(k, v)
        with open(os.path.join(folder, name), "w", encoding="utf-8") as f:
            f.write(text)


def write_direct_lighting_shaders(folder: str, dist_scale: float, texel_angle: float) -> None:
    """The direct-lighting shaders for a scene of size ``dist_scale`` (K: shadow maps store
    d/(d+K)) and shadow-map texels subtending at most ``texel_angle``."""
    write_shaders(folder, DIRECT_LIGHTING, {"DIST_SCALE": dist_scale, "TEXEL_ANGLE": texel_angle, **SHADOW_BIAS})
