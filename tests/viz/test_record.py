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


def test_a_report_never_replaces_the_scene_file(tmp_path, capsys):
    from spreadgym.config.resources import resolve_named

    scene = tmp_path / "mine.html"
    scene.write_text(resolve_named("scenes", "paper").read_text())
    assert main(["simulate", "--scene", str(scene), *SMALL, "--report", str(scene)]) == 2
    assert "would replace an input" in capsys.readouterr().err
    assert scene.read_text() == resolve_named("scenes", "paper").read_text()
