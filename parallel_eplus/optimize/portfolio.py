"""One building or several: a single model or spec is optimized in DIR itself; several (or a folder of them) each in
DIR/<name>/, one after the other, a failed one reported and the next one started, then DIR/summary.md tables every
building's answer. With `ray_address`, the buildings run at once as Ray tasks (placement.py) instead."""

from __future__ import annotations

import logging
from pathlib import Path

import pandas as pd

from parallel_eplus.optimize.folders import BuildingFolder, short_name
from parallel_eplus.optimize.pipeline import not_finished, optimize_building
from parallel_eplus.optimize.prepare import source_of
from parallel_eplus.optimize.settings import OptimizeSettings

log = logging.getLogger(__name__)

SUMMARY = "summary.md"
STOPPED = "stopped before its answer (rerun the same command to continue)"


def sources_of(arguments: list[str]) -> list[Path]:
    """Each argument a model, a spec or a built-in spec's name; a folder: its .idf models and the .toml specs whose
    name is not a model's beside them (a starter spec written next to its model would count the building twice)."""
    out: list[Path] = []
    for argument in arguments:
        path = Path(argument)
        if path.is_dir():
            models = sorted(path.glob("*.idf"))
            specs = [s for s in sorted(path.glob("*.toml")) if s.stem not in {m.stem for m in models}]
            if not models and not specs:
                raise FileNotFoundError(f"{path}: no .idf model or .toml spec in it")
            out += [p.resolve() for p in models + specs]
        else:
            out.append(source_of(argument))
    return list(dict.fromkeys(out))


def folders_for(sources: list[Path], out: Path) -> list[BuildingFolder]:
    if len(sources) == 1:
        return [BuildingFolder(out, short_name(sources[0]), sources[0])]
    names: dict[str, int] = {}
    folders = []
    for source in sources:
        name = short_name(source)
        names[name] = names.get(name, 0) + 1
        name = name if names[name] == 1 else f"{name}-{names[name]}"
        folders.append(BuildingFolder(out / name, name, source))
    return folders


def run_optimize(
    arguments: list[str], out: Path, settings: OptimizeSettings, show: bool = True, ray_address: str | None = None
) -> int:
    """Optimize every building named (on the Ray cluster at `ray_address`, "local" for this machine's); 0 when each
    has its answer, 1 when one could not be finished. Stopped (Ctrl-C), several buildings' summary still tables what
    is answered so far, the rest as not finished: a portfolio run in chunks shows its answers chunk by chunk."""
    folders = folders_for(sources_of(arguments), Path(out).resolve())
    rows: list[dict | None] = [None] * len(folders)
    try:
        if ray_address:
            from parallel_eplus.optimize.placement import optimize_on_ray

            optimize_on_ray(folders, settings, ray_address, rows)
        else:
            for i, folder in enumerate(folders):
                rows[i] = _one(folder, folders, i, settings, show)
    except KeyboardInterrupt:
        if len(folders) > 1:
            so_far = [r or not_finished(f, STOPPED) for r, f in zip(rows, folders, strict=True)]
            write_summary(so_far, Path(out).resolve(), settings)
        raise
    return _finish(rows, folders, out, settings)  # type: ignore[arg-type]


def _one(folder: BuildingFolder, folders: list[BuildingFolder], i: int, settings: OptimizeSettings, show: bool) -> dict:
    if len(folders) > 1:
        log.info("building %d of %d: %s (%s)", i + 1, len(folders), folder.name, folder.source)
    try:
        return optimize_building(folder, settings, show)
    except KeyboardInterrupt:
        log.warning("%s: interrupted; rerun the same command to continue (finished stages are kept in %s)",
                    folder.name, folder.root)  # fmt: skip
        raise
    except (ValueError, FileNotFoundError, OSError) as e:
        if len(folders) == 1:
            raise
        log.error("%s: %s", folder.name, e)
        return not_finished(folder, str(e))


def _finish(rows: list[dict], folders: list[BuildingFolder], out: Path, settings: OptimizeSettings) -> int:
    if len(folders) > 1:
        write_summary(rows, Path(out).resolve(), settings)
    for r in rows:
        log.info("%s: %s", r["building"], f"{r['chosen']}: {r['why']}" if r["chosen"] else r["why"])
    return 0 if all(r["chosen"] for r in rows) else 1


def write_summary(rows: list[dict], out: Path, settings: OptimizeSettings) -> Path:
    lines = ["# Every building: what to install", "",
             f"Each building's choice on the held-out weathers ({', '.join(settings.held_out)}): its measure (HVAC "
             "energy; a data center's facility energy; the bill with --objective cost) and occupied discomfort against "
             "its own controls (sums over the test periods). Details: each building's report.", "",
             "| building | chosen | measure | chosen × own | best candidate × own | occupied K·h: own → chosen "
             "| report |",
             "|---|---|---|---|---|---|---|"]  # fmt: skip
    for r in rows:
        x = "" if pd.isna(r.get("metric_x", float("nan"))) else f"{r['metric_x']:.3f}"
        best = "" if r.get("best_other_x") is None or pd.isna(r["best_other_x"]) else f"{r['best_other_x']:.3f}"
        kh = f"{r['kh_own']:.2f} → {r['kh']:.2f}" if "kh" in r else ""
        chosen = r["chosen"] or f"not finished: {r['why']}"
        link = Path(r["folder"]).relative_to(out) / "report.md"
        report = f"[{link}]({link})" if (out / link).is_file() else ""  # a building not reached yet has none
        lines.append(f"| {r['building']} | {chosen} | {r.get('metric', '')} | {x} | {best} | {kh} | {report} |")
    chosen = [r for r in rows if r["chosen"]]
    keep = sum(r["chosen"] == "own controls" for r in chosen)
    lines += ["", f"{len(chosen)} of {len(rows)} buildings answered: {len(chosen) - keep} with a controller to "
              f"install, {keep} keep their own controls."]  # fmt: skip
    path = out / SUMMARY
    path.write_text("\n".join(lines) + "\n")
    return path
