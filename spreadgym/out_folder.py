"""Output folders (`--out DIR` of every command): checked before the work, written after
it, never over the user's files.

One rule for every command, the chart's rule made general:

* before any work (`OutFolder.check`): DIR is a folder or not there yet, and the nearest
  folder that exists takes a file; no file the run writes is a folder there; no input of
  the run is among the files it writes (never replaced, `--force` or not); DIR holds no
  other command's outputs (its stamp, the file `.spreadgym`, names the command that wrote
  it), and no file the run writes is there already, unless the command replaces or
  resumes its own outputs (a chart, a training run, the bench and study folders) or
  `--force` is given;
* nothing is created before the work: the folder and its stamp are made at the first
  write (`OutFolder.writing`);
* a run that fails or is interrupted while it writes removes every file and folder it
  created in DIR (and DIR, if it made it), unless the command keeps its finished parts
  to resume them (a chart's cells, a training run's checkpoints). Single files are
  written whole or not at all (`write_atomic`).
"""

from __future__ import annotations

import os
import shutil
import tempfile
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, Optional, Sequence

from spreadgym.config.base import brief
from spreadgym.errors import SpreadgymError

STAMP = ".spreadgym"  # one line: the command whose outputs the folder holds


def partial_path(path: Path) -> Path:
    """Where `write_atomic` writes `path` before renaming it."""
    return path.with_name(f".{path.name}.partial")


def write_atomic(path: Path, content: str | bytes) -> Path:
    """Write `content` (text as UTF-8, or bytes) to `path` whole: a temporary file beside
    it, renamed over it."""
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = partial_path(path)
    data = content.encode("utf-8") if isinstance(content, str) else content
    with open(partial, "wb") as handle:
        handle.write(data)
        handle.flush()
        os.fsync(handle.fileno())
    os.replace(partial, path)
    return path


def named_files(*values: Optional[str | Path]) -> list[Path]:
    """The files among command-line values (a --scene that names a file rather than a
    shipped scene, a --config, a --policy): inputs an output folder may not write over."""
    return [Path(v) for v in values if v and Path(v).is_file()]


def stamp_of(folder: Path) -> Optional[str]:
    """The command named by `folder`'s stamp (None: no stamp, or not readable)."""
    try:
        with open(Path(folder) / STAMP, encoding="utf-8") as handle:
            return handle.read(200).strip() or None
    except (OSError, UnicodeDecodeError):
        return None


@dataclass
class OutFolder:
    """The output folder of one run of `command` (e.g. "fit").

    files: names (relative to the folder) the run writes, as far as known before the
    work; inputs: the files the run reads; replaces_own: a folder holding this command's
    earlier outputs is written over (reports made again from their command line) or
    resumed rather than refused; keeps_partial: an interrupted run keeps what it wrote
    (finished parts a rerun resumes)."""

    path: Path
    command: str
    files: Sequence[str] = ()
    inputs: Sequence[Path] = ()
    force: bool = False
    replaces_own: bool = True
    keeps_partial: bool = False
    marker: Optional[str] = None  # a file only this command writes: a folder holding it is this command's,
    # stamped or not (folders written before stamps, e.g. a chart's manifest.json)
    flag: str = "--out"

    def refuse(self, message: str) -> SpreadgymError:
        return SpreadgymError(f"{self.flag} {brief(str(self.path))[1:-1]}: {message}")

    def check(self) -> None:
        """Every refusal, before the work and writing nothing (see the module's docstring)."""
        path = Path(self.path)
        problem = folder_problem(path)
        if problem:
            raise self.refuse(problem)
        due = [path / name for name in self.files]
        for target in (t for name in due for t in (name, partial_path(name))):
            if target.is_dir():
                raise self.refuse(f"{target} is a folder where the run writes a file; remove it or use another "
                                  f"{self.flag}")
        for name in self.inputs:
            if name is not None and _is_among(Path(name), [path / STAMP, *due]):
                raise self.refuse(f"would replace the input {name}; choose another {self.flag} (inputs are never "
                                  "written over)")
        owner = self.owner()
        if self.force:
            return
        if owner is not None and owner != self.command:
            raise self.refuse(f"holds the outputs of `spreadgym {owner}`; add --force to write beside them, or "
                              "choose another folder")
        there = [target.name for target in due if target.exists()]
        if there and not (self.replaces_own and owner == self.command):
            shown = ", ".join(there[:4]) + (" ..." if len(there) > 4 else "")
            whose = f"an earlier `spreadgym {owner}`'s outputs" if owner else "files of the same names"
            raise self.refuse(f"holds {whose} ({shown}); add --force to replace them, or choose another folder")

    def owner(self) -> Optional[str]:
        """The command whose outputs the folder holds (its stamp, or this command's marker file), or None."""
        path = Path(self.path)
        if not path.is_dir():
            return None
        stamp = stamp_of(path)
        if stamp is None and self.marker is not None and (path / self.marker).is_file():
            return self.command
        return stamp

    @contextmanager
    def writing(self) -> Iterator[Path]:
        """The folder, created (with its stamp, where it has none) now; what this run
        created there is removed if the block fails (unless the command keeps finished parts
        and wrote some: a stamp alone is removed). An earlier run's files that this one
        writes over are set aside first and put back if the block fails, so a failed or
        interrupted run leaves the earlier outputs whole, never a mix of old and new."""
        path = Path(self.path)
        missing = [p for p in (path, *path.absolute().parents) if not p.exists()]
        path.mkdir(parents=True, exist_ok=True)
        aside = None if self.keeps_partial or missing else _set_aside(path, self.files)
        before = set() if missing else set(os.listdir(path))
        try:
            if stamp_of(path) is None:
                write_atomic(path / STAMP, self.command + "\n")
            yield path
        except BaseException:
            stamp_only = set(os.listdir(path)) - before <= {STAMP}  # nothing finished to keep
            if not self.keeps_partial or stamp_only:
                _remove_new(path, missing[-1] if missing else None, before)
            if aside is not None:
                _put_back(aside, path)
            raise
        if aside is not None:
            shutil.rmtree(aside, ignore_errors=True)


def folder_problem(path: Path) -> Optional[str]:
    """Why `path` cannot be an output folder (a file; the nearest folder that exists
    takes no file: permission bits alone say nothing to root or about read-only file
    systems, so a temporary file is made and removed), or None."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        return "is a file, not a folder"
    existing = next(p for p in (path, *path.absolute().parents) if p.exists() or p == p.parent)
    if not existing.is_dir():
        return f"{existing} is a file, not a folder"
    try:
        with tempfile.TemporaryFile(dir=existing):
            pass
    except OSError as exc:
        return f"cannot write in {existing} ({exc.strerror or type(exc).__name__})"
    return None


ASIDE = ".spreadgym-replaced"  # an earlier run's outputs while a run writes over them


def _set_aside(path: Path, files: Sequence[str]) -> Path:
    """Move the files of `files` that `path` holds into its ASIDE folder (emptied first: one
    left by a killed run held outputs that run had already given up); returns that folder."""
    aside = path / ASIDE
    shutil.rmtree(aside, ignore_errors=True)
    aside.mkdir()
    for name in files:
        source = path / name
        if source.is_file() or source.is_symlink():
            (aside / name).parent.mkdir(parents=True, exist_ok=True)
            os.replace(source, aside / name)
    return aside


def _put_back(aside: Path, path: Path) -> None:
    """The files `_set_aside` moved, back where they were (over whatever the failed run wrote)."""
    for moved in sorted(p for p in aside.rglob("*") if not p.is_dir()):
        target = path / moved.relative_to(aside)
        target.parent.mkdir(parents=True, exist_ok=True)
        os.replace(moved, target)
    shutil.rmtree(aside, ignore_errors=True)


def _remove_new(path: Path, made: Optional[Path], before: set) -> None:
    """Remove what a failed run created: the folders it made (`made`, the highest), else
    the entries of `path` that were not there `before`."""
    if made is not None:
        shutil.rmtree(made, ignore_errors=True)
        return
    for name in set(os.listdir(path)) - before:
        target = path / name
        if target.is_dir() and not target.is_symlink():
            shutil.rmtree(target, ignore_errors=True)
        else:
            target.unlink(missing_ok=True)


def _is_among(name: Path, targets: Sequence[Path]) -> bool:
    """Whether the file `name` is one of `targets` (the same file, links followed)."""
    try:
        resolved = name.resolve()
    except OSError:
        return False
    return any(resolved == target.resolve() or (target.exists() and name.exists() and os.path.samefile(name, target))
               for target in targets)
