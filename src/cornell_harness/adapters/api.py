"""The renderer API: the one module of the harness a renderer imports (besides the scene model).

A renderer is a small class (state: the renderer's own handles) that
satisfies :class:`Renderer`, and may declare more (:class:`Declarations`:
its settings, AOVs, estimator, quantities, ...). Everything it needs from
the harness is here: what it returns (:class:`RenderResult`,
:class:`Checkpoint`), the auxiliary images it may give (:data:`AOVS`), the
kinds of estimate it may declare (:data:`ESTIMATORS`), its settings
(:class:`Setting`, :class:`SettingsError`), the seed and pass helpers every
renderer shares (:func:`pass_key`, :func:`pass_seed`, :func:`spp_passes`), the
thread count (:func:`default_threads`) and the clock of the render proper
(:class:`Stopwatch`). The harness reads what a renderer declares through
:func:`attribute` only. Discovery, settings resolution and the render path
live elsewhere (:mod:`cornell_harness.adapters.registry`, :mod:`cornell_harness.adapters.settings`,
:mod:`cornell_harness.workflows.render`) and a renderer never imports them.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field, fields
from typing import Any, Mapping, Protocol, Sequence, runtime_checkable

import numpy as np

from cornell_harness.adapters.seeds import frame_seed, pass_key, pass_seed, spp_passes
from cornell_harness.scenes.model import Scene
from cornell_harness.scenes.quantities import DEFAULT_QUANTITY

__all__ = ["AOVS", "DECLARATIONS", "ESTIMATORS", "THREADS_VARIABLE", "Checkpoint", "Declarations", "ReferenceFit",
           "RenderResult", "Renderer", "SequenceResult", "Setting", "SettingsError", "Stopwatch", "attribute",
           "default_threads",
           "frame_seed", "machine_cores", "pass_key", "pass_seed", "process_cpu_s", "spp_passes"]

#: Auxiliary images (AOVs) a renderer may return, defined as Intel Open Image Denoise expects them (its
#: documentation, "RT" filter): the surface seen through each pixel at the first non-delta hit, following
#: mirrors and glass, averaged over the pixel's samples like the image; (H, W, 3) float32.
#: ``albedo``: its reflectance times the specular chain's tint, in [0, 1]; ``normal``: its unit normal
#: (world space) on the side the ray arrives from, in [-1, 1]; both 0 where the path leaves the scene.
AOVS = ("albedo", "normal")
#: What a renderer's ``estimator`` may say; the first is the default of a renderer that says nothing.
ESTIMATORS = ("unbiased", "consistent", "biased")


class SettingsError(ValueError):
    """A setting is unknown or out of range; ``str()`` names it and what is allowed."""


@dataclass(frozen=True)
class Setting:
    """One declared setting: ``kind`` is int, float, bool or str; bounds are inclusive."""

    name: str
    kind: type
    default: Any
    doc: str
    low: float | None = None
    high: float | None = None
    choices: tuple = ()

    def allowed(self) -> str:
        """What values are allowed, in words (for errors and ``cbox renderers --settings``)."""
        if self.choices:
            return "one of " + ", ".join(map(str, self.choices))
        kind = {int: "an integer", float: "a number", bool: "true or false", str: "a string"}[self.kind]
        if self.low is not None and self.high is not None:
            return f"{kind} in [{self.low:g}, {self.high:g}]"
        if self.low is not None:
            return f"{kind} >= {self.low:g}"
        if self.high is not None:
            return f"{kind} <= {self.high:g}"
        return kind

    def coerce(self, value: Any, renderer: str) -> Any:
        """``value`` (from TOML, or a string from the command line) as this setting's type, checked."""
        bad = SettingsError(f"renderer {renderer!r}: setting {self.name}={value!r}: expected {self.allowed()}")
        if isinstance(value, str) and self.kind is not str:
            value = _parse_word(value)
        if self.kind is bool:
            if not isinstance(value, bool):
                raise bad
        elif self.kind is int:
            # bool is an int in Python, and 3.0 from a sweep list is a fine 3; 3.5 is not.
            if isinstance(value, bool) or not isinstance(value, (int, float)) or value != int(value):
                raise bad
            value = int(value)
        elif self.kind is float:
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise bad
            value = float(value)
        elif not isinstance(value, str):
            raise bad
        if self.choices and value not in self.choices:
            raise bad
        if (self.low is not None and value < self.low) or (self.high is not None and value > self.high):
            raise bad
        return value


def _parse_word(text: str) -> Any:
    low = text.strip().lower()
    if low in ("true", "false"):
        return low == "true"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text.strip()


@dataclass
class Checkpoint:
    """The image after the first ``spp`` samples per pixel, and the time to get there (wall, and CPU when the
    renderer measures it: :class:`Stopwatch`); ``variance``, where the renderer gives one, is the per-pixel
    variance of ``image`` as :class:`RenderResult`'s (a sequential gate's looks use it)."""

    spp: int
    image: np.ndarray
    time_s: float
    aovs: dict = field(default_factory=dict)  # name (AOVS) -> (H, W, 3) float32, when asked for
    cpu_time_s: float | None = None
    variance: np.ndarray | None = None


@dataclass
class RenderResult:
    """What a render returns.

    ``image`` is linear-sRGB radiance, float32, shape (height, width, 3).
    ``time_s`` is wall time of the render proper (scene set-up excluded,
    JIT compilation included unless the adapter warmed up beforehand);
    ``cpu_time_s`` the CPU time of the same span, all threads and children
    included (:class:`Stopwatch`), None when the renderer does not measure
    it (the harness then records the CPU time of the whole ``render`` call).
    ``info["setup_s"]``, when given, is the set-up left out of ``time_s``
    (scene build, JIT compilation, warm-up): the results' ``setup_s`` column.
    ``info`` carries adapter details worth recording (e.g. Mitsuba's variant).
    ``variance``, when the renderer can give it, is the per-pixel variance of
    ``image`` (of the mean, not of one sample), float32 (height, width, 3).
    ``aovs`` holds the auxiliary images (:data:`AOVS`) the caller asked for.
    """

    image: np.ndarray
    time_s: float
    spp: int
    seed: int
    checkpoints: list[Checkpoint] = field(default_factory=list)
    info: dict = field(default_factory=dict)
    variance: np.ndarray | None = None
    aovs: dict = field(default_factory=dict)
    cpu_time_s: float | None = None


@dataclass
class SequenceResult:
    """What a sequence render returns: one :class:`RenderResult` per frame, in frame order (each with its own
    time and seed), and ``state``, what the renderer carried from frame to frame (its settings of time: a
    hysteresis, a history length), recorded with the run."""

    frames: list[RenderResult]
    state: dict = field(default_factory=dict)


def process_cpu_s() -> float:
    """CPU seconds of this process so far: all its threads (:func:`time.process_time`) and its children that
    have ended and been waited for (:func:`os.times`; a command-line renderer's program, a sandbox)."""
    t = os.times()
    return time.process_time() + t.children_user + t.children_system


class Stopwatch:
    """The clock of a render proper: wall time (:func:`time.perf_counter`) and CPU time (:func:`process_cpu_s`)
    since it was started. Start it where ``time_s`` starts; read both where it ends."""

    def __init__(self):
        self.start()

    def start(self) -> None:
        self._wall0, self._cpu0 = time.perf_counter(), process_cpu_s()

    def wall(self) -> float:
        return time.perf_counter() - self._wall0

    def cpu(self) -> float:
        return process_cpu_s() - self._cpu0

    def read(self) -> tuple[float, float]:
        """(wall seconds, CPU seconds) since the start."""
        return self.wall(), self.cpu()


@runtime_checkable
class Renderer(Protocol):
    """What every renderer has. Found through the entry-point group ``cbox.renderers`` or given as
    ``package.module:ClassName`` (:mod:`cornell_harness.adapters.registry`), constructed with no arguments.

    What a renderer may declare besides, and what is assumed when it does not,
    is :class:`Declarations`; the harness reads it with :func:`attribute`.
    """

    #: Short id used on the command line and in results (``mitsuba``, ``pathtracer``).
    name: str
    #: The scene features (:data:`cornell_harness.scenes.model.FEATURES`) it models; it never runs on a scene with others.
    features: frozenset[str]

    def unavailable_reason(self) -> str | None:
        """None if it can run here, else why not (a missing library, no GPU): one line for the user."""

    def version(self) -> str:
        """The renderer's version string, recorded with every result (called only when it is available)."""

    def render(self, scene: Scene, spp: int, seed: int, checkpoints: Sequence[int] = ()) -> RenderResult:
        """``scene`` at ``spp`` samples per pixel; the same ``seed`` gives the same image, whatever the threads.

        ``checkpoints``: spp values (each at most ``spp``) whose images it returns along the way
        (:attr:`RenderResult.checkpoints`), as if each were a render of its own with the same seed.
        A renderer that declares ``settings`` is also called with ``settings=``: every declared setting,
        validated, typed and with its default filled in (the render path, :mod:`cornell_harness.workflows.render`,
        resolves them once; the renderer never validates them again). One that declares ``aovs`` may be
        called with ``aovs=`` (a subset of :data:`AOVS`) and then returns them in :attr:`RenderResult.aovs`.
        """


@dataclass(frozen=True)
class ReferenceFit:
    """A setting value the harness renders as an oracle fitted to the stored reference, not the renderer.

    When a renderer's ``setting`` is ``value`` (the ambient renderer's ``ambient = oracle``), the render
    path (:mod:`cornell_harness.workflows.render`) loads the scene's stored reference R (refusing a scene without
    one before anything renders), renders twice with the same seed, with ``without`` (the image D without
    the term) and with ``unit`` (the image with the term at 1) merged into the settings, and returns
    D + c·B, B = unit − D, with c per channel the least-squares constant against R
    (:mod:`cornell_harness.evaluate.reference_fit`), each checkpoint with its own c; c goes in ``info[record]``.
    Valid only for an image linear in the fitted constant, which ``unit`` must set to 1.
    """

    setting: str
    value: str
    without: Mapping[str, Any]
    unit: Mapping[str, Any]
    record: str


@dataclass(frozen=True)
class Declarations:
    """What a renderer may declare as class attributes besides :class:`Renderer`'s; each default is the value
    of a renderer that does not (or declares None). Read them with :func:`attribute`, never ``getattr``."""

    #: Its settings (:class:`Setting`): validated by the harness, handed to ``render`` as ``settings=``.
    settings: tuple[Setting, ...] = ()
    #: The auxiliary images (:data:`AOVS`) it can return when ``render`` is called with ``aovs=(...)``;
    #: the denoisers (:mod:`cornell_harness.renderers.oidn`) ask for them.
    aovs: tuple[str, ...] = ()
    #: What its images can mean (:data:`cornell_harness.scenes.quantities.QUANTITIES`); it never runs on a scene of
    #: another quantity.
    quantities: tuple[str, ...] = (DEFAULT_QUANTITY,)
    #: What kind of estimate its image is (:data:`ESTIMATORS`): ``unbiased`` (the expected image is the
    #: reference at any spp: path tracers), ``consistent`` (biased, the error goes to 0 as the budget grows:
    #: photon mapping, SPPM; Jensen 2001, Hachisuka et al. 2008) or ``biased`` (does not converge to the
    #: reference: rasterisers, approximations). The gate refuses z-tests for the last two and offers a
    #: consistency check instead (:mod:`cornell_harness.gate.config`); results record it in the ``estimator`` column.
    #: Any other value is refused when the renderer is loaded.
    estimator: str = ESTIMATORS[0]
    #: True for a renderer whose image does not depend on the seed (a rasteriser): experiments run it for
    #: one seed only.
    deterministic: bool = False
    #: One line per thing it only approximates (shown in reports; the stress suite checks no mean for it).
    approximations: tuple[str, ...] = ()
    #: A setting value that asks the harness for an oracle fitted to the stored reference (:class:`ReferenceFit`).
    reference_fit: ReferenceFit | None = None
    #: True for a renderer whose ``render`` takes ``stop=``: a function called with each :class:`Checkpoint` as
    #: it is made, in spp order; when it returns True the render ends there and returns that checkpoint's image
    #: (with its variance where it gives one) as its result, at that checkpoint's spp. A sequential gate
    #: (:mod:`cornell_harness.gate.sequential`) stops so at its first verdict; a renderer that cannot stop renders
    #: its whole budget, and the gate takes its looks from the checkpoints afterwards.
    stops_early: bool = False
    #: The published sources of its method, one short citation each (authors, year, title): shown with the
    #: renderer in the docs' reference of renderers.
    citations: tuple[str, ...] = ()
    #: True for a renderer that renders a sequence itself: its ``render_sequence(scene, spp, seed, settings=...,
    #: frames=...)`` returns a :class:`SequenceResult` and carries state from frame to frame (a temporal history,
    #: probes updated with a hysteresis). Any other renderer renders each frame on its own, as a still image
    #: with :func:`frame_seed` (:mod:`cornell_harness.workflows.sequence`).
    sequences: bool = False


#: The declarations of a renderer that declares nothing.
DECLARATIONS = Declarations()
_OPTIONAL = frozenset(f.name for f in fields(Declarations))


def attribute(renderer, name: str) -> Any:
    """The renderer's declared ``name`` (a field of :class:`Declarations`), or its default when it declares
    none; the sequences as tuples. A name that is not a declaration is a KeyError (a typo, not a default)."""
    if name not in _OPTIONAL:
        raise KeyError(f"{name!r} is not a renderer declaration; they are {', '.join(sorted(_OPTIONAL))}")
    default = getattr(DECLARATIONS, name)
    value = getattr(renderer, name, None)
    if value is None:
        return default
    return tuple(value) if isinstance(default, tuple) else value


#: The environment variable that sets :func:`default_threads` (a Dask worker's share is set through it).
THREADS_VARIABLE = "CBOX_THREADS"


def machine_cores() -> int:
    """The machine's CPU count (at least 1): the threads without ``$CBOX_THREADS``, and what a host's workers share."""
    return os.cpu_count() or 1


def default_threads() -> int:
    """Worker threads: ``$CBOX_THREADS`` (a positive integer) or the machine's CPU count.

    Raises :class:`SettingsError` (one of the CLI's user errors) naming
    ``CBOX_THREADS`` if it is set to anything else.
    """
    env = os.environ.get(THREADS_VARIABLE)
    if env:
        try:
            threads = int(env)
        except ValueError:
            threads = 0
        if threads < 1:
            raise SettingsError(f"{THREADS_VARIABLE}: expected a positive integer (worker threads), got {env!r}")
        return threads
    return machine_cores()
