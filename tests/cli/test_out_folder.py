"""--out of every command (spreadgym.out_folder): checked before the work, inputs never
written over, another command's outputs refused without --force, and a failed run
leaves nothing behind."""

import pytest

from spreadgym.cli.main import main
from spreadgym.errors import SpreadgymError
from spreadgym.out_folder import STAMP, OutFolder, stamp_of


def test_a_failed_run_removes_what_it_created_and_keeps_what_was_there(tmp_path):
    fresh = OutFolder(tmp_path / "a" / "b" / "c", "fit", ("x.json",))
    fresh.check()
    assert not (tmp_path / "a").exists()  # nothing made before the work
    with pytest.raises(KeyboardInterrupt), fresh.writing() as folder:
        (folder / "x.json").write_text("{}")
        raise KeyboardInterrupt
    assert not (tmp_path / "a").exists()  # every folder it made is gone
    kept = tmp_path / "kept"
    kept.mkdir()
    (kept / "mine.txt").write_text("the user's")
    with pytest.raises(RuntimeError), OutFolder(kept, "fit", ("x.json",)).writing() as folder:
        (folder / "x.json").write_text("{}")
        (folder / "sub").mkdir()
        raise RuntimeError("failed while writing")
    assert sorted(p.name for p in kept.iterdir()) == ["mine.txt"]
    with OutFolder(kept, "fit", ("x.json",)).writing() as folder:
        (folder / "x.json").write_text("{}")
    assert stamp_of(kept) == "fit" and (kept / STAMP).read_text() == "fit\n"


def test_resumed_outputs_are_kept_when_interrupted(tmp_path):
    with pytest.raises(KeyboardInterrupt), OutFolder(tmp_path / "run", "train", keeps_partial=True).writing() as out:
        (out / "checkpoint.zip").write_text("step 1000")
        raise KeyboardInterrupt
    assert (tmp_path / "run" / "checkpoint.zip").is_file()


def test_a_run_that_fails_before_any_output_leaves_no_stamp_only_folder(tmp_path):
    with pytest.raises(SpreadgymError), OutFolder(tmp_path / "run", "train", keeps_partial=True).writing():
        raise SpreadgymError("a bad hyperparameter, found once the folder was made")
    assert not (tmp_path / "run").exists()
    (tmp_path / "old").mkdir()
    (tmp_path / "old" / "mine.txt").write_text("kept")
    with pytest.raises(SpreadgymError), OutFolder(tmp_path / "old", "train", keeps_partial=True).writing():
        raise SpreadgymError("again")
    assert sorted(p.name for p in (tmp_path / "old").iterdir()) == ["mine.txt"]  # its stamp gone, the rest kept


@pytest.mark.parametrize("make, words", [
    (lambda d: (d / STAMP).write_text("chart\n"), "holds the outputs of `spreadgym chart`; add --force"),
    (lambda d: (d / "x.json").write_text("mine"), "holds files of the same names (x.json); add --force"),
    (lambda d: (d / "x.json").mkdir(), "x.json is a folder where the run writes a file"),
])
def test_other_outputs_are_refused_unless_forced(tmp_path, make, words):
    folder = tmp_path / "d"
    folder.mkdir()
    make(folder)
    with pytest.raises(SpreadgymError, match=words.replace("(", r"\(").replace(")", r"\)")):
        OutFolder(folder, "fit", ("x.json",)).check()
    if "is a folder" not in words:
        OutFolder(folder, "fit", ("x.json",), force=True).check()


def test_an_input_is_never_written_over_even_with_force(tmp_path):
    (tmp_path / "x.json").write_text("the input")
    for force in (False, True):
        with pytest.raises(SpreadgymError, match="would replace the input"):
            OutFolder(tmp_path, "fit", ("x.json",), inputs=[tmp_path / "x.json"], force=force).check()
    link = tmp_path / "sub"
    link.symlink_to(tmp_path)  # the same file by another path
    with pytest.raises(SpreadgymError, match="would replace the input"):
        OutFolder(link, "fit", ("x.json",), inputs=[tmp_path / "x.json"], force=True).check()


def test_the_commands_keep_the_rule(tmp_path, capsys):
    """simulate --plot into a fit's folder, a chart into it, a study over a chart: refused,
    one line, before any work; with --force simulate writes beside the fit's files."""
    fitted = tmp_path / "fitted"
    fitted.mkdir()
    (fitted / STAMP).write_text("fit\n")
    (fitted / "scene.yaml").write_text("the fit's")
    argvs = [["simulate", "--set", "sim.granules=64", "--max-runs", "2", "--plot", str(fitted)],
             ["chart", "--scene", "paper", "--fertilizers", "pellet", "--widths", "3", "--out", str(fitted)],
             ["study", "paper", "--out", str(fitted)]]
    for argv in argvs:
        code = main(argv)
        err = capsys.readouterr().err
        assert code == 2 and "holds the outputs of `spreadgym fit`; add --force" in err and err.count("\n") == 1, err
    assert main(argvs[0] + ["--force"]) == 0
    capsys.readouterr()
    assert (fitted / "pattern.png").is_file() and (fitted / "scene.yaml").read_text() == "the fit's"
    assert stamp_of(fitted) == "fit"  # the folder stays the fit's


def test_a_scene_file_is_never_replaced_by_simulate_plots(tmp_path, capsys):
    import yaml

    from spreadgym.config.scene import load_scene_dict

    scene = tmp_path / "pattern.png"  # an odd name, but the user's scene
    scene.write_text(yaml.safe_dump(load_scene_dict("paper")))
    code = main(["simulate", "--scene", str(scene), "--plot", str(tmp_path), "--force", "--max-runs", "2"])
    err = capsys.readouterr().err
    assert code == 2 and "would replace the input" in err


def test_a_failed_run_over_an_earlier_one_leaves_the_earlier_outputs_whole(tmp_path):
    folder = tmp_path / "fit"
    with OutFolder(folder, "fit", files=("fit.json", "parameters.csv", "plots/fit.png")).writing() as out:
        (out / "fit.json").write_text("old")
        (out / "parameters.csv").write_text("old")
        (out / "plots").mkdir()
        (out / "plots" / "fit.png").write_text("old")
    with pytest.raises(KeyboardInterrupt), OutFolder(folder, "fit", files=("fit.json", "parameters.csv",
                                                                           "plots/fit.png")).writing() as out:
        (out / "parameters.csv").write_text("new")  # written over before the interruption
        (out / "plots" / "fit.png").write_text("new")
        raise KeyboardInterrupt
    assert [(folder / n).read_text() for n in ("fit.json", "parameters.csv", "plots/fit.png")] == ["old"] * 3
    with OutFolder(folder, "fit", files=("fit.json", "parameters.csv", "plots/fit.png")).writing() as out:
        (out / "fit.json").write_text("new")  # a run that writes fewer files: the folder holds its outputs only
    assert (folder / "fit.json").read_text() == "new" and not (folder / "parameters.csv").exists()
    assert not (folder / ".spreadgym-replaced").exists()
