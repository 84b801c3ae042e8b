"""The CLI's habits: quiet logs, one error style with did-you-mean, the strict spp grammar, --version, --json.

Most run ``cbox`` in this process (:func:`cornell_harness.cli.app.main` with a list of
arguments, output through capsys: not a terminal, as in CI); the log test runs
it as a subprocess whose stderr is a pipe, as a CI runner does.
"""

from __future__ import annotations

import io
import json
import os
import re
import subprocess
import sys

import pytest

from tests.conftest import cbox_in_process as cbox, ROOT, run_cbox
from cornell_harness.cli import common, output
from cornell_harness.suggest import closest
from cornell_harness.workflows.spp_list import parse_spp_list


def _converge(out, *extra: str) -> list[str]:
    return ["converge", "--scene", "furnace", "-r", "tests.user_renderers:SeededNoise", "--spp", "1,2", "--seeds", "2",
            "--out", str(out), *extra]


#: A finished cell in a log: which, of how many, and its time (or "stored"), then perhaps the time left.
CELL_LINE = re.compile(r"converge furnace: ([12])/2 cells, seeded-noise seed ([01]) \((\d+\.\d s|stored)\)"
                       r"(?:, [\d:]+ left)?")


def test_converge_log_in_ci_has_a_line_per_cell_and_no_carriage_return(tmp_path, capsys):
    proc = subprocess.run([sys.executable, "-m", "cornell_harness", *_converge(tmp_path)], capture_output=True, cwd=ROOT,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)), timeout=300)
    assert proc.returncode == 0, proc.stderr.decode()[-2000:]
    assert b"\r" not in proc.stdout and b"\r" not in proc.stderr
    progress = [line for line in proc.stderr.decode().splitlines() if line.startswith("converge ")]
    assert progress[0] == "converge furnace: 0/2 cells, starting seeded-noise seed 0"  # the work's start
    cells = [CELL_LINE.fullmatch(line).groups() for line in progress[1:]]
    assert [c[:2] for c in cells] == [("1", "0"), ("2", "1")] and "stored" not in {c[2] for c in cells}
    assert "report: " in proc.stderr.decode()

    # Resumed: both cells stored, said so, and no time left guessed from them; --json: one object, its rows
    # with settings and regions as objects, not JSON text.
    code, out, err = cbox(capsys, *_converge(tmp_path, "--json"))
    assert code == 0, err
    assert [CELL_LINE.fullmatch(line).groups() for line in err.splitlines() if line.startswith("converge ")] == [
        ("1", "0", "stored"), ("2", "1", "stored")], err
    assert "left" not in err and "\r" not in err
    data = json.loads(out)
    assert {r["spp"] for r in data["runs"]} == {1, 2} and {r["seed"] for r in data["runs"]} == {0, 1}
    assert all(isinstance(r["settings"], dict) and isinstance(r["scene_settings"], dict) for r in data["runs"])
    assert isinstance(data["runs"][0]["approximations"], list)
    assert [s["renderer"] for s in data["summary"]] == ["seeded-noise"]
    assert data["report"].endswith("report.html")

    # --quiet (here after the command; `cbox -q converge` is the same flag): the results, nothing on stderr.
    code, out, err = cbox(capsys, *_converge(tmp_path), "-q")
    assert code == 0 and err == "", err
    assert "seeded-noise" in out  # the summary table is a result


def test_progress_time_left_ignores_stored_units(monkeypatch, capsys):
    clock = iter([0.0, 0.0, 0.0, 10.0])  # made at 0; two stored units at 0; a rendered one took 10 s
    monkeypatch.setattr(output.time, "perf_counter", lambda: next(clock))
    bar = output.Progress(4, "converge box", "cell")
    bar.advance("a seed 0", stored=True)
    bar.advance("a seed 1", stored=True)
    bar.advance("a seed 2")
    bar.close()
    assert capsys.readouterr().err.splitlines() == [
        "converge box: 1/4 cells, a seed 0 (stored)",
        "converge box: 2/4 cells, a seed 1 (stored)",
        "converge box: 3/4 cells, a seed 2 (10.0 s), 00:10 left"]  # not 00:03: stored cells took no time


def test_an_error_on_a_terminal_starts_a_fresh_line(monkeypatch):
    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True

    term = Terminal()
    monkeypatch.setattr(sys, "stderr", term)
    bar = output.Progress(3, "gate", "expectation")
    bar.advance("one passed")
    assert term.getvalue().startswith("\rgate: 0/3 expectations |")  # a bar: stderr is a terminal
    with pytest.raises(SystemExit):
        common.fail("boom")
    # The bar's line was cleared and the cursor put back at its start before the error.
    assert term.getvalue().split("\r")[-1] == "cbox: error: boom\n"
    assert output._live_bars == []


# Usage errors: (arguments, texts the one stderr line must contain after "cbox: error: ").
USAGE_ERRORS = {
    # unknown options, with did-you-mean where one is close
    "option misspelt": (["render", "-s", "cornell-box", "-r", "mitsuba", "--spn", "4", "-o", "x.exr"],
                        "no such option: --spn (did you mean '--spp'?)"),
    "option unknown": (["scenes", "--frobnicate"], "no such option: --frobnicate"),
    "short option unknown": (["features", "-x"], "no such option: -x"),
    "global option misspelt": (["--verison"], "(did you mean '--version'?)"),
    # sub-commands
    "command misspelt": (["comvert"], "no such command 'comvert' (did you mean 'converge'?)"),
    "command in capitals": (["SCENES"], "(did you mean 'scenes'?)"),
    "sub-command misspelt": (["reference", "biuld"], "no such command 'biuld' (did you mean 'build'?)"),
    # missing arguments and options
    "render without --scene": (["render", "-r", "mitsuba", "-o", "x.exr"], "Missing option '--scene'"),
    "compare without --scene": (["compare"], "Missing option '--scene'"),
    "converge without --scene": (["converge"], "Missing option '--scene'"),
    "report without FOLDER": (["report"], "Missing argument"),
    "reference show without --scene": (["reference", "show"], "Missing option '--scene'"),
    "an option without its value": (["compare", "--scene"], "--scene"),
    "extra argument": (["features", "surplus"], "unexpected extra argument"),
    # bad values
    "render --spp 0": (["render", "-s", "cornell-box", "-r", "mitsuba", "--spp", "0", "-o", "x.exr"], "--spp: "),
    "compare --spp abc": (["compare", "-s", "cornell-box", "--spp", "abc"], "--spp: "),
    "demo --spp 0": (["demo", "--spp", "0"], "--spp: "),
    "converge --seeds 0": (["converge", "-s", "cornell-box", "--seeds", "0"], "--seeds: "),
    "converge --spp 3-20": (["converge", "-s", "cornell-box", "--spp", "3-20"],
                            "--spp: spp list '3-20': a range A-B means the powers of two"),
    "compare --time-budget soon": (["compare", "-s", "cornell-box", "--time-budget", "soon"],
                                   "--time-budget: time budget 'soon': expected"),
    "compare --time-budget empty": (["compare", "-s", "cornell-box", "--time-budget", ""],
                                    "--time-budget: time budget '': expected"),
    "compare --time-budget 0": (["compare", "-s", "cornell-box", "--time-budget", "0s"],
                                "--time-budget: time budget '0s': must be positive"),
    "compare --target-error empty": (["compare", "-s", "cornell-box", "--target-error", ""], "--target-error: "),
    "compare --target-error negative": (["compare", "-s", "cornell-box", "--target-error", "rel_mse=-1"],
                                        "--target-error: target error 'rel_mse=-1': rel_mse is at least 0"),
    "converge --target negative": (["converge", "-s", "cornell-box", "--target", "delta_e2000_mean=-1"],
                                   "--target: target error 'delta_e2000_mean=-1': delta_e2000_mean is at least 0, "
                                   "so -1 would fail every image"),
    "converge --target above the range": (["converge", "-s", "cornell-box", "--target", "flip_mean=2"],
                                          "--target: target error 'flip_mean=2': flip_mean is between 0 and 1"),
    "converge --target infinite": (["converge", "-s", "cornell-box", "--target", "rmse=1e999"],
                                   "--target: target error 'rmse=1e999': the value must be finite"),
    "reference build --batches 1": (["reference", "build", "-s", "cornell-box", "--batches", "1"], "--batches: "),
    "reference build spp not a multiple": (["reference", "build", "-s", "cornell-box", "--spp", "5", "--batches", "2"],
                                           "must be a multiple of --batches"),
    "quiet and verbose": (["-q", "features", "-v"], "give --quiet or --verbose, not both"),
    # names that were meant: did-you-mean, case-insensitive too
    "renderer in capitals": (["render", "-s", "cornell-box", "-r", "Mitsuba", "-o", "x.exr"],
                             "unknown renderer 'Mitsuba' (did you mean 'mitsuba'?)"),
    "renderer misspelt": (["compare", "-s", "cornell-box", "-r", "pathtracr"], "(did you mean 'pathtracer'?)"),
    "scene misspelt": (["compare", "-s", "cornel-box", "-r", "mitsuba"], "(did you mean 'cornell-box'?)"),
    "scene in capitals": (["reference", "show", "-s", "Cornell-Box"], "(did you mean 'cornell-box'?)"),
    "setting misspelt": (["compare", "-s", "cornell-box", "-r", "pathtracer[rr_dept=3]"],
                         "unknown setting 'rr_dept' (did you mean 'rr_depth'?)"),
    "metric misspelt": (["compare", "-s", "cornell-box", "--target-error", "delta_e2000_maen=1"],
                        "(did you mean 'delta_e2000_mean'?)"),
    "region metric misspelt": (["converge", "-s", "cornell-box", "--target", "region.caustic.rel_mes=0.1"],
                               "(did you mean 'region.caustic.rel_mse'?)"),
    "target region misspelt": (["converge", "-s", "cornell-box-caustics", "--target", "region.caustik.rel_mse=1"],
                               "--target: scene 'cornell-box-caustics' has no region 'caustik' (did you mean "
                               "'caustic'?)"),
    "stress variant misspelt": (["stress", "-r", "pathtracer", "--variant", "grazing-camra"],
                                "(did you mean 'grazing-camera'?)"),
}


@pytest.mark.parametrize("case", list(USAGE_ERRORS))
def test_usage_error_is_one_line_exit_2(case, capsys, tmp_path, monkeypatch):
    args, text = USAGE_ERRORS[case]
    monkeypatch.chdir(tmp_path)  # relative outputs (x.exr, out/) land here, if anything were written
    code, out, err = cbox(capsys, *args)
    lines = err.splitlines()
    assert code == 2 and len(lines) == 1, err
    assert lines[0].startswith("cbox: error: ") and text in lines[0], lines[0]
    assert list(tmp_path.iterdir()) == []  # refused before anything ran


def test_every_command_refuses_an_unknown_option_in_one_line(capsys):
    root = common.command_tree()
    paths = [[name] for name, c in root.commands.items() if not hasattr(c, "commands")]
    paths += [[name, sub] for name, c in root.commands.items() if hasattr(c, "commands") for sub in c.commands]
    assert ["converge"] in paths and ["reference", "build"] in paths
    for path in paths:
        code, out, err = cbox(capsys, *path, "--no-such-option")
        assert (code, err.count("\n")) == (2, 1) and err.startswith("cbox: error: no such option"), (path, err)


def test_quiet_and_verbose_are_taken_by_every_command():
    root = common.command_tree()
    for name, command in root.commands.items():
        for c in command.commands.values() if hasattr(command, "commands") else [command]:
            opts = {o for p in c.params for o in p.opts}
            assert {"--quiet", "-q", "--verbose"} <= opts, name
    # stress keeps -v for --variant
    assert "-v" in next(p for p in root.commands["stress"].params if p.name == "variant").opts


def test_closest_name_ignores_case():
    names = ["mitsuba", "pathtracer", "photonmap"]
    assert closest("Mitsuba", names) == "mitsuba" and closest("MITSUBA", names) == "mitsuba"
    assert closest("pathtracr", names) == "pathtracer"
    assert closest("zzz", names) is None
    assert closest("x" * 10**6, names) is None  # a huge name is cut, not compared for minutes


@pytest.mark.parametrize("text, expected", [
    ("1,2,4,...,256", [1, 2, 4, 8, 16, 32, 64, 128, 256]), ("1-16", [1, 2, 4, 8, 16]), ("4-4", [4]),
    ("4,1,16", [1, 4, 16]), ("1,3,5", [1, 3, 5]), ("64", [64]), ("10,20,...,50", [10, 20, 30, 40, 50]),
    ("1, 2, 4, …, 8", [1, 2, 4, 8]), ("1,2,3,...,6", [1, 2, 3, 4, 5, 6]), ("3,6,12,...,48", [3, 6, 12, 24, 48]),
])
def test_spp_grammar_accepts(text, expected):
    assert parse_spp_list(text) == expected


@pytest.mark.parametrize("text, why", [
    ("3-20", "powers of two (3 and 20 are not); give 4-16"),
    ("2-12", "(12 is not)"),
    ("16-1", "runs backwards"),
    ("1,2,...,8", "ambiguous"),  # ×2 or +1: both reach 8
    ("1,3,...,8", "never reaches 8"),
    ("1,3,4,...,16", "neither one constant ratio nor one constant difference"),
    ("1,...,8", "at least two numbers before '...'"),
    ("1,2,...,9,10", "'...' goes once, just before the last number"),
    ("4,2,...,1", "must increase"),
    ("1,1,2", "1 listed twice"),
    ("0,1", ">= 1"), ("-4", ">= 1"), ("1.5", "not a whole number"), ("a,b", "not a whole number"), ("", "empty"),
    ("1,2,3,...,100000", "at most 1000"),
])
def test_spp_grammar_refuses_saying_why(text, why):
    with pytest.raises(ValueError, match="spp list") as e:
        parse_spp_list(text)
    assert why in str(e.value)


def test_converge_help_states_the_spp_grammar():
    from cornell_harness.cli.experiment import SPP_HELP

    assert "powers of two" in SPP_HELP and "exactly" in SPP_HELP
    for example in re.findall(r"\d[\d,.]*(?:-\d+)?", SPP_HELP.replace("1,2,...,8", "")):
        parse_spp_list(example.rstrip(".,"))  # every example the help gives is accepted


def test_version_is_one_line_then_the_user_store(capsys, user_store):
    code, out, err = cbox(capsys, "--version")
    assert code == 0 and err == ""
    line, home = out.splitlines()
    assert re.fullmatch(r"cbox \d+\.\d+\S* \(Python 3\.\d+\.\d+, Mitsuba \S+, NumPy \S+, .*\)", line), line
    assert home == f"user store: {user_store} (from $CBOX_HOME)"


def test_scenes_json_has_paths_and_nested_objects(capsys):
    code, out, err = cbox(capsys, "scenes", "--json")
    assert code == 0, err
    scenes = {s["name"]: s for s in json.loads(out)}
    box = scenes["cornell-box-caustics"]
    assert box["path"].endswith(os.path.join("references", "cornell-box-caustics", "scene.toml"))
    assert box["reference"]["spp"] == 32768 and "caustic" in box["regions"] and "dielectric" in box["features"]
    code, text, err = cbox(capsys, "scenes")
    assert f"file: {box['path']}" in text


def test_completion_answers_for_cbox():
    env = dict(os.environ, _CBOX_COMPLETE="complete_bash", COMP_WORDS="cbox conv", COMP_CWORD="1")
    proc = subprocess.run([sys.executable, "-c", "import sys; sys.argv[0] = 'cbox'; from cornell_harness.cli.app import "
                           "main; main()"], capture_output=True, text=True, cwd=ROOT, env=env, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert "converge" in proc.stdout.split()


def test_gate_json_has_checks_and_runs(tmp_path):
    config = tmp_path / "gate.toml"
    config.write_text('[[expect]]\nscene = "cornell-box"\nrenderer = "tests.user_renderers:FlatGrey"\nspp = 1\n'
                      'max = { delta_e2000_mean = 100 }\n')
    proc = run_cbox("gate", "--config", str(config), "--out", str(tmp_path / "out"), "--json", env_path=ROOT)
    assert proc.returncode == 0, proc.stderr
    verdict = json.loads(proc.stdout)
    assert verdict["passed"] is True and verdict["failed_checks"] == 0
    (exp,) = verdict["expectations"]
    assert exp["renderer"] == "tests.user_renderers:FlatGrey" and exp["passed"] is True
    assert {"name", "passed", "message", "value", "limit"} <= set(exp["checks"][0])
    assert exp["run"]["renderer"] == "flat-grey" and isinstance(exp["run"]["settings"], dict)
    assert "\r" not in proc.stderr


def test_renderers_json_lists_settings_as_objects(capsys):
    code, out, err = cbox(capsys, "renderers", "--json")
    assert code == 0, err
    renderers = {r["name"]: r for r in json.loads(out)}
    pt = renderers["pathtracer"]
    assert pt["available"] is True and "diffuse" in pt["models"]
    rr = next(s for s in pt["settings"] if s["name"] == "rr_depth")
    assert rr["type"] == "int" and isinstance(rr["default"], int) and rr["doc"]

