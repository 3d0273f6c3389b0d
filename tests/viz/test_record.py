"""`simulate --report FILE`: the record worth printing, HTML or PDF, with everything it promises; bad paths refused
in one line before any work."""

import re

import pytest

from spreadgym.cli.main import main

SMALL = ["--set", "sim.granules=256", "--max-runs", "2"]


def test_an_html_report_carries_the_whole_record(tmp_path, capsys):
    path = tmp_path / "record.html"
    assert main(["simulate", "--scene", "paper", "--set", "spinner.rpm=640", "--set", "vanes.pitch_deg=12", *SMALL,
                 "--report", str(path)]) == 0
    assert f"wrote {path}" in capsys.readouterr().out
    text = path.read_text(encoding="utf-8")
    for expected in ("paper", "compound-10-16-10", "disc speed</th><td>640 rpm", "vane pitch</th><td>12.0°",
                     "drop radius", "drop angle", "working width</th><td>3 m", "racetrack", "CV at 3 m", " +- ",
                     "effective swath", "spreadgym 0.", "300 mm", "4, from 25 to 150 mm"):
        assert expected in text, expected
    assert re.search(r"made by</th><td>spreadgym [0-9.]+, 20\d\d-\d\d-\d\d \d\d:\d\d", text)
    assert 'src="data:image/png;base64,' in text and "http" not in text  # nothing from the network


def test_a_pdf_report_is_one_page(tmp_path):
    path = tmp_path / "record.pdf"
    assert main(["simulate", "--scene", "field", *SMALL, "--report", str(path)]) == 0
    data = path.read_bytes()
    assert data.startswith(b"%PDF") and data.count(b"/Type /Page\n") + data.count(b"/Type /Page ") >= 1
    assert not list(tmp_path.glob(".*partial"))


@pytest.mark.parametrize("name, message", [("record.txt", "give a file ending in .html or .pdf"),
                                           ("missing/record.html", "does not exist")])
def test_a_bad_report_path_is_refused_before_the_work(tmp_path, capsys, name, message):
    assert main(["simulate", "--scene", "paper", *SMALL, "--report", str(tmp_path / name)]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1


def test_a_report_in_a_folder_that_takes_no_file_is_refused_before_the_work(capsys):
    assert main(["simulate", "--scene", "paper", *SMALL, "--report", "/proc/record.html"]) == 2
    err = capsys.readouterr().err
    assert "cannot write in /proc" in err and len(err.strip().splitlines()) == 1


def test_a_report_never_replaces_the_scene_file(tmp_path, capsys):
    from spreadgym.config.resources import resolve_named

    scene = tmp_path / "mine.html"
    scene.write_text(resolve_named("scenes", "paper").read_text())
    assert main(["simulate", "--scene", str(scene), *SMALL, "--report", str(scene)]) == 2
    assert "would replace an input" in capsys.readouterr().err
    assert scene.read_text() == resolve_named("scenes", "paper").read_text()


@pytest.mark.parametrize("swath, cv, expected", [
    (3.5, 7.4, "3.5 m (CV <= 15 % up to it)"),
    (0.5, 31.0, "none: no working width of two trays or more stays under 15 %"),  # one tray's CV is always 0
    (29.0, 17.0, "not at 8 m: the CV is 17.0 % there, over 15 % (the CV dips under it again at 29 m, a wider width)"),
    (5.0, 24.0, "5 m, narrower than the 8 m working width (the CV is 24.0 % there, over 15 %)"),
])
def test_the_swath_never_reads_as_good_news_when_it_is_not(swath, cv, expected):
    from spreadgym.report import swath_text

    metrics = {"effective_swath_m": swath, "target_swath_m": 8.0 if swath != 3.5 else 3.0, "tray_width_m": 0.5,
               "cv_threshold_percent": 15.0, "cv_percent_at_target": cv}
    assert swath_text(metrics) == expected
