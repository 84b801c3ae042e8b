"""`cbox report DIR1 DIR2 ... --out OUT`: several experiments in one report; `--label` names them.

The experiment folders are made once for the module, in-process, by `cbox converge` and `cbox compare`
with the fast test renderers (tests/user_renderers.py). PDF and PNG conversion of the figures is switched
off (the SVG files are still written): tests/reports/test_report.py checks the conversion; here it would only cost
seconds per report.
"""

from __future__ import annotations

import html
import re

import pandas as pd
import pytest

from cornell_harness.cli.app import main
from cornell_harness.reports import figures


def _run(*args: str) -> int:
    """``cbox ARGS`` in this process; its exit code."""
    with pytest.raises(SystemExit) as done:
        main(list(args))
    return done.value.code


@pytest.fixture(scope="module")
def experiments(tmp_path_factory):
    """Three experiment folders: two sweeps of furnace (32², the smallest stored scene) that share a renderer
    name, and a comparison on light-panel."""
    root = tmp_path_factory.mktemp("experiments")
    mp = pytest.MonkeyPatch()
    mp.setattr(figures, "_converter", lambda: (None, "off in these tests"))
    try:
        runs = {
            "sweep-a": ("converge", "--scene", "furnace", "-r", "tests.user_renderers:SeededNoise",
                        "--spp", "1,2", "--seeds", "2"),
            "sweep-b": ("converge", "--scene", "furnace", "-r", "tests.user_renderers:SeededNoise",
                        "-r", "tests.user_renderers:FlatGrey", "--spp", "1,2", "--seeds", "2"),
            "panel": ("compare", "--scene", "light-panel", "-r", "tests.user_renderers:FlatGrey", "--spp", "1"),
        }
        for name, args in runs.items():
            assert _run("-q", *args, "--out", str(root / name)) == 0, name
        yield root
    finally:
        mp.undo()


@pytest.fixture(autouse=True)
def _svg_only(monkeypatch):
    monkeypatch.setattr(figures, "_converter", lambda: (None, "off in these tests"))


def cbox(capsys, *args: str) -> tuple[int, str]:
    code = _run("-q", *args)
    return code, capsys.readouterr().err


def _section(text: str, sid: str) -> str:
    i = text.index(f'<section id="{sid}">')
    return text[i:text.index("</section>", i)]


def _summary_renderers(text: str) -> list[str]:
    summary = _section(text, "summary")
    return [html.unescape(n) for n in re.findall(r'<tr class="record [^"]*" data-renderer="([^"]*)"', summary)]


def test_same_scene_merges_into_one_table_with_a_section_each(experiments, tmp_path, capsys):
    out = tmp_path / "merged"
    code, err = cbox(capsys, "report", str(experiments / "sweep-a"), str(experiments / "sweep-b"),
                     "--out", str(out))
    assert code == 0, err
    text = (out / "report.html").read_text()
    # One combined table: the name both sweeps use is told apart by label, the other is kept as it is.
    assert sorted(_summary_renderers(text)) == ["flat-grey", "seeded-noise (sweep-a)", "seeded-noise (sweep-b)"]
    assert "experiments <strong>sweep-a, sweep-b</strong>" in text
    # Combined convergence charts: one line per renderer of both experiments.
    chart = re.search(r'<svg id="conv-spp-rmse".*?</svg>', text, re.S).group(0)
    assert chart.count('<path class="series"') == 3
    # A section per experiment, with its renderers, its charts and a link to its own report.
    for label, names in (("sweep-a", ["seeded-noise (sweep-a)"]),
                         ("sweep-b", ["seeded-noise (sweep-b)", "flat-grey"])):
        section = _section(text, f"experiment-{label}")
        assert f"{label} · furnace" in section
        href = re.search(r'<a href="([^"]+)">Full report of', section).group(1)
        assert (out / href).resolve() == (experiments / label / "report.html").resolve()
        for name in names:
            assert html.escape(name) in section
        assert f'id="{label}-conv-spp-rmse"' in section
        # Its own timing-quality badge (issue 30), with timing_quality's figures beside it.
        assert re.search(r'<span class="badge timing timing-(good|contended|unknown)" data-timing="\1"', section)
        assert "timing-figures" in section
    # Its own figures: the combined charts, and each section's under its label.
    svgs = {p.name for p in (out / "figures").glob("*.svg")}
    for stem in ("convergence-spp-rmse", "sweep-a-convergence-spp-rmse", "sweep-b-convergence-spp-rmse",
                 "sweep-b-bias-variance"):
        assert f"{stem}.svg" in svgs, stem
        assert f'href="figures/{stem}.svg"' in text
    assert len(set(re.findall(r'<svg id="([^"]+)"', text))) == len(re.findall(r'<svg id="', text))  # ids unique
    # Every experiment's summary for people and papers: an experiment column, a LaTeX table each with its names.
    readable = pd.read_csv(out / "summary.csv")
    assert list(zip(readable["experiment"], readable["renderer"])) == [
        ("sweep-a", "seeded-noise"), ("sweep-b", "seeded-noise"), ("sweep-b", "flat-grey")]
    tex = (out / "summary.tex").read_text()
    assert tex.count("\\begin{tabular}{l") == tex.count("\\begin{table}[") == 2
    assert "\\caption{\\textbf{sweep-a}." in tex and "\\caption{\\textbf{sweep-b}." in tex


def test_different_scenes_each_get_a_section(experiments, tmp_path, capsys):
    out = tmp_path / "merged"
    code, err = cbox(capsys, "report", str(experiments / "sweep-a"), str(experiments / "panel"),
                     "--out", str(out), "--label", "oven", "--label", "lamp", "--title", "Two scenes")
    assert code == 0, err
    text = (out / "report.html").read_text()
    assert "<h1>Two scenes</h1>" in text
    assert "oven · furnace" in _section(text, "experiment-oven")
    assert "lamp · light-panel" in _section(text, "experiment-lamp")
    # No name is shared: names stay as they are; the lead table is the first scene's alone.
    assert _summary_renderers(text) == ["seeded-noise"]
    assert "flat-grey" in _section(text, "experiment-lamp")
    assert (out / "figures" / "oven-convergence-spp-rmse.svg").exists()
    assert (out / "figures" / "lamp-speed-accuracy-rmse.svg").exists()


def test_single_folder_with_a_label_shows_it(experiments, tmp_path, capsys):
    out = tmp_path / "one"
    code, err = cbox(capsys, "report", str(experiments / "sweep-a"), "--label", "baseline <v1>",
                     "--out", str(out))
    assert code == 0, err
    text = (out / "report.html").read_text()
    assert "experiment <strong>baseline &lt;v1&gt;</strong>" in text
    assert (out / "figures" / "convergence-spp-rmse.svg").exists()


@pytest.mark.parametrize("args, words", [
    (["sweep-a", "sweep-b"], "--out: 2 folders make one merged report: give --out"),
    (["sweep-a", "sweep-b", "--out", "{tmp}/m", "--label", "x"], "--label: 1 label for 2 folders"),
    (["sweep-a", "--label", "x", "--label", "y"], "--label: 2 labels for 1 folder"),
    (["sweep-a", "sweep-b", "--out", "{tmp}/m", "--label", "x", "--label", "x"], "--label: 'x' names two"),
    (["sweep-a", "sweep-b", "--out", "{exp}/sweep-a"], "--out: "),
    (["sweep-a", "--label", " "], "--label: a label cannot be empty"),
])
def test_usage_errors_are_one_line(experiments, tmp_path, capsys, args, words):
    args = [a.format(tmp=tmp_path, exp=experiments) for a in args]
    args = [str(experiments / a) if a.startswith("sweep-") else a for a in args]
    code, err = cbox(capsys, "report", *args)
    assert code == 2
    (line,) = err.strip().splitlines()
    assert line.startswith("cbox: error: ") and words in line, line
    assert not (tmp_path / "m").exists()


def test_names_and_file_prefixes_stay_distinct():
    from cornell_harness.reports.merge import distinct_names, file_prefixes

    names = distinct_names([["pt", "pt[rr_depth=3]"], ["pt", "mitsuba"]], ["a", "b"])
    assert names == [{"pt": "pt (a)", "pt[rr_depth=3]": "pt[rr_depth=3]"}, {"pt": "pt (b)", "mitsuba": "mitsuba"}]
    assert file_prefixes(["run 1", "run/1", "Ü", "ok"]) == ["run_1", "run_1-2", "experiment", "ok"]
