"""The reference scene family (configs/references.yaml) and its converged results.

Every accuracy figure is measured against these: each scene run `runs` times on
consecutive replicates and pooled (`spread.reference`), on the full model unless said
otherwise. Results go to DIR/<model>/<name>.json (one file per scene, written when it
is done, so a long computation resumes where it stopped) and DIR/<model>.md (a table).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Callable, Optional

from spreadgym.config.resources import config_dir, read_yaml
from spreadgym.config.scene import Scene, load_scene
from spreadgym.errors import ConfigError
from spreadgym.report import format_table, print_json
from spreadgym.spread.reference import pool_runs, reference_from

FAMILY_FILE = "references.yaml"
DEFAULT_RUNS = 32  # x 2048 granules x 32 release angles (the default run) = 65 536 simulated


def reference_family(overrides: Optional[dict] = None) -> dict[str, Scene]:
    """name -> scene of every reference, with `overrides` (dotted keys) applied to all."""
    entries = read_yaml(config_dir() / FAMILY_FILE)["references"]
    family = {}
    for entry in entries:
        family[entry["name"]] = load_scene(entry["scene"], {**entry["set"], **(overrides or {})})
    return family


def reference_path(out_dir: Path, model: str, name: str) -> Path:
    return Path(out_dir) / model / f"{name}.json"


def compute_references(out_dir: Path, model: str = "pymunk", runs: Optional[int] = None,
                       names: Optional[list[str]] = None, overrides: Optional[dict] = None,
                       progress: Callable[[str], None] = lambda _: None) -> list[dict]:
    """Compute (or reuse) the reference of every family scene; returns their JSON dicts.

    A stored reference is reused when its model and overrides match and, if `runs` is
    given, its run count too; a missing one is computed with `runs` (default
    DEFAULT_RUNS). Each stored file records how many runs it pooled. DIR/<model>.md is
    rewritten with every stored scene of the family."""
    family = reference_family(overrides)
    unknown = sorted(set(names or []) - set(family))
    if unknown:
        raise ConfigError("references", f"unknown reference scene(s) {', '.join(unknown)}; "
                                        f"known: {', '.join(family)}")
    results = []
    for name in names or list(family):
        path = reference_path(out_dir, model, name)
        settings = {"model": model, "runs": runs or DEFAULT_RUNS, "overrides": overrides or {}}
        if path.is_file():
            stored = json.loads(path.read_text(encoding="utf-8"))
            kept = stored.get("settings", {})
            same_run = (kept.get("model"), kept.get("overrides")) == (model, overrides or {})
            if same_run and runs in (None, kept.get("runs")):
                results.append(stored)
                continue
        progress(f"{name}: {settings['runs']} runs, {model}")
        payload = reference_from(family[name], pool_runs(family[name], settings["runs"], model=model)).to_json()
        payload.update(name=name, settings=settings)
        path.parent.mkdir(parents=True, exist_ok=True)
        partial = path.with_suffix(".json.partial")
        with open(partial, "w", encoding="utf-8") as handle:
            print_json(payload, handle)
        partial.replace(path)  # never a half-written result under the final name
        results.append(json.loads(path.read_text(encoding="utf-8")))
    stored = load_references(out_dir, model)  # the table lists every stored scene, not just these
    write_table([stored[name] for name in family if name in stored], Path(out_dir) / f"{model}.md")
    return results


def load_references(out_dir: Path, model: str = "pymunk") -> dict[str, dict]:
    """name -> stored reference JSON (only the scenes computed so far)."""
    folder = Path(out_dir) / model
    return {p.stem: json.loads(p.read_text(encoding="utf-8")) for p in sorted(folder.glob("*.json"))}


def write_table(results: list[dict], path: Path) -> None:
    rows = [[r["name"], r["granules"], r["replicates"], r["target_swath_m"], r["driving"],
             _fmt(r["cv_percent_at_target"]), _fmt(r["cv_standard_error_percent"]), _fmt(r["cv_raw_percent"]),
             r["effective_swath_m"], "-".join(f"{w:g}" for w in r["effective_swath_interval_m"]), round(r["wall_s"])]
            for r in results]
    header = ("scene", "granules", "replicates", "target (m)", "driving", "CV (%)", "SE (pp)", "plain CV (%)",
              "swath (m)", "swath within 2 SE (m)", "wall (s)")
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    path.parent.mkdir(parents=True, exist_ok=True)
    model = results[0]["model"] if results else "?"
    path.write_text(f"# Converged references ({model})\n\n" + "\n".join(lines) + "\n", encoding="utf-8")
    print(format_table(rows, header))


def _fmt(value) -> str:
    return "-" if value is None else f"{value:.2f}"
