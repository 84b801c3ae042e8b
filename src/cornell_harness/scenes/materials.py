"""The materials a scene may use: each type's fields, their ranges, its feature and its meaning.

A material type is one frozen dataclass below, listed in
:data:`MATERIAL_TYPES`; everything else reads it from there: the loader
parses a ``[materials.NAME]`` table from the dataclass's fields, the scene's
feature set and content hash come from it, and renderers dispatch on the
class. Adding a material is adding a class here (and teaching the renderers
that can model it; the others skip scenes that use its feature).

Field kinds (``metadata["kind"]`` of each field):

- ``"rgb01"``: three numbers in [0, 1], linear sRGB (the scene's colour
  space, :mod:`cornell_harness.scenes.model`);
- ``"ior"``: an index of refraction, a number in (0, :data:`MAX_IOR`].

All three types follow Mitsuba 3's plugins of the same meaning, which the
reference renders with (``diffuse``, ``conductor`` with ``material = "none"``,
``dielectric``); see each class.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import ClassVar

#: Largest index of refraction accepted (diamond is 2.42; 10 leaves room without inviting nonsense).
MAX_IOR = 10.0


def _rgb01(doc: str):
    return field(metadata={"kind": "rgb01", "doc": doc})


def _ior(doc: str, default: float | None = None):
    if default is None:
        return field(metadata={"kind": "ior", "doc": doc})
    return field(default=default, metadata={"kind": "ior", "doc": doc})


@dataclass(frozen=True)
class Diffuse:
    """Lambertian BRDF ρ/π, front side only (Mitsuba 3 ``diffuse``; pbrt-v4 §9.2)."""

    type: ClassVar[str] = "diffuse"
    feature: ClassVar[str] = "diffuse"
    is_delta: ClassVar[bool] = False

    name: str
    reflectance: tuple[float, float, float] = _rgb01("albedo per channel")


@dataclass(frozen=True)
class Mirror:
    """A smooth conductor with a constant specular reflectance R: ωi = reflect(ωo), weight R.

    Front side only. Mitsuba 3 ``conductor`` with ``material = "none"``
    (Fresnel factor 1) and ``specular_reflectance = R`` (pbrt-v4 §9.3 with a
    perfect-mirror Fresnel term).
    """

    type: ClassVar[str] = "mirror"
    feature: ClassVar[str] = "mirror"
    is_delta: ClassVar[bool] = True

    name: str
    reflectance: tuple[float, float, float] = _rgb01("specular reflectance per channel")


@dataclass(frozen=True)
class Dielectric:
    """A smooth dielectric interface (glass): exact Fresnel reflection and Snell refraction, both sides.

    Mitsuba 3 ``dielectric`` (pbrt-v4 §9.3 ``DielectricBxDF``, smooth case):
    the front side faces the exterior medium (index ``ext_ior``), the back
    side the interior (``int_ior``). Reflection and refraction are chosen in
    proportion to the unpolarised Fresnel reflectance; past the critical
    angle all light is reflected (total internal reflection). Radiance
    crossing into a medium is scaled by (η_incident/η_transmitted)², as
    Mitsuba does in radiance transport (Veach 1997, §5.2).
    """

    type: ClassVar[str] = "dielectric"
    feature: ClassVar[str] = "dielectric"
    is_delta: ClassVar[bool] = True

    name: str
    int_ior: float = _ior("index of refraction inside (behind the surface normal)")
    ext_ior: float = _ior("index of refraction outside (in front of the surface normal)", 1.0)

    @property
    def eta(self) -> float:
        """Relative index of refraction int_ior / ext_ior."""
        return self.int_ior / self.ext_ior


Material = Diffuse | Mirror | Dielectric

#: Every material type by the name a scene file gives in ``type``.
MATERIAL_TYPES: dict[str, type] = {cls.type: cls for cls in (Diffuse, Mirror, Dielectric)}


def material_fields(cls: type) -> tuple[dataclasses.Field, ...]:
    """The fields a scene file gives for material type ``cls`` (all but ``name``)."""
    return tuple(f for f in dataclasses.fields(cls) if f.name != "name")


def hash_payload(material) -> dict:
    """What the scene's content hash reads of a material.

    A diffuse material hashes without its type, as it did before other types
    existed, so the stored references of Lambertian scenes stay valid.
    """
    payload = dataclasses.asdict(material)
    if material.type != Diffuse.type:
        payload["type"] = material.type
    return payload
