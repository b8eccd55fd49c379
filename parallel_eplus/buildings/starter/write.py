"""`parallel-eplus building init`: a starter spec from any EnergyPlus model, in minutes rather than an afternoon.

From a survey of the model (buildings/starter/survey.py: EnergyPlus's own list of what can be read and actuated, and the
values seen in its first simulated week), the observations (outdoor, zone temperatures, facility power) are written
active and the likely actions (zone thermostat setpoints, node setpoints, fan flows) as commented candidates, with
bounds a user then edits. What it writes loads with `load_spec`; the candidates are commented because choosing
what the agent owns is the user's decision.
"""

from __future__ import annotations

import re
from pathlib import Path

from parallel_eplus.buildings.idf.loops import topology
from parallel_eplus.buildings.idf.objects import idf_objects
from parallel_eplus.buildings.idf.thermostat import zone_setpoints
from parallel_eplus.buildings.idf.ventilation import plan_ventilation
from parallel_eplus.buildings.starter.air_side import economizer_candidates, fan_candidates, node_candidates
from parallel_eplus.buildings.starter.survey import Survey, summary, survey
from parallel_eplus.buildings.starter.toml_text import candidate as _candidate
from parallel_eplus.buildings.starter.toml_text import clamp as _clamp
from parallel_eplus.buildings.starter.toml_text import num as _num
from parallel_eplus.buildings.starter.toml_text import seen_text
from parallel_eplus.buildings.starter.toml_text import snake as _snake
from parallel_eplus.buildings.starter.toml_text import toml_str as _str

# Fuels besides electricity that a facility meter may count (EnergyPlus's resource types), for the energy figure.
FUELS = ("NaturalGas", "Propane", "FuelOilNo1", "FuelOilNo2", "Diesel", "Gasoline", "Coal", "OtherFuel1",
         "OtherFuel2", "DistrictCooling", "DistrictHeatingWater", "DistrictHeatingSteam")  # fmt: skip


def _idf_names(idf: Path) -> dict[str, str]:
    """Every field value in the IDF by its upper-case form: EnergyPlus lists keys upper-case, users wrote them."""
    text = re.sub(r"!.*", "", idf.read_text(encoding="latin-1"))
    names: dict[str, str] = {}
    for value in re.split(r"[,;]", text):
        value = value.strip()
        names.setdefault(value.upper(), value)
    return names


def _path(target: Path, spec_dir: Path, weather: bool = False) -> str:
    """Relative to the spec when beside or below it; a built-in weather, or a model of the EnergyPlus wheel, by its
    bare name (the spec then works on any install); else absolute."""
    from parallel_eplus.buildings.resources import energyplus_model_dir, weather_file

    target = target.resolve()
    if target.is_relative_to(spec_dir.resolve()):
        return target.relative_to(spec_dir.resolve()).as_posix()
    wheel = energyplus_model_dir()
    if not weather and wheel is not None and target.parent == wheel.resolve():
        return target.name
    try:
        if weather and weather_file(target.name) == target:
            return target.name
    except FileNotFoundError:
        pass
    return str(target)


def weather_key(weather: Path) -> str:
    """USA_CA_San.Francisco...epw -> CA (the paper's short names); otherwise the file's stem."""
    parts = weather.stem.split("_")
    return parts[1] if len(parts) > 2 and len(parts[0]) == 3 and len(parts[1]) == 2 else weather.stem


def _observation(name: str, variable: str, key: str, low: float, high: float, note: str = "") -> list[str]:
    lines = ["[[observations]]" + (f"  # {note}" if note else "")]
    lines += [f"name = {_str(name)}", f"variable = {_str(variable)}", f"key = {_str(key)}", f"low = {_num(low)}"]
    return [*lines, f"high = {_num(high)}", ""]


def _zone_air_nodes(idf: Path) -> set[str]:
    """Zone air nodes (ZoneHVAC:EquipmentConnections' fifth field): their setpoint is the thermostat's, not a knob."""
    text = re.sub(r"!.*", "", idf.read_text(encoding="latin-1"))
    found = re.findall(r"ZoneHVAC:EquipmentConnections\s*,([^;]*);", text, re.I)
    return {f.split(",")[4].strip().upper() for f in found if len(f.split(",")) > 4}


def occupancy_schedule(idf: Path) -> str | None:
    """The schedule most of the model's People objects follow (their 'Number of People Schedule Name')."""
    from parallel_eplus.buildings.idf.objects import idf_objects

    names = [o.fields[2] for o in idf_objects(idf.read_text(encoding="latin-1"))
             if o.kind.lower() == "people" and len(o.fields) > 2 and o.fields[2]]  # fmt: skip
    return max(dict.fromkeys(names), key=names.count) if names else None


def starter_spec(idf: Path, weather: Path, out: Path, s: Survey, name: str | None = None) -> str:
    """The commented TOML text of a starter spec for `idf` from a survey `s`."""
    orig = _idf_names(idf)
    o = lambda key: orig.get(key.upper(), key)  # noqa: E731
    spec_dir = out.parent
    seen = lambda variable, key: s.seen.get((variable, key.upper()))  # noqa: E731
    name = name or _snake(idf.stem).replace("_", "-")
    n_act = sum(r[0] == "Actuator" for r in s.rows)
    n_var = sum(r[0] == "OutputVariable" for r in s.rows)
    lines = [
        f"# Starter spec for {idf.name}, written by `parallel-eplus building init` after {s.days:.1f} simulated day(s)",
        f"# on {weather.name}. EnergyPlus listed {n_act} actuators and {n_var} output variables: the",
        "# observations below are the usual ones; the actions are commented candidates. Uncomment what the agent",
        "# should own, check the bounds (they come from a week of the model's own control), then run",
        "# `parallel-eplus building check` on this file. Keys are matched case-insensitively by EnergyPlus.",
    ]
    lines += [
        f"name = {_str(name)}",
        f"idf = {_str(_path(idf, spec_dir))}",
        f"# timesteps_per_hour: the IDF's Timestep ({s.timesteps_per_hour} per hour) is the control step",
        *_ventilation(idf),
        "",
        "[weathers]  # short names for --weathers; any .epw path works too",
        f"{weather_key(weather)} = {_str(_path(weather, spec_dir, weather=True))}",
        "",
    ]
    obs: list[str] = []
    outdoor = "Site Outdoor Air Drybulb Temperature"
    if seen(outdoor, "Environment"):
        lines += _observation("outdoor_temp_c", outdoor, "Environment", -20.0, 50.0)
        obs.append("outdoor_temp_c")
    zone_keys = [
        k for k in s.keys("OutputVariable", "Zone Mean Air Temperature") if seen("Zone Mean Air Temperature", k)
    ]
    controlled = set(s.keys("Actuator", "Zone Temperature Control", "Cooling Setpoint"))
    temps = []
    obs_keys: dict[str, str] = {}  # observation -> its zone
    for key in zone_keys:
        n = _snake(o(key)) + "_temp_c"
        obs_keys[n] = key
        lines += _observation(
            n, "Zone Mean Air Temperature", o(key), -20.0, 50.0, "" if key in controlled else "no thermostat"
        )
        obs.append(n)
        if key in controlled:
            temps.append(n)
    ite = []
    for key in s.keys("OutputVariable", "ITE Air Inlet Dry-Bulb Temperature"):
        n = _snake(o(key)) + "_inlet_c"
        lines += _observation(n, "ITE Air Inlet Dry-Bulb Temperature", o(key), -20.0, 60.0, "IT equipment air inlet")
        obs.append(n)
        ite.append(n)
    power = None
    for variable, n in (
        ("Facility Total Electricity Demand Rate", "power_w"),
        ("Facility Total Building Electricity Demand Rate", "building_power_w"),
        ("Facility Total HVAC Electricity Demand Rate", "hvac_power_w"),
    ):
        if seen(variable, "Whole Building"):
            lines += _observation(n, variable, "Whole Building", 0.0, 1e9)
            obs.append(n)
            power = power or n
    if not obs or power is None:
        raise ValueError(f"{idf}: EnergyPlus offered no zone temperature or facility power to observe")
    energy = [power]
    for fuel in FUELS:  # every other fuel the model meters counts in the energy figure and the reward
        if f"{fuel}:FACILITY".upper() in s.meters():
            n = _snake(fuel) + "_w"
            lines += [f"[[observations]]  # {fuel}, as a mean rate over the control step", f"name = {_str(n)}",
                      f'meter = "{fuel}:Facility"', "low = 0.0", "high = 1e9", ""]  # fmt: skip
            obs.append(n)
            energy.append(n)
    temps = temps or [n for n in obs if n.endswith("_temp_c") and n != "outdoor_temp_c"] or ite
    lines += ["# ---- candidate actions (uncomment at least one) ----", ""]
    zones = s.keys("Actuator", "Zone Temperature Control", "Cooling Setpoint")
    if len(zones) > 1:  # what a user most often wants: one knob per setpoint for the whole building
        schedules = zone_setpoints(idf)
        for side in ("cooling", "heating"):
            lines += _together(side, zones, schedules, o, lambda key, v=side: seen(THERMOSTAT_SEEN[v], key))
    for key in zones:
        base, z = _snake(o(key)), o(key)
        c = seen("Zone Thermostat Cooling Setpoint Temperature", key)
        h = seen("Zone Thermostat Heating Setpoint Temperature", key)
        lines += _candidate(
            f"{base}_cooling_setpoint_c", "Zone Temperature Control", "Cooling Setpoint", z, 22.0, 30.0,
            _clamp(c[0], 22.0, 30.0) if c else 24.0, "C", f"zone {z} cooling" + seen_text(c),
        )  # fmt: skip
        lines += _candidate(
            f"{base}_heating_setpoint_c", "Zone Temperature Control", "Heating Setpoint", z, 15.0, 23.0,
            _clamp(h[1], 15.0, 23.0) if h else 21.0, "C", f"zone {z} heating (below cooling)" + seen_text(h),
        )  # fmt: skip
    t = topology(idf.read_text(encoding="latin-1"))
    lines += node_candidates(t, s, o, _zone_air_nodes(idf))
    lines += fan_candidates(s, o) + economizer_candidates(t, s, o)
    thermostat = temps != ite and _thermostats_cover(idf, temps, obs_keys)
    lines += [
        "[reward]  # HVAC energy, comfort within each zone's own setpoints in occupied hours (the preset's)"
        if thermostat
        else "[reward]  # the paper's form: a bonus near `center`, a penalty outside [lower, upper], minus power",
        f"temperatures = [{', '.join(map(_str, temps))}]",
    ]
    if ite and temps != ite:
        lines.append(f"# temperatures = [{', '.join(map(_str, ite))}]  # data centers: the IT inlet air")
    lines += [f"power = {_str(power)}  # electric: peak power"]
    if len(energy) > 1:
        lines.append(f"energy = [{', '.join(map(_str, energy))}]  # every fuel: the energy figure and the reward")
    occupancy = occupancy_schedule(idf)
    if occupancy:
        lines.append(f"occupied = {{ schedule = {_str(occupancy)} }}  # the band applies where its value is above 0")
    else:
        lines.append('# occupied = { hours = [8, 18], weekdays = ["Mon", "Tue", "Wed", "Thu", "Fri"] }  # else always')
    if thermostat:
        lines += [
            'band = "thermostat"  # each zone\'s own heating and cooling setpoint schedules, read each step (BOPTEST)',
            "# band = [22.0, 25.0]  # or one band for every zone, or { zone_temp_c = [low, high], ... }",
            'objective = "hvac"  # what the reward\'s energy term counts: hvac, energy (above), cost or emissions',
        ]
    else:
        lines += [
            "band = [22.0, 25.0]  # reported as % in band; also set center/lower/upper to your comfort range",
            '# objective = "energy"  # what the reward\'s energy term counts: energy (above), hvac, cost or emissions',
            "# center = 23.5",
            "# lower = 23.0",
            "# upper = 24.0",
            "# power_weight = 1e-5  # per W: scale to the building's power",
        ]
    lines += [
        "",
        "[kpis]  # BOPTEST's figures (docs/kpis.md): HVAC energy per fuel; tariff and emission factors per fuel",
    ]
    hvac = [f"Electricity = {_str('hvac_power_w')}"] if "hvac_power_w" in obs else []
    hvac += [f'{fuel} = "{fuel}:HVAC"' for fuel in FUELS if f"{fuel}:HVAC".upper() in s.meters()]
    if hvac:
        lines.append(f"hvac = {{ {', '.join(hvac)} }}")
    lines += [
        "# tariff = { Electricity = { day = 0.20, night = 0.08, day_hours = [7, 22] }, NaturalGas = 0.04 }  # per kWh",
        '# tariff = { Electricity = { file = "commercial-tou-demand.toml" } }  # time of use, demand charges (kpis.md)',
        "# emissions = { Electricity = 0.37, NaturalGas = 0.18 }  # kg CO2e per kWh",
        "# floor_area_m2 = 500.0  # default: the model's own",
        "",
    ]
    if thermostat:  # a top-level key: before the first table
        at = next(i for i, line in enumerate(lines) if line.startswith("idf = ")) + 1
        lines.insert(at, 'preset = "thermostat-planner"  # what `train --building` trains (`parallel-eplus presets`)')
    return "\n".join(lines)


THERMOSTAT_SEEN = {side: f"Zone Thermostat {side.title()} Setpoint Temperature" for side in ("cooling", "heating")}
KNOB = {"cooling": (22.0, 30.0, 24.0), "heating": (15.0, 21.5, 21.0)}  # C: low, high, initial of a shared knob


def _together(side: str, zones: list[str], schedules: dict, o, seen) -> list[str]:
    """One knob per thermostat schedule: the zones that follow the same schedule share it. A warehouse's storage
    heated to 7 C and its office to 20 C on one knob would heat the storage to the office's setpoint; where every
    zone follows one schedule (the offices) this is the one building-wide knob."""
    groups: dict[str | None, list[str]] = {}
    for key in zones:
        zone = schedules.get(key.upper())
        groups.setdefault(getattr(zone, side, None) if zone else None, []).append(key)
    lines: list[str] = []
    control = f"{side.title()} Setpoint"
    low, high, initial = KNOB[side]
    for schedule, keys in groups.items():
        ranges = [r for r in (seen(k) for k in keys) if r]
        lo, hi = min((r[0] for r in ranges), default=low), max((r[1] for r in ranges), default=high)
        group_low, group_high = min(low, float(int(lo))), max(high, float(-int(-hi)))  # the knob holds what was seen
        outside = ranges and (hi < low or lo > high)  # a schedule far from people's comfort (storage at 7 C)
        start = _clamp((hi if side == "heating" else lo) if outside else initial, group_low, group_high)
        what = f"all {len(keys)} thermostats' {side} setpoints"
        what = what if len(keys) > 1 else f"the one thermostat's {side} setpoint"
        note = f"{what} together" + (" (keep below cooling)" if side == "heating" else "")
        name = f"{side}_setpoint_c"
        if len(groups) > 1:
            note = f"{what} on schedule {schedule} together" + seen_text((lo, hi))
            name = f"{side}_setpoint_{_snake(schedule or 'unscheduled')}_c"
        lines += _candidate(name, "Zone Temperature Control", control, [o(k) for k in keys], group_low, group_high,
                            start, "C", note)  # fmt: skip
    return lines


def _ventilation(idf: Path) -> list[str]:
    """The outdoor air on demand, offered where the model holds a fixed minimum (buildings/idf/ventilation.py)."""
    text = idf.read_text(encoding="latin-1")
    plan = plan_ventilation(text, idf_objects(text))
    if not plan.added:
        return []
    held = f"{len(plan.added)} of {len(plan.notes)} outdoor-air controllers hold their design"
    return [
        f'# ventilation = "demand"  # {held}',
        "#   minimum whenever they run; on demand, the controller's copy follows the people (docs/buildings.md)",
    ]


def _thermostats_cover(idf: Path, temps: list[str], keys: dict[str, str]) -> bool:
    """Whether every zone the reward counts has a thermostat with heating and cooling setpoint schedules."""
    from parallel_eplus.buildings.idf.thermostat import zone_setpoints

    setpoints = zone_setpoints(idf)
    found = [setpoints.get(keys.get(t, "").upper()) for t in temps]
    return bool(temps) and all(sp and sp.heating and sp.cooling for sp in found)


def init_spec(
    idf: Path, weather: str | Path | None = None, out: Path | None = None, name: str | None = None
) -> tuple[Path, list[str]]:
    """Survey `idf` and write its starter spec (default: beside the IDF, `<stem>.toml`): its path and a summary.

    `weather`: a short name (CA, CO, FL, IL, VA) or an .epw path; default San Francisco."""
    from parallel_eplus.buildings.weather.files import resolve_weather

    idf = Path(idf).expanduser().resolve()
    if not idf.is_file():
        raise FileNotFoundError(f"model file not found: {idf}")
    weather = resolve_weather(weather or "CA")
    out = Path(out or idf.with_suffix(".toml")).expanduser().resolve()
    if out.exists():
        raise ValueError(f"{out} exists: choose another file with -o, or move it away")
    s = survey(idf, weather)
    text = starter_spec(idf, weather, out, s, name)
    out.write_text(text, encoding="utf-8")
    written = f"{text.count('# [[actions]]')} candidate actions written, commented; observations: {text.count('[[obs')}"
    return out, [*summary(s), written]
