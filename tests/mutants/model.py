"""What a mutant is: a realistic bug in one of our renderers, as exact source patches, and the files they patch.

Each :class:`Mutant` names the renderer it is a copy of (:data:`INTEGRATORS`)
and its patches: an ``old`` snippet, which must occur exactly once in its
file, replaced by ``new``. The bugs themselves are in the family modules
(:mod:`tests.mutants.pathtracer`, ...), gathered by :mod:`tests.mutants.catalogue`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

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
SOURCE = ROOT / PATHTRACER
CORE = "cornell_harness/renderers/core"
#: The renderers mutants are made of: registered name -> (integrator module, adapter class).
INTEGRATORS = {"pathtracer": (PATHTRACER, "PathTracer"), "photonmap": (PHOTONMAP, "PhotonMapper"),
               "sppm": (SPPM, "SPPM"), "ao": (AO, "AORenderer"), "ambient": (AMBIENT, "AOAmbient"),
               "probes": (PROBES, "IrradianceProbes"), "pathtracer+oidn": (OIDN, "PathTracerOIDN"),
               "whitted": (WHITTED, "Whitted")}


class Patch(NamedTuple):
    old: str  # occurs exactly once in ``file``
    new: str
    file: str = PATHTRACER  # relative to src/


@dataclass(frozen=True)
class Mutant:
    name: str
    description: str  # the bug, as a developer would make it
    patches: tuple[Patch, ...]  # a patch without a file patches src/cornell_harness/renderers/pathtracer.py
    renderer: str = "pathtracer"  # the registered renderer it is a copy of (INTEGRATORS)

    def __post_init__(self):
        object.__setattr__(self, "patches", tuple(Patch(*p) for p in self.patches))
