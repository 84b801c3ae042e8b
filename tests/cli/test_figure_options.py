"""Figure options (issue 31): ``--series-label SPEC=TEXT`` and a renderers file's ``[series_labels]`` name a series
in legends and tables; a label that names no series is a usage error before anything renders; the labels
are kept for ``cbox report``; ``--crop X,Y,W,H`` is checked against the image."""

from __future__ import annotations

import re

import pytest

from cornell_harness.adapters.renderers_file import RenderersFileError, read_series_labels
from cornell_harness.adapters.settings import SettingsError, match_series_labels, parse_series_label, series_key
from tests.conftest import ROOT, run_cbox


def test_parse_splits_at_the_first_equals_sign_outside_the_brackets():
    assert parse_series_label('pathtracer[sampler="independent"]=PT (independent)') == (
        'pathtracer[sampler="independent"]', "PT (independent)")
    assert parse_series_label("pathtracer[rr_depth=3,sampler=sobol] = a=b") == (
        "pathtracer[rr_depth=3,sampler=sobol]", "a=b")
    for bad in ("pathtracer", "pathtracer=", "=text", "pathtracer[rr_depth=3"):
        with pytest.raises(SettingsError):
            parse_series_label(bad)


def test_a_spec_matches_its_recorded_name_quoted_or_not_in_any_order():
    names = ["pathtracer", 'pathtracer[rr_depth=3,sampler="sobol"]']
    assert series_key("pathtracer[sampler=sobol, rr_depth=3]") == series_key(names[1])
    assert match_series_labels({"pathtracer[sampler=sobol,rr_depth=3]": "sobol"}, names) == {names[1]: "sobol"}
    with pytest.raises(SettingsError, match="pathtracer\\[sampler=pmj02\\]' names no series"):
        match_series_labels({"pathtracer[sampler=pmj02]": "x"}, names)


def test_renderers_file_series_labels_are_read_and_checked(tmp_path):
    good = tmp_path / "labels.toml"
    good.write_text("[series_labels]\n'pathtracer[sampler=\"independent\"]' = \"PT (independent)\"\n")
    assert read_series_labels(good) == {'pathtracer[sampler="independent"]': "PT (independent)"}
    bad = tmp_path / "bad.toml"
    bad.write_text("[series_labels]\npathtracer = 3\n")
    with pytest.raises(RenderersFileError, match="series_labels.pathtracer"):
        read_series_labels(bad)


def _legend_texts(svg: str) -> list[str]:
    """Each legend entry's text, its wrapped lines (tspans) joined, spaces left out."""
    entries = re.findall(r'class="legend-label"[^>]*>(.*?)</text>', svg)
    return [re.sub(r"\s+", "", re.sub(r"<[^>]+>", "", re.sub(r"<title>.*?</title>", "", t))) for t in entries]


def test_converge_labels_its_series_and_report_keeps_them(tmp_path):
    out = tmp_path / "sweep"
    proc = run_cbox("converge", "--scene", "cornell-box", "-r", "tests.user_renderers:Tunable", "--sweep",
                    "tests.user_renderers:Tunable.level=0.25,0.5", "--spp", "1,2", "--seeds", "1", "--out", str(out),
                    "--series-label", "tunable[level=0.5]=Half level", env_path=ROOT)
    assert proc.returncode == 0, proc.stderr
    legend = _legend_texts((out / "figures" / "convergence-spp-rmse.svg").read_text())
    assert "Halflevel" in legend and "tunable" in legend
    html = (out / "report.html").read_text()
    assert 'data-renderer="tunable[level=0.5]"' in html  # the recorded name stays the key
    # cbox report keeps the run's label and adds the one given now
    proc = run_cbox("report", str(out), "--series-label", "tunable=Quarter level", env_path=ROOT)
    assert proc.returncode == 0, proc.stderr
    legend = _legend_texts((out / "figures" / "convergence-spp-rmse.svg").read_text())
    assert {"Halflevel", "Quarterlevel"} <= set(legend)


def test_a_label_naming_no_series_is_a_usage_error_before_rendering(tmp_path):
    out = tmp_path / "typo"
    proc = run_cbox("converge", "--scene", "cornell-box", "-r", "tests.user_renderers:Tunable", "--spp", "1",
                    "--seeds", "1", "--out", str(out), "--series-label", "tunabel=T", env_path=ROOT)
    assert proc.returncode == 2
    assert "--series-label" in proc.stderr and "did you mean 'tunable'" in proc.stderr
    assert not (out / "results.parquet").exists()


@pytest.mark.parametrize("crop", ["1,2,3", "0,0,1,8", "250,0,16,16", "a,b,c,d"])
def test_a_crop_outside_the_image_or_malformed_is_a_usage_error(tmp_path, crop):
    proc = run_cbox("compare", "--scene", "cornell-box", "-r", "tests.user_renderers:Tunable", "--spp", "1",
                    "--out", str(tmp_path / "c"), "--crop", crop, env_path=ROOT)
    assert proc.returncode == 2 and "--crop" in proc.stderr, proc.stderr
    assert not (tmp_path / "c" / "results.parquet").exists()
