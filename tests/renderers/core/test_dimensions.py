"""The sampler's dimension map (src/cornell_harness/renderers/core/sampler.py), checked on its declarations.

- the blocks one kind of path draws (a layout) never share a dimension, and every block lies below
  rng's 2^24 dimensions;
- every dimension function stays inside its block at the extreme items the block holds, and the settings
  that count rays are bounded by what their blocks hold;
- the map gives exactly the numbers every integrator drew before the map owned them (the formulas below
  are those it replaced), so the pinned images stay bit-identical;
- every renderer of ours that draws from a stream declares the one ``sampler`` setting.

That no integrator writes a dimension of its own is checked on the sources: tests/test_code_shape.py.
"""

from __future__ import annotations

from cornell_harness.renderers.ambient import AOAmbient
from cornell_harness.renderers.ao import AORenderer
from cornell_harness.renderers.core import sampler as S
from cornell_harness.renderers.core.sampler import (MAX_RAYS, MAX_TREE_DEPTH, SAMPLERS, bounce_dim, gather_dim,
                                                    gather_walk_base, occlusion_dim, shifted_vertex_dim,
                                                    tree_light_dim, tree_occlusion_dim, vertex_dim)
from cornell_harness.renderers.pathtracer import PathTracer
from cornell_harness.renderers.photonmap import PhotonMapper
from cornell_harness.renderers.probes import IrradianceProbes
from cornell_harness.renderers.sppm import SPPM
from cornell_harness.renderers.whitted import Whitted

#: rng's uniform() takes dimensions below this.
RNG_DIMS = 1 << 24
OURS = (PathTracer, AORenderer, AOAmbient, PhotonMapper, SPPM, IrradianceProbes, Whitted)


def overlaps(blocks) -> list[tuple[str, str]]:
    """The pairs of ``blocks`` (by name) that share a dimension."""
    return [(a.name, b.name) for i, a in enumerate(blocks) for b in blocks[i + 1:]
            if a.base < b.stop and b.base < a.stop]


def setting(renderer, name: str):
    return next(s for s in renderer.settings if s.name == name)


def test_the_blocks_of_a_layout_never_overlap():
    assert {name: overlaps(blocks) for name, blocks in S.LAYOUTS.items() if overlaps(blocks)} == {}


def test_the_overlap_check_finds_blocks_that_share_dimensions():
    """Blocks of different layouts may share dimensions (ambient's occlusion rays and photonmap's gather rays
    both start at 2^20; ao's direction is where a path's first vertex would be): the check sees them."""
    assert overlaps((S.CAMERA, S.OCCLUSION, S.GATHER)) == [("occlusion rays", "gather rays")]
    assert overlaps((S.VERTICES, S.AO_DIRECTION)) == [("vertices", "ao direction")]
    assert overlaps((S.HERO, S.PHOTON_BOUNCES)) == []  # adjacent is not overlapping


def test_every_block_is_named_once_laid_out_and_inside_rngs_dimensions():
    names = [b.name for b in S.BLOCKS]
    assert len(set(names)) == len(names)
    assert {b for layout in S.LAYOUTS.values() for b in layout} == set(S.BLOCKS)
    outside = [b for b in S.BLOCKS if not (0 <= b.base < b.stop <= RNG_DIMS and b.count >= 1)]
    assert outside == []


def test_each_dimension_function_stays_inside_its_block():
    """The first and the last dimension of the first and the last item each block holds (a 2D draw at d uses
    d + 1 too)."""
    walk_vertices = (S.GATHER_WALKS.stride - S.VERTICES.base) // S.VERTICES.stride
    cases = {
        S.CAMERA: [S.CAMERA_U, S.CAMERA_V],
        S.VERTICES: [vertex_dim(1, S.EMITTER_PICK), vertex_dim(S.VERTICES.count, S.ROULETTE)],
        S.AO_DIRECTION: [S.AO_U, S.AO_V],
        S.OCCLUSION: [occlusion_dim(0), occlusion_dim(MAX_RAYS - 1) + 1],
        S.GATHER: [gather_dim(0), gather_dim(MAX_RAYS - 1) + 1],
        S.GATHER_WALKS: [shifted_vertex_dim(gather_walk_base(0), 1, S.EMITTER_PICK),
                         shifted_vertex_dim(gather_walk_base(MAX_RAYS - 1), walk_vertices, S.ROULETTE)],
        S.TREE_LIGHTS: [tree_light_dim(1, 0, S.EMITTER_PICK),
                        tree_light_dim(MAX_TREE_DEPTH, MAX_RAYS - 1, S.EMITTER_V)],
        S.TREE_OCCLUSION: [tree_occlusion_dim(1, 0), tree_occlusion_dim(MAX_TREE_DEPTH, MAX_RAYS - 1) + 1],
        S.HERO: [S.WAVELENGTH],
        S.PHOTON_EMISSION: [S.EMIT_PICK, S.EMIT_DIR_V],
        S.PHOTON_BOUNCES: [bounce_dim(1, S.BOUNCE_U), bounce_dim(S.PHOTON_BOUNCES.count, S.BOUNCE_ROULETTE)],
        S.PROBE_RAY: [S.PROBE_EMITTER_PICK, S.PROBE_BSDF_V],
        S.PROBE_ROTATION: [S.ROTATION_U1, S.ROTATION_U2 + 1],
    }
    assert set(cases) == set(S.BLOCKS)
    assert {b.name: dims for b, dims in cases.items() if not all(b.base <= d < b.stop for d in dims)} == {}
    assert shifted_vertex_dim(0, 4, S.BSDF_U) == vertex_dim(4, S.BSDF_U)  # no shift: the camera path's own


def test_the_map_gives_the_numbers_the_integrators_drew_before_it():
    """The formulas each integrator wrote itself before the sampler owned the map: every image pinned since
    (tests/renderers/test_*pinned.py) was made with them."""
    assert (S.CAMERA_U, S.CAMERA_V, S.AO_U, S.AO_V, S.WAVELENGTH) == (0, 1, 2, 3, (1 << 24) - 1)
    assert (S.EMITTER_PICK, S.EMITTER_U, S.EMITTER_V, S.BSDF_U, S.BSDF_V, S.ROULETTE) == (0, 1, 2, 3, 4, 5)
    assert (S.EMIT_PICK, S.EMIT_U, S.EMIT_V, S.EMIT_DIR_U, S.EMIT_DIR_V) == (0, 1, 2, 3, 4)
    assert (S.PROBE_EMITTER_PICK, S.PROBE_EMITTER_U, S.PROBE_EMITTER_V, S.PROBE_BSDF_U,
            S.PROBE_BSDF_V) == (0, 1, 2, 3, 4)
    assert (S.ROTATION_U1, S.ROTATION_U2) == (0, 1)
    assert (S.BOUNCE_U, S.BOUNCE_V, S.BOUNCE_ROULETTE) == (0, 1, 2)
    for d in (1, 2, 7, 64):
        for o in range(6):
            assert vertex_dim(d, o) == 2 + (d - 1) * 6 + o
            assert bounce_dim(d, o % 3) == 5 + (d - 1) * 3 + o % 3
        for s in (0, 1, 1023):
            assert tree_light_dim(d, s, 0) == (1 << 20) + 3 * (1024 * (d - 1) + s)  # whitted's LIGHT_DIM
            assert tree_light_dim(d, s, 1) == (1 << 20) + 3 * (1024 * (d - 1) + s) + 1
            assert tree_occlusion_dim(d, s) == (1 << 23) + 2 * (1024 * (d - 1) + s)  # whitted's AO_DIM
    for g in (0, 1, 1023):
        assert occlusion_dim(g) == (1 << 20) + 2 * g  # ambient's AO_DIM
        assert gather_dim(g) == (1 << 20) + 2 * g  # photonmap's GATHER_DIM
        assert shifted_vertex_dim(gather_walk_base(g), 3, 5) == (1 << 21) + g * (1 << 12) + vertex_dim(3, 5)


def test_the_settings_that_count_rays_are_bounded_by_their_blocks():
    assert setting(AOAmbient, "ao_samples").high == S.OCCLUSION.count
    assert setting(PhotonMapper, "gather_rays").high == S.GATHER.count == S.GATHER_WALKS.count
    assert setting(Whitted, "light_samples").high == setting(Whitted, "ao_samples").high == MAX_RAYS
    assert setting(Whitted, "max_depth").high == MAX_TREE_DEPTH
    assert S.TREE_LIGHTS.count == S.TREE_OCCLUSION.count == MAX_RAYS * MAX_TREE_DEPTH


def test_every_renderer_of_ours_declares_the_one_sampler_setting():
    """Each draws from a stream, so each takes the ``sampler`` setting, with the same choices; the defaults are
    those its gate expectations were measured with."""
    for renderer in OURS:
        assert setting(renderer, "sampler").choices == tuple(SAMPLERS), renderer.name
    assert {r.name: setting(r, "sampler").default for r in OURS} == {
        "pathtracer": "pmj02", "ao": "pmj02", "ambient": "independent", "photonmap": "independent",
        "sppm": "independent", "probes": "independent", "whitted": "independent"}
