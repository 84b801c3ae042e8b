"""A scene's spectral content: its ``[colour]`` pipeline, its ``[spectra]``, and which materials and emitters use them.

Scene-file syntax (format 1)::

    [colour]                          # required once any value is a spectrum
    observer = "CIE1931_2"            # cornell_harness.scenes.spectra.OBSERVER (the only one)
    output = "linear_srgb_d65"        # cornell_harness.scenes.spectra.OUTPUT (the only one)
    rgb_convention = "illuminant_E"   # or "scene_light" (cornell_harness.scenes.spectra.RGB_CONVENTIONS)
    light = "light"                   # the spectrum of the scene's emitter; required by scene_light

    [spectra.white]                   # a sampled spectrum, by name
    wavelengths_nm = [400, 404, ...]  # strictly increasing, nm
    values = [0.343, 0.445, ...]      # one per wavelength
    extrapolation = "zero"            # optional: "zero" (default) or "constant"

    [materials.white]
    type = "diffuse"
    reflectance = { spectrum = "white" }        # any rgb01 field of a material

    [[meshes]]
    ...
    emitter = { radiance = { spectrum = "light" } }

A spectral value is projected to linear sRGB once, at load
(:mod:`cornell_harness.scenes.spectra`: the reflectance by the declared convention,
the emission by the emitter rule), and the material or mesh holds that RGB,
so every RGB renderer reads the scene as before. The spectra themselves, and
which field uses which, are kept in :class:`SpectralContent`
(``Scene.spectral``) for spectral renderers, and its ``rgb_convention`` is
the convention a run on the RGB values used (:func:`convention_used`, the results'
``rgb_convention`` column). Reflectance spectra must lie in
[0, 1] and so must their projection; emission spectra must be non-negative and
so must their RGB (an RGB renderer cannot emit a negative channel).
"""

from __future__ import annotations

from dataclasses import dataclass

from cornell_harness.scenes.spectra import SCENE_LIGHT, Spectrum, emission_rgb, reflectance_rgb, spectrum_problem
from cornell_harness.suggest import closest

#: The ``RenderResult.info`` key by which a renderer says it rendered a scene's spectra, not their RGB projection;
#: its value says how (Mitsuba's variant, ``hero``). Absent or empty: the render used the RGB values.
SPECTRAL_INFO = "spectral"
#: The ``rgb_convention`` column of a run that rendered the spectra themselves.
SPECTRAL_RUN = "spectral"


def convention_used(rgb_convention: str, info) -> str:
    """What a run's colours were, for the results' ``rgb_convention`` column, from the scene's ``rgb_convention``
    (empty for a scene without spectral content) and the render's ``info``: empty for such a scene,
    :data:`SPECTRAL_RUN` where the renderer rendered the spectra (``info[SPECTRAL_INFO]``), else the scene's
    convention, by which the RGB values it rendered were projected."""
    if not rgb_convention:
        return ""
    return SPECTRAL_RUN if (info or {}).get(SPECTRAL_INFO) else rgb_convention


@dataclass(frozen=True)
class SpectralContent:
    """The colour pipeline a scene declares and the spectra its materials and emitters use.

    ``materials`` maps a material's name to {field: spectrum name} (e.g.
    ``{"white": {"reflectance": "white"}}``), ``emitters`` a mesh's name to
    the name of its emission spectrum; ``spectra`` holds the spectra those
    name (and the light's), nothing else, so an unused ``[spectra]`` table
    does not change the scene's content hash.
    """

    observer: str
    output: str
    rgb_convention: str
    light: str | None
    spectra: dict[str, Spectrum]
    materials: dict[str, dict[str, str]]
    emitters: dict[str, str]

    @property
    def used(self) -> bool:
        """Whether any material or emitter is given as a spectrum (a spectral renderer then renders those)."""
        return bool(self.emitters or any(self.materials.values()))

    def fields(self, material: str) -> dict[str, Spectrum]:
        """``material``'s fields given as spectra, {field: spectrum}; empty where all are RGB."""
        return {f: self.spectra[name] for f, name in self.materials.get(material, {}).items()}

    def reflectance(self, material: str, field: str = "reflectance") -> Spectrum | None:
        """The spectrum of ``material``'s ``field``, None where that field is RGB."""
        name = self.materials.get(material, {}).get(field)
        return None if name is None else self.spectra[name]

    def emission(self, mesh: str) -> Spectrum | None:
        """The emission spectrum of mesh ``mesh``, None where its radiance is RGB (or it does not emit)."""
        name = self.emitters.get(mesh)
        return None if name is None else self.spectra[name]

    def hash_payload(self) -> dict:
        return {"observer": self.observer, "output": self.output, "rgb_convention": self.rgb_convention,
                # the light changes the RGB values only under scene_light
                "light": self.light if self.rgb_convention == SCENE_LIGHT else None, "spectra": {k: s.hash_payload() for k, s in sorted(self.spectra.items())},
                "materials": {k: dict(sorted(v.items())) for k, v in sorted(self.materials.items())},
                "emitters": dict(sorted(self.emitters.items()))}


class SpectralReader:
    """Reads a scene's [colour] and [spectra] tables, then each spectral value; ``err(field, message)`` is the
    loader's error of the file, whose document the scene schema has checked.

    State: the bindings found so far, turned into a :class:`SpectralContent`
    by :meth:`finish`. A scene without a [colour] table has no spectral
    content, and a spectral value in it is an error.
    """

    def __init__(self, err, doc: dict, key_text):
        self.err, self.key_text = err, key_text
        colour = doc.get("colour")
        self.declared = colour is not None
        self.spectra: dict[str, Spectrum] = {}
        self.materials: dict[str, dict[str, str]] = {}
        self.emitters: dict[str, str] = {}
        if not self.declared:
            if "spectra" in doc:
                raise err("spectra", "a scene with spectra declares its colour pipeline in a [colour] table "
                                     "(observer, output, rgb_convention)")
            return
        self.observer, self.output, self.convention = colour["observer"], colour["output"], colour["rgb_convention"]
        for name, t in doc.get("spectra", {}).items():
            self.spectra[name] = self._spectrum(name, t)
        self.light = colour.get("light")
        if self.convention == SCENE_LIGHT and self.light is None:
            raise err("colour.light", f"missing required field: rgb_convention = {SCENE_LIGHT!r} balances "
                                      "reflectances to the scene's light; name its spectrum")
        if self.light is not None:
            # The light is an emission: its samples are checked here, before a reflectance is white-balanced to
            # it, so a negative sample is reported as itself, not as a light that cannot be balanced to.
            self._check_values(self.light, self._lookup(self.light, "colour.light"), 0.0, None,
                               "an emission (colour.light)")

    def _spectrum(self, name: str, t: dict) -> Spectrum:
        wavelengths, values, extrapolation = t["wavelengths_nm"], t["values"], t.get("extrapolation", "zero")
        if problem := spectrum_problem(wavelengths, values, extrapolation):
            raise self.err(f"spectra.{self.key_text(name)}.{problem[0]}", problem[1])
        return Spectrum(tuple(float(x) for x in wavelengths), tuple(float(x) for x in values), extrapolation)

    def _lookup(self, name: str, field: str) -> Spectrum:
        if name not in self.spectra:
            close = closest(name, tuple(self.spectra))
            hint = f"did you mean {close!r}?" if close else f"defined: {', '.join(self.spectra) or '(none)'}"
            raise self.err(field, f"no spectrum named {name[:60]!r} in [spectra]; {hint}")
        return self.spectra[name]

    def _reference(self, value: dict, field: str) -> tuple[str, Spectrum]:
        """The spectrum a ``{ spectrum = "NAME" }`` value names."""
        if not self.declared:
            raise self.err(field, "a spectral value needs the scene's [colour] table (observer, output, "
                                  "rgb_convention)")
        return value["spectrum"], self._lookup(value["spectrum"], f"{field}.spectrum")

    def _check_values(self, name: str, spectrum: Spectrum, lo: float, hi: float | None, what: str) -> None:
        for i, x in enumerate(spectrum.values):
            if x < lo or (hi is not None and x > hi):
                raise self.err(f"spectra.{self.key_text(name)}.values[{i}]",
                                 f"{what} must be in [{lo:g}, {'inf' if hi is None else f'{hi:g}'}], got {x}")

    def reflectance(self, value: dict, field: str, material: str, key: str) -> tuple[float, float, float]:
        """The RGB reflectance of a spectral material field (``materials.NAME.reflectance``), recorded."""
        name, spectrum = self._reference(value, field)
        self._check_values(name, spectrum, 0.0, 1.0, f"a reflectance ({field})")
        light = self.spectra[self.light] if self.light is not None else None
        try:
            rgb = reflectance_rgb(spectrum, self.convention, light)
        except ValueError as e:
            raise self.err("colour.light", str(e)) from None
        if not all(0.0 <= x <= 1.0 for x in rgb):
            raise self.err(field, f"spectrum {name!r} projects to {[round(x, 6) for x in rgb]} under "
                                    f"{self.convention}, outside [0, 1]")
        self.materials.setdefault(material, {})[key] = name
        return rgb

    def emission(self, value: dict, field: str, mesh: str, bound: float) -> tuple[float, float, float]:
        """The RGB radiance of a spectral emitter (``meshes[i].emitter.radiance``), recorded."""
        name, spectrum = self._reference(value, field)
        self._check_values(name, spectrum, 0.0, None, f"an emission ({field})")
        rgb = emission_rgb(spectrum)
        if min(rgb) < 0.0 or max(rgb) > bound:
            raise self.err(field, f"spectrum {name!r} maps to linear sRGB {[round(x, 6) for x in rgb]}: "
                                    f"each channel must be in [0, {bound:g}] for an RGB renderer")
        self.emitters[mesh] = name
        return rgb

    def finish(self) -> SpectralContent | None:
        """The scene's spectral content, once every material and mesh is read; None without a [colour] table."""
        if not self.declared:
            return None
        if self.light is not None and self.light not in self.emitters.values():
            raise self.err("colour.light", f"spectrum {self.light!r} is no emitter's radiance; the scene_light "
                                             "convention balances to the scene's own light")
        used = set(self.emitters.values()) | {n for v in self.materials.values() for n in v.values()}
        return SpectralContent(self.observer, self.output, self.convention, self.light,
                               {k: s for k, s in self.spectra.items() if k in used}, self.materials, self.emitters)
