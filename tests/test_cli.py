"""CLI conventions: --help, --version, exit codes 0/2/1, one-line errors without a traceback,
no half-written output; the `trace` command end to end."""

from __future__ import annotations

import subprocess
import sys

import pytest

from vid2sim import __version__
from vid2sim.base.errors import FormatError, OutputError
from vid2sim.cli import main
from vid2sim.samples.sample_gps import write_sample_gpx


@pytest.fixture(scope="module")
def sample_gpx(tmp_path_factory):
    return write_sample_gpx(tmp_path_factory.mktemp("gps") / "sample.gpx")


def test_help_lists_trace(capsys):
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    assert "trace" in out and "Usage" in out


def test_version(capsys):
    assert main(["--version"]) == 0
    assert __version__ in capsys.readouterr().out


def test_console_entry_point_runs():
    # The real `python -m vid2sim` process: exit code and output through the entry point.
    r = subprocess.run([sys.executable, "-m", "vid2sim", "--version"], check=False,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and __version__ in r.stdout


def test_trace_help(capsys):
    assert main(["trace", "--help"]) == 0
    out = capsys.readouterr().out
    for opt in ("--rate", "--gps-offset", "--out"):
        assert opt in out


def test_trace_success_writes_csv_and_summary(sample_gpx, tmp_path, capsys):
    out = tmp_path / "ego.csv"
    assert main(["trace", str(sample_gpx), "--rate", "5", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "format:" in text and "gpx" in text and str(out) in text
    lines = out.read_text().splitlines()
    assert lines[0] == "t_s,lat,lon,x_m,y_m,heading_rad,speed_mps"
    assert lines[2].split(",")[0] == "0.200"  # 5 Hz


def test_trace_gps_offset_shifts_time(sample_gpx, tmp_path, capsys):
    out = tmp_path / "ego.csv"
    assert main(["trace", str(sample_gpx), "--rate", "1", "--gps-offset", "3", "--out",
                 str(out)]) == 0
    assert out.read_text().splitlines()[1].startswith("3.000,")
    assert "--gps-offset" in capsys.readouterr().out


def test_quiet_prints_nothing(sample_gpx, tmp_path, capsys):
    assert main(["-q", "trace", str(sample_gpx), "--out", str(tmp_path / "e.csv")]) == 0
    assert capsys.readouterr().out == ""


def test_bad_input_is_one_line_exit_2_and_no_output(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("t,lat,lon\n0,60,24\n1,not-a-number,24\n")
    out = tmp_path / "ego.csv"
    assert main(["trace", str(bad), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1
    assert lines[0].startswith("error: ") and "bad.csv" in lines[0] and "line 3" in lines[0]
    assert "Traceback" not in err
    assert not out.exists()
    assert [p.name for p in tmp_path.iterdir()] == ["bad.csv"]  # no temporary file either


def test_failed_run_keeps_previous_output(tmp_path, capsys):
    out = tmp_path / "ego.csv"
    out.write_text("previous\n")
    assert main(["trace", str(tmp_path / "missing.gpx"), "--out", str(out)]) == 2
    assert "no such file" in capsys.readouterr().err
    assert out.read_text() == "previous\n"


def test_output_folder_is_an_input_error(sample_gpx, tmp_path, capsys, raised):
    assert main(["trace", str(sample_gpx), "--out", str(tmp_path)]) == 2
    assert capsys.readouterr().err.startswith(f"error: {tmp_path}: ")
    assert raised == [OutputError]  # a folder where the output file goes


def test_verbose_error_shows_traceback(tmp_path, capsys, raised):
    empty = tmp_path / "empty.nmea"
    empty.write_text("")
    assert main(["-v", "trace", str(empty), "--out", str(tmp_path / "e.csv")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {empty}: ") and "Traceback" in err
    assert raised == [FormatError]  # an empty file


@pytest.mark.parametrize("args", [
    ["trace"],                                   # missing GPS_FILE
    ["trace", "x.gpx"],                          # missing --out
    ["trace", "x.gpx", "--out", "o.csv", "--rate", "0"],
    ["trace", "x.gpx", "--out", "o.csv", "--gps-offset", "soon"],
    ["no-such-command"],
])
def test_usage_errors_exit_2_without_traceback(args, capsys):
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "Error" in err and "Traceback" not in err


def test_internal_error_exit_1(monkeypatch, sample_gpx, tmp_path, capsys):
    import vid2sim.app.gpsroad as commands_mod

    def boom(*a, **k):
        raise RuntimeError("simulated bug")

    monkeypatch.setattr(commands_mod, "run_trace", boom)
    assert main(["trace", str(sample_gpx), "--out", str(tmp_path / "e.csv")]) == 1
    err = capsys.readouterr().err
    assert "internal error" in err and "simulated bug" in err and "Traceback" not in err


@pytest.mark.parametrize("command", [
    ["trace", "{gps}", "--out", "{folder}"],
    ["road", "{gps}", "--no-download", "--out", "{folder}"],
    ["detect", "{gps}", "--detections", "{gps}", "--out", "{folder}"],
    ["track", "{gps}", "--detections", "{gps}", "--out", "{folder}"],
    ["export", "{gps}", "--format", "openscenario", "--out", "{file}"],
    ["export", "{gps}", "--format", "highway-env", "--out", "{file}"],
    ["eval", "{gps}", "--keyframes", "{gps}", "--out", "{file}"],
    ["build", "{gps}", "--out", "{file}"],
    ["demo", "--out", "{file}"],
    ["trace", "{gps}", "--out", "{file}/ego.csv"],
])
def test_unusable_output_path_is_one_line_error_before_any_work(command, sample_gpx, tmp_path,
                                                                 capsys):
    # An output file that is a folder, or an output folder that is a file: exit 2 with one
    # line naming it, checked before the inputs are read, and nothing written.
    folder = tmp_path / "existing_folder"
    folder.mkdir()
    afile = tmp_path / "existing_file"
    afile.write_text("keep me\n")
    args = [a.format(gps=sample_gpx, folder=folder, file=afile) for a in command]
    before = sorted(p.name for p in tmp_path.rglob("*"))
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and "existing_" in err[0]
    assert sorted(p.name for p in tmp_path.rglob("*")) == before
    assert afile.read_text() == "keep me\n"


def test_readme_sections_name_only_options_their_command_has():
    # Each "### `vid2sim CMD ...`" section of the README and docs/commands.md may only mention
    # options CMD accepts
    # (the detect section once advertised a --fps that detect does not have).
    import re
    from pathlib import Path

    from click.testing import CliRunner

    from vid2sim.cli import cli

    root = Path(__file__).resolve().parents[1]
    readme = "\n".join((root / name).read_text(encoding="utf-8")
                       for name in ("README.md", "docs/commands.md"))
    other_programs = {"export": {"--log"}}  # DIR/replay.py's own option
    checked = 0
    for section in re.split(r"^### ", readme, flags=re.MULTILINE)[1:]:
        m = re.match(r"`vid2sim (\w[\w-]*)", section)  # test-policy has a hyphen
        if not m or m.group(1) == "models":
            continue
        cmd = m.group(1)
        body = section.split("\n## ")[0]
        mentioned = set(re.findall(r"(?<![\w-])(--[a-z][a-z-]+)", body))
        help_text = CliRunner().invoke(cli, [cmd, "--help"]).output
        unknown = mentioned - other_programs.get(cmd, set()) - {
            o for o in mentioned if o in help_text}
        assert not unknown, f"README section of `vid2sim {cmd}` names {sorted(unknown)}"
        checked += 1
    assert checked >= 8


def test_the_readme_is_short_and_the_docs_carry_the_rest():
    import re
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    readme = (root / "README.md").read_text(encoding="utf-8")
    assert len(readme.splitlines()) <= 250
    pages = sorted((root / "docs").glob("*.md"))
    assert len(pages) >= 2
    # user documentation names no issue numbers or work in progress
    for page in [root / "README.md", *pages]:
        text = page.read_text(encoding="utf-8")
        assert not re.search(r"\bissue \d+|\(#\d+\)|this branch", text, re.IGNORECASE), page.name
    # every page the README links to exists
    for link in re.findall(r"\]\((docs/[^)#]+)", readme):
        assert (root / link).exists(), link
