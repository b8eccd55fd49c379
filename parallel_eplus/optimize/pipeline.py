"""One building's stages in order (prepare, test periods, own controls, the reset, training, the learned controller,
the choice, the export, the report), each skipped when status.json says it is done, so a rerun or a resume after
Ctrl-C continues where the last session stopped; returns the building's row for a portfolio's summary."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

from parallel_eplus.optimize import candidates as cands
from parallel_eplus.optimize.budget import MIN_TRAIN_S, MIN_USEFUL_TRAIN_S, Budget
from parallel_eplus.optimize.choice import METRIC_NAMES, Choice, choose, figures, read_results
from parallel_eplus.optimize.export import export
from parallel_eplus.optimize.figures import DAY_PNG, SAVINGS_PNG, day_shown, savings, typical_day
from parallel_eplus.optimize.folders import BuildingFolder
from parallel_eplus.optimize.periods import find, weather_labels
from parallel_eplus.optimize.prepare import prepare
from parallel_eplus.optimize.report import write_report
from parallel_eplus.optimize.scoring import forget, gather, score
from parallel_eplus.optimize.settings import QUICK, QUICK_DAY, OptimizeSettings
from parallel_eplus.optimize.training import acting_from, run_dir, steps_of, timesteps, train

log = logging.getLogger(__name__)


def _stage(folder: BuildingFolder, budget: Budget, name: str, work: Callable[[], dict]) -> dict:
    """Run a stage's work, record its fields and its time (added to an earlier attempt's), and the budget spent."""
    t0 = time.time()
    log.info("%s: %s", folder.name, name)
    before = float(folder.stage(name).get("seconds") or 0.0)
    fields = dict(work())
    fields["seconds"] = round(before + (fields.get("seconds") or (time.time() - t0)), 1)
    record = folder.set_stage(name, **fields)
    budget.save()
    return record


def _check_settings(folder: BuildingFolder, settings: OptimizeSettings) -> None:
    status = folder.status()
    before = status.get("settings")
    if before is not None and before != settings.fingerprint():
        changed = sorted(k for k in set(before) | set(settings.fingerprint())
                         if before.get(k) != settings.fingerprint().get(k))  # fmt: skip
        raise ValueError(f"{folder.root} holds an optimize made with other settings ({', '.join(changed)}): rerun "
                         "with the same options to continue it, or give another --out")  # fmt: skip
    status["settings"] = settings.fingerprint()
    status.setdefault("source", str(folder.source))
    folder.write_status(status)


def optimize_building(folder: BuildingFolder, settings: OptimizeSettings, show: bool = True) -> dict:
    _check_settings(folder, settings)
    if folder.answered(settings.budget_minutes):  # nothing rewritten, no session counted
        log.info("%s: answered already (%s)", folder.name, folder.report)
        held = figures(read_results(folder.results), held_out=True)
        metric = settings.metric(folder.stage("prepare")["kind"])
        return _row(folder, choose(held, metric, weather_labels(settings.held_out)), held, metric)
    budget = Budget(folder, settings.budget_minutes)
    try:
        return _stages(folder, settings, budget, show)
    finally:
        budget.save()


def _stages(folder: BuildingFolder, settings: OptimizeSettings, budget: Budget, show: bool) -> dict:
    notes: list[str] = []
    prep = folder.stage("prepare") if folder.done("prepare") else _stage(
        folder, budget, "prepare", lambda: prepare(folder, settings.weathers[0], show))  # fmt: skip
    if prep.get("state") != "done":
        return _unfinished(folder, settings, f"preparing failed: {prep.get('error')}")
    t0 = time.time()
    periods = find(folder, settings, show)
    if "seconds" not in folder.stage("periods"):
        folder.set_stage("periods", seconds=round(time.time() - t0, 1))
    budget.save()

    own = cands.own(folder)
    if not folder.done("own"):
        _stage(folder, budget, "own", lambda: score(folder, own, periods, settings, show))
    if not folder.done("own"):
        return _unfinished(folder, settings, f"scoring the own controls failed: {folder.stage('own').get('error')}")
    scored = [own]

    reset = cands.reset(folder)
    if not folder.done("reset"):
        _stage(folder, budget, "reset", lambda: _score_reset(folder, reset, periods, settings, show))
    r = folder.stage("reset")
    if r.get("state") == "done":
        scored.append(reset)
    else:
        notes.append(f"Guideline 36's supply-air reset: {r.get('reason') or r.get('error')}")

    preset = cands.preset_for(prep["kind"], r.get("state") == "done", settings.preset)
    learned = _learned(folder, settings, budget, preset, periods, notes, show)
    if learned is not None:
        scored.append(learned)

    gather(folder, scored, periods, settings)
    df = read_results(folder.results)
    train_f, held_f = figures(df, held_out=False), figures(df, held_out=True)
    for c in scored:
        missed = folder.stage(c.key).get("failed_episodes")
        if missed:
            notes.append(f"{c.label}: no result on {', '.join(missed)} (see eval/{c.key}/*/results.md)")
    metric = settings.metric(prep["kind"])
    choice = choose(held_f, metric, weather_labels(settings.held_out))
    folder.set_stage("choice", state="done", chosen=choice.candidate, reason=choice.reason)
    _export(folder, settings, budget, choice, preset, learned, show)
    shown = day_shown(choice.candidate, choice.label, held_f, metric)
    pictures = [savings(train_f, held_f, metric, folder.root / SAVINGS_PNG).name]
    day = _typical_day(folder, df, periods, settings, shown)
    pictures += [day] if day else []
    write_report(folder, settings, metric, train_f, held_f, choice, periods, pictures, notes)
    folder.set_stage("report", state="done", budget_minutes=settings.budget_minutes)
    log.info("%s: %s: %s (report: %s)", folder.name, choice.label, choice.reason, folder.report)
    return _row(folder, choice, held_f, metric)


def _score_reset(folder, reset, periods, settings, show) -> dict:
    prep = folder.stage("prepare")
    if not prep.get("supply_air"):
        return {"state": "skipped", "reason": "the spec has no supply-air action (a System Node Setpoint) to reset"}
    refusal = cands.reset_refusal(folder)
    if refusal:
        return {"state": "refused", "reason": f"refused: {refusal}"}
    fields = score(folder, reset, periods, settings, show)
    if fields["state"] == "failed":  # `evaluate --rbc` refused it: the reason, and on to the next stage
        return {"state": "refused", "reason": f"`evaluate --rbc` refused it: {fields['error']}",
                "seconds": fields.get("seconds")}  # fmt: skip
    return fields


def _learned(folder, settings, budget, preset, periods, notes, show):
    """Train the preset's controller (or continue it where the budget allows), then score it; its Candidate once
    scored, else None with a note."""
    if preset.requires == "rule" and folder.stage("reset").get("state") != "done":
        notes.append(f"learned ({preset.name}): it rides Guideline 36's reset, which this building cannot take")
        return None
    spec = cands.learned_spec(folder, preset)
    planner = cands.scores_planner(preset)
    t = folder.stage("train")
    reserve = budget.reserve_after_training(folder.stage("own").get("seconds") or 60.0, planner)
    target = timesteps(preset, settings)
    floor = MIN_TRAIN_S if settings.quick else MIN_USEFUL_TRAIN_S
    short = budget.too_short(reserve, floor)
    more = t.get("state") == "done" and not short and (t.get("planned") != target or t.get("stopped"))
    if t.get("state") != "done" and short:
        folder.set_stage("train", state="short", error=short, preset=preset.name)
        notes.append(f"learned ({preset.name}): not trained: {short}")
        log.warning("%s: not training: %s", folder.name, short)
        return None
    if t.get("state") != "done" or more:
        pace = {}
        if planner:  # its own pace in training tells how long scoring it will take
            pace = {"steps": steps_of(run_dir(folder)), "acting_from": acting_from(preset, settings),
                    "eval_steps": eval_steps(spec, periods)}  # fmt: skip
        deadline, share = budget.training_deadline(reserve, **pace)
        log.info("%s: training gets %.1f min of the budget (%.1f min left, %.1f reserved to score and export it)",
                 folder.name, share / 60, budget.left_s() / 60, reserve / 60)  # fmt: skip
        info = {"preset": preset.name, "version": preset.version, "summary": preset.summary, "share_s": round(share)}
        _stage(folder, budget, "train", lambda: train(folder, spec, preset, settings, deadline, show) | info)
        t = folder.stage("train")
    if t.get("state") != "done":
        notes.append(f"learned ({preset.name}): training failed: {t.get('error')}")
        return None
    candidate = cands.learned(folder, preset, run_dir(folder))
    scored = folder.stage("learned")
    if scored.get("steps") != t.get("steps"):  # trained further since it was scored: scored again
        forget(folder, cands.LEARNED)
        folder.set_stage("learned", state="pending", steps=t.get("steps"))
    if not folder.done("learned"):
        _stage(folder, budget, "learned", lambda: score(folder, candidate, periods, settings, show)
               | {"steps": t.get("steps")})  # fmt: skip
    if not folder.done("learned"):
        notes.append(f"learned ({preset.name}): scoring failed: {folder.stage('learned').get('error')}")
        return None
    return candidate


def eval_steps(spec, periods: dict) -> int:
    """The control steps of scoring one controller on every period and weather (warm-ups included)."""
    from parallel_eplus.buildings.building import load_building

    per_day = load_building(str(spec)).steps_per_day
    return sum(p["run_days"] * per_day for ps in periods.values() for p in ps.values())


def _export(folder, settings, budget, choice: Choice, preset, learned, show) -> None:
    before = folder.stage("export")
    same = before.get("state") == "done" and before.get("chosen") == choice.candidate
    if same and (choice.candidate != cands.LEARNED or before.get("steps") == folder.stage("train").get("steps")):
        return
    controller = str(learned.args[1].rsplit("=", 1)[0]) if learned is not None else None
    steps = folder.stage("train").get("steps")
    _stage(folder, budget, "export", lambda: export(folder, choice.candidate, choice.reason, controller, preset,
                                                    settings.workers, show) | {"chosen": choice.candidate,
                                                                               "steps": steps})  # fmt: skip


def _typical_day(folder, df, periods, settings, shown) -> str | None:
    """The typical heating (else cooling, else the first) period's day on the first held-out weather that has it."""
    names = [n for n in ("typical_heat", "typical_cool", *periods) if n in periods]
    if not names or df.empty:
        return None
    name = names[0]
    held = [w for w in weather_labels(settings.held_out) if w in periods[name]]
    if not held:
        return None
    day = QUICK_DAY if name == QUICK else periods[name][held[0]]["day"]
    path = typical_day(df, folder.spec, shown, name, held[0], day, folder.root / DAY_PNG)
    return path.name if path else None


def not_finished(folder: BuildingFolder, why: str) -> dict:
    """A building's row without an answer, saying why (a portfolio's summary lists it so)."""
    return {"building": folder.name, "chosen": "", "why": why, "folder": folder.root}


def _unfinished(folder: BuildingFolder, settings: OptimizeSettings, why: str) -> dict:
    folder.report.write_text(f"# {folder.name}: not finished\n\n{why}\n\nLogs: `{folder.logs}`. Fix the cause and "
                             "rerun the same command: finished stages are kept.\n")  # fmt: skip
    log.error("%s: %s", folder.name, why)
    return not_finished(folder, why)


def _row(folder: BuildingFolder, choice: Choice, held, metric: str) -> dict:
    row = {"building": folder.name, "chosen": choice.label, "why": choice.reason, "folder": folder.root,
           "metric": METRIC_NAMES[metric]}  # fmt: skip
    mine = held[held.candidate == choice.candidate]
    if not mine.empty:
        r = mine.iloc[0]
        row |= {"metric_x": r.get(f"{metric}_x"), "kh_own": r.kh_own, "kh": r.kh,
                "best_other_x": held[held.candidate != cands.OWN][f"{metric}_x"].min()
                if (held.candidate != cands.OWN).any() else None}  # fmt: skip
    return row
