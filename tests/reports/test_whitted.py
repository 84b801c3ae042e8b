"""The section "Recursive ray tracing and its hacks": its table from results rows."""

from __future__ import annotations

from cornell_harness.reports.whitted import hacks_table, renderer_rows_order, whitted_section

NOISE = {"caustic": {"mean": 1.0, "mean_rel_se": 0.001}, "floor": {"mean": 0.1, "mean_rel_se": 0.001}}


def _row(name, caustic, floor=0.0, status="ok"):
    return {"renderer": name, "status": status, "spp": 4, "time_s": 1.0,
            "region.caustic.mean_radiance_rel_error": caustic, "region.caustic.delta_e2000_mean": 5.0,
            "region.floor.mean_radiance_rel_error": floor, "region.floor.delta_e2000_mean": 1.0}


def test_whitted_variants_lead_in_their_order():
    names = ["pathtracer", 'whitted[transparent_shadows="boolean"]', "ambient", "whitted", "whittedness"]
    assert renderer_rows_order(names) == ['whitted[transparent_shadows="boolean"]', "whitted", "pathtracer",
                                          "ambient", "whittedness"]


def test_table_cells_are_the_missing_share_and_delta_e():
    html = hacks_table([_row("pathtracer", 0.01), _row('whitted[transparent_shadows="boolean"]', -0.9, 0.25),
                        _row("broken", 0.0, status="failed")], NOISE)
    assert html.index("whitted") < html.index("pathtracer") and "broken" not in html
    assert "+90.0% · ΔE 5.00" in html  # boolean shadows lose 90% of the caustic
    assert "\u22121.0% · ΔE 5.00" in html  # the path tracer 1% over: a negative share, typographic minus
    assert "\u221225.0% · ΔE 1.00" in html  # light added on the floor


def test_section_says_when_no_whitted_render_ran():
    assert "No whitted render ran" in whitted_section([_row("ambient", 0.5)], NOISE, "cornell-box-caustics")
    assert "No whitted render" not in whitted_section([_row("whitted", 0.5)], NOISE, "cornell-box-caustics")
