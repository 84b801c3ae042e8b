"""The ambient-occlusion family's mutants: Monte Carlo AO (src/cornell_harness/renderers/ao.py, the occlusion rays it shares) and AO as
ambient (src/cornell_harness/renderers/ambient.py)."""

from __future__ import annotations

from tests.mutants.model import AMBIENT, AO, CORE, Edit, Mutant

OCCLUSION = f"{CORE}/occlusion.py"

MUTANTS: tuple[Mutant, ...] = (
    # -- ambient occlusion (ao) ------------------------------------------------------------------------
    Mutant(
        "ao_uniform_as_cosine",
        "cosine-weighted AO sampled with uniform hemisphere directions but each still counted as V (the pdf "
        "1/(2π) taken for cos θ/π): the image is the uniform obscurance, too dark beside walls",
        (Edit("ao_direction", "cosine_hemisphere(n[0], n[1], n[2], u1, u2)",
              "uniform_hemisphere(n[0], n[1], n[2], u1, u2)", OCCLUSION),),
        "ao",
    ),
    Mutant(
        "ao_max_distance_ignored",
        "the occlusion ray's tfar left at infinity: occluders beyond max_distance count",
        (Edit("trace_ao", "tfar = ao.max_distance", 'tfar = float("inf")', AO),),
        "ao",
    ),
    Mutant(
        "ao_normal_flipped",
        "FaceForward's test the wrong way round: the hemisphere is on the far side of every surface, so the "
        "rays look into walls and boxes (or the void behind them) instead of the room",
        (Edit("face_forward", "n if cos_o >= 0.0 else (-n[0], -n[1], -n[2])",
              "(-n[0], -n[1], -n[2]) if cos_o >= 0.0 else n", OCCLUSION),),
        "ao",
    ),
    # -- the AO-ambient approximation (ambient) --------------------------------------------------------
    Mutant(
        "ambient_not_occluded",
        "the ambient term added without its occlusion rays' verdict (AO taken as 1): corners and the floor "
        "round the boxes as bright as open walls",
        (Edit("Shading.trace", "add_unoccluded(L, seg, self.geom.unoccluded(seg.o, seg.d, seg.t))",
              "add_unoccluded(L, seg, np.ones(k, bool))", AMBIENT),),
        "ambient",
    ),
)
