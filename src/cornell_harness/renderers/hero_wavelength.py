"""Hero-wavelength spectral path tracing: the path tracer's ``spectral = "hero"`` mode.

Wilkie, Nawaz, Droske, Weidlich and Hanika 2014, "Hero Wavelength Spectral
Sampling" (EGSR), as pbrt-v4 does it (§4.6.5 ``SampledWavelengths``, §13.4
``PathIntegrator`` on ``SampledSpectrum``): each camera path carries 4
wavelengths, the hero λ_0 and three rotations of it
(:func:`cornell_harness.renderers.core.wavelengths.hero_wavelengths`, pbrt-v4's visible-wavelength
pdf), and a throughput per wavelength. Every sampling decision of the path
(pixel jitter, NEE, BSDF direction, Russian roulette on the largest of the
four throughputs) is the RGB path tracer's: the same kernel
(:func:`cornell_harness.renderers.pathtracer._shade`) runs both, with this
module's channel type :class:`Hero` and path state :class:`HeroPaths` in
place of RGB's. That is exact because none of our materials makes a
direction depend on wavelength: a constant-index dielectric refracts every
wavelength alike, so no secondary wavelength is ever terminated (Wilkie §4's
dispersion case does not arise), and the hero's balance-heuristic weights
over the 4 wavelengths are 1/4 each: the estimate is the mean of the four
single-wavelength estimates. Each wavelength's radiance enters the pixel's
linear sRGB at once, through the observer's matching functions divided by
that wavelength's pdf (:func:`cornell_harness.renderers.core.wavelengths.sensor_rgb`), so the
film, its variance, the batches of the low-discrepancy samplers, and the
determinism (a pure function of the seed, whatever the thread count) are the
RGB path tracer's. The scale is the scene model's: a spectral emitter seen
directly converges to :func:`cornell_harness.scenes.spectra.emission_rgb` of its
spectrum (:mod:`cornell_harness.renderers.core.wavelengths` says why exactly).

What a hero render reads (:func:`spectral_tables`): each diffuse or mirror
material's reflectance spectrum and each emitter's emission spectrum, as the
scene binds them (``Scene.spectral``: :mod:`cornell_harness.scenes.spectral_scene`);
glass is 1 at every wavelength. A field that is RGB only is refused with a
one-line reason (upsampling RGB to a spectrum would be an arbitrary choice
that a spectral reference does not make), except a black reflectance (0, 0,
0), which is 0 at every wavelength in any model. AOVs come from the RGB mode.

The wavelength's number is the sampler's dimension
:data:`cornell_harness.renderers.core.sampler.WAVELENGTH`, outside every vertex's, so the
hero render of a scene uses the RGB render's numbers for everything else.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from cornell_harness.scenes.materials import Dielectric
from cornell_harness.scenes.model import Scene
from cornell_harness.renderers.core.bsdf import bsdf_eval, bsdf_sample
from cornell_harness.renderers.core.geometry import SceneGeometry
from cornell_harness.renderers.core.rays import set_path
from cornell_harness.renderers.core.roulette import continue_spectral_path
from cornell_harness.renderers.core.sampler import WAVELENGTH, Stream, path_point, sample_1d
from cornell_harness.renderers.core.sampling import jit
from cornell_harness.renderers.core.wavelengths import N_WAVELENGTHS, hero_wavelengths, on_grid, sensor_rgb


class SpectralTables(NamedTuple):
    """What the kernels read about a scene's spectra, besides the geometry's tables (one numba argument)."""

    cmf_rgb: np.ndarray  # (N_BINS, 3) cornell_harness.renderers.core.wavelengths.sensor_rgb
    rho: np.ndarray  # (K, N_BINS) reflectance spectra on the table's nodes
    rho_row: np.ndarray  # (N,) int64 per primitive: its row of rho
    le: np.ndarray  # (K', N_BINS) emission spectra on the nodes
    le_row: np.ndarray  # (N,) int64 per primitive: its row of le, -1 for a non-emitter


class HeroPaths(NamedTuple):
    """The state of a work unit's hero-wavelength paths (the :class:`Hero` channel type), per path (indexed by
    the path, not the ray: a path has one live ray): linear-sRGB radiance, no AOVs (they come from the RGB
    mode: 0 rows), and per wavelength the table nodes, linear-sRGB weights cmf_rgb / (4 p) and throughput, which
    the bounces update in place; then the scene's spectra that the bounces read (:class:`SpectralTables`'
    fields of the same names), as fields of their own so the channel functions read them with one lookup."""

    L: np.ndarray  # (m, 3) float64 linear sRGB
    aux: np.ndarray  # (0, 6)
    aux_open: np.ndarray  # (0,) bool
    lam: np.ndarray  # (m, 4) int64 table nodes
    sensor: np.ndarray  # (m, 4, 3) float64
    beta: np.ndarray  # (m, 4) float64
    rho: np.ndarray  # SpectralTables.rho, and so on
    rho_row: np.ndarray
    le: np.ndarray
    le_row: np.ndarray


def _refuse(scene: Scene, what: str) -> ValueError:
    return ValueError(f"scene {scene.name!r}: {what} is RGB only; spectral=hero renders spectra only "
                      "(bind it to a [spectra] table) or use spectral=rgb")


def spectral_tables(scene: Scene, geom: SceneGeometry) -> SpectralTables:
    """The scene's spectra resampled for the kernels, per primitive (module docstring: what is refused)."""
    spectral = scene.spectral
    if spectral is None:
        raise ValueError(f"scene {scene.name!r} has no spectra (no [colour] table); spectral=hero needs a "
                         "spectral scene, spectral=rgb renders it")
    rows_rho: dict = {}
    rows_le: dict = {}
    rho_of, le_of = [], []
    for obj in scene.meshes + scene.spheres:
        mat = scene.materials[obj.material]
        if isinstance(mat, Dielectric):
            key = "one"
        else:
            key = spectral.reflectance(obj.material, "reflectance")
            if key is None:
                if any(mat.reflectance):
                    raise _refuse(scene, f"material {obj.material!r}'s reflectance")
                key = "zero"
        rho_of.append(rows_rho.setdefault(key, len(rows_rho)))
        radiance = getattr(obj, "radiance", None)
        if radiance is None or not any(radiance):
            le_of.append(-1)
            continue
        s = spectral.emission(obj.name)
        if s is None:
            raise _refuse(scene, f"mesh {obj.name!r}'s emission")
        le_of.append(rows_le.setdefault(s, len(rows_le)))
    const = {"one": 1.0, "zero": 0.0}
    rho = np.array([np.full(sensor_rgb().shape[0], const[k]) if isinstance(k, str) else on_grid(k)
                    for k in rows_rho]).reshape(len(rows_rho), -1)
    le = np.array([on_grid(s) for s in rows_le]).reshape(len(rows_le), -1) if rows_le else np.zeros((1, rho.shape[1]))
    return SpectralTables(sensor_rgb(), rho, np.asarray(rho_of, np.int64)[geom.object],
                          le, np.asarray(le_of, np.int64)[geom.object])


def start_paths(spec: SpectralTables, stream: Stream, first: int, m: int) -> HeroPaths:
    """The state of paths ``first .. first + m - 1`` before their first bounce: each path's wavelengths (its
    number at dimension WAVELENGTH), their sRGB weights, throughput 1 and radiance 0."""
    paths = HeroPaths(np.zeros((m, 3)), np.zeros((0, 6)), np.ones(0, np.bool_), np.empty((m, N_WAVELENGTHS), np.int64),
                      np.empty((m, N_WAVELENGTHS, 3)), np.empty((m, N_WAVELENGTHS)), spec.rho, spec.rho_row, spec.le,
                      spec.le_row)
    _start_paths(stream, first, spec, paths.lam, paths.sensor, paths.beta)
    return paths


@jit
def _start_paths(stream, first, spec, lam, sensor, beta):
    """:func:`start_paths`' kernel."""
    for q in range(lam.shape[0]):
        nodes, pdf = hero_wavelengths(sample_1d(stream, path_point(stream, first + q), WAVELENGTH))
        for j in range(N_WAVELENGTHS):
            lam[q, j] = nodes[j]
            beta[q, j] = 1.0
            p = pdf[j]
            inv = 1.0 / (N_WAVELENGTHS * p) if p > 0.0 else 0.0
            for c in range(3):
                sensor[q, j, c] = spec.cmf_rgb[nodes[j], c] * inv


class Hero:
    """The hero-wavelength channel type (:mod:`cornell_harness.renderers.core.channels`) of the path tracer's
    kernel (:func:`cornell_harness.renderers.pathtracer._shade`): 4 wavelengths per path, state
    :class:`HeroPaths`, the throughput per path in it (the rays' own is left 1). Each function is
    :class:`cornell_harness.renderers.pathtracer.RGB`'s per wavelength."""

    @jit
    def throughput(paths, rays, i, q):
        """β of path ``q`` per wavelength."""
        return paths.beta[q, 0], paths.beta[q, 1], paths.beta[q, 2], paths.beta[q, 3]

    @jit
    def reflectance(paths, geo, p, q):
        """ρ of primitive ``p`` at path ``q``'s wavelengths."""
        k = paths.rho_row[p]
        return (paths.rho[k, paths.lam[q, 0]], paths.rho[k, paths.lam[q, 1]], paths.rho[k, paths.lam[q, 2]],
                paths.rho[k, paths.lam[q, 3]])

    @jit
    def add_emission(paths, q, beta, geo, p, w):
        """Path ``q``'s linear sRGB += Σ_λ β(λ) · Le(p, λ) · w · sensor(λ)."""
        r = paths.le_row[p]
        for j in range(N_WAVELENGTHS):
            s = beta[j] * paths.le[r, paths.lam[q, j]] * w
            for c in range(3):
                paths.L[q, c] += s * paths.sensor[q, j, c]

    @jit
    def light_rgb(paths, q, mat, beta, rho, cos_x, g, geo, e):
        """The linear sRGB that a light sample of emitter triangle ``e`` adds to path ``q`` if unoccluded:
        Σ_λ f(λ) · Le(e, λ) · g · sensor(λ), f of reflectance β(λ)·ρ(λ)."""
        r = paths.le_row[e]
        c0 = c1 = c2 = 0.0
        for j in range(N_WAVELENGTHS):
            s = bsdf_eval(mat, beta[j] * rho[j], cos_x) * paths.le[r, paths.lam[q, j]] * g
            c0 += s * paths.sensor[q, j, 0]
            c1 += s * paths.sensor[q, j, 1]
            c2 += s * paths.sensor[q, j, 2]
        return c0, c1, c2

    @jit
    def sample_bsdf(paths, mat, n, wo, cos_o, rho, eta, u1, u2):
        """The direction and its weight at unit reflectance, times ρ(λ): for our materials f·cos/pdf is ρ(λ)
        times that, and no direction depends on the wavelength (module docstring)."""
        wi, cos_w, f, valid = bsdf_sample(mat, n, wo, cos_o, (1.0, 1.0, 1.0), eta, u1, u2)
        return wi, cos_w, (f[0] * rho[0], f[0] * rho[1], f[0] * rho[2], f[0] * rho[3]), valid

    @jit
    def next_throughput(paths, mat, valid, cos_w, f, beta, scale, u_rr, roulette):
        """:func:`cornell_harness.renderers.core.roulette.continue_spectral_path`: (alive, β', pdf)."""
        return continue_spectral_path(mat, valid, cos_w, f, beta, scale, u_rr, roulette)

    @jit
    def set_throughput(paths, nxt, k, q, beta, pdf, scale):
        """Ray ``k`` of ``nxt`` continues path ``q``, whose throughput per wavelength becomes ``beta``."""
        set_path(nxt, k, q, (1.0, 1.0, 1.0), pdf, scale)
        paths.beta[q, 0], paths.beta[q, 1], paths.beta[q, 2], paths.beta[q, 3] = beta
