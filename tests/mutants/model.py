"""What a mutant is: a realistic bug in one of our renderers, as changes to named functions, and the files they patch.

Each :class:`Mutant` names the renderer it is a copy of (:data:`INTEGRATORS`)
and its patches, each addressed to one function by its qualified name in a
file (``"_shade"``, ``"PathTracer.render"``): an :class:`Edit` of code in it
(matched as syntax, so formatting, comments and code elsewhere in the file do
not matter), a :class:`Replace` of the whole function or a :class:`Wrap` of
it. :mod:`tests.mutants.editing` applies them. The bugs themselves are in the
family modules (:mod:`tests.mutants.pathtracer`, ...), gathered by
:mod:`tests.mutants.catalogue`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple, Union

#: The folder holding the import package: mutant files are named relative to it.
ROOT = Path(__file__).resolve().parents[2] / "src"
PATHTRACER = "cornell_harness/renderers/pathtracer.py"
PHOTONMAP = "cornell_harness/renderers/photonmap.py"
SPPM = "cornell_harness/renderers/sppm.py"
AO = "cornell_harness/renderers/ao.py"
AMBIENT = "cornell_harness/renderers/ambient.py"
PROBES = "cornell_harness/renderers/probes.py"
DDGI = "cornell_harness/renderers/ddgi.py"  # the probes' algorithm (not an integrator: its mutants get a copy, as core modules do)
WHITTED = "cornell_harness/renderers/whitted.py"
OIDN = "cornell_harness/renderers/oidn.py"  # the denoise stage; its PathTracerOIDN wraps the unmutated path tracer
HERO = "cornell_harness/renderers/hero_wavelength.py"
TEMPORAL = "cornell_harness/renderers/temporal.py"  # the temporal accumulation stage; PathTracerTemporal wraps the path tracer
SVGF = "cornell_harness/renderers/svgf.py"  # the SVGF stage; PathTracerSVGF wraps the path tracer
SOURCE = ROOT / PATHTRACER
CORE = "cornell_harness/renderers/core"
#: The renderers mutants are made of: registered name -> (integrator module, adapter class).
INTEGRATORS = {"pathtracer": (PATHTRACER, "PathTracer"), "photonmap": (PHOTONMAP, "PhotonMapper"),
               "sppm": (SPPM, "SPPM"), "ao": (AO, "AORenderer"), "ambient": (AMBIENT, "AOAmbient"),
               "probes": (PROBES, "IrradianceProbes"), "pathtracer+oidn": (OIDN, "PathTracerOIDN"),
               "whitted": (WHITTED, "Whitted"), "pathtracer+temporal": (TEMPORAL, "PathTracerTemporal"),
               "pathtracer+svgf": (SVGF, "PathTracerSVGF")}


class Edit(NamedTuple):
    """In ``function`` of ``file``, the code ``old`` replaced by ``new``.

    ``old`` is an expression or one or more consecutive statements, compared
    by syntax tree (``ast.dump``) with the code inside the function; it must
    occur there exactly once. ``new`` is an expression in place of an
    expression, or statements (none: ``old`` deleted) in place of statements.
    """

    function: str  # qualified name in the file: "_shade", "PathTracer.render"
    old: str
    new: str
    file: str = PATHTRACER  # relative to src/


class Replace(NamedTuple):
    """``function`` of ``file`` replaced by ``source``: a ``def`` of the same name (the original's decorators are
    kept, e.g. ``@jit``)."""

    function: str
    source: str
    file: str = PATHTRACER


class Wrap(NamedTuple):
    """``function`` of ``file`` wrapped by ``wrapper``: the source of a ``def`` taking the original function and
    returning what stands in for it (applied as the outermost decorator: a Python-level function only, as a jitted
    kernel's callers are compiled against the kernel itself)."""

    function: str
    wrapper: str
    file: str = PATHTRACER


Patch = Union[Edit, Replace, Wrap]


@dataclass(frozen=True)
class Mutant:
    name: str
    description: str  # the bug, as a developer would make it
    patches: tuple[Patch, ...]
    renderer: str = "pathtracer"  # the registered renderer it is a copy of (INTEGRATORS)

    def __post_init__(self):
        assert self.patches and all(isinstance(p, (Edit, Replace, Wrap)) for p in self.patches), \
            f"mutant {self.name!r}: its patches are Edit, Replace or Wrap"
