"""Where the built-in buildings' files are: the one module that knows, installed from a wheel or run from a checkout.

The repository keeps EnergyPlus models in its top-level `idf/` folder and weather in `weather/`, where users
know them. A wheel carries `idf/` as package data, `parallel_eplus/buildings/models/` (pyproject.toml maps the
folder), found through `importlib.resources`. The weathers are not copied into the wheel: the EnergyPlus wheel we
depend on ships the paper's five EPWs byte for byte (`pyenergyplus/data/weather/`), so they are found there, and
its prototype buildings (`pyenergyplus/data/model/`), which built-in specs use as they are.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

# A source checkout (editable install, tests, scripts): the folders beside the package.
SOURCE_ROOT = Path(__file__).resolve().parents[2]
SPECS = "specs"  # built-in building specs, always inside the package


def _package_dir(name: str) -> Path:
    return Path(str(resources.files("parallel_eplus.buildings") / name))


def _energyplus_data_dir(name: str) -> Path | None:
    try:
        return Path(str(resources.files("pyenergyplus") / "data" / name))
    except ModuleNotFoundError:
        return None


def model_dirs() -> list[Path]:
    """Folders holding the built-in EnergyPlus models: ours (the wheel's, then the checkout's `idf/`), then the
    EnergyPlus wheel's prototype buildings, which specs use unmodified (the engine prepares each run's copy)."""
    dirs = (_package_dir("models"), SOURCE_ROOT / "idf", _energyplus_data_dir("model"))
    return [d for d in dirs if d is not None and d.is_dir()]


def energyplus_model_dir() -> Path | None:
    """The EnergyPlus wheel's example models (the DOE and ASHRAE prototypes), which any spec may name bare."""
    return _energyplus_data_dir("model")


def weather_dirs() -> list[Path]:
    """Folders holding the built-in weathers: the checkout's `weather/`, then the EnergyPlus wheel's."""
    dirs = (SOURCE_ROOT / "weather", _energyplus_data_dir("weather"))
    return [d for d in dirs if d is not None and d.is_dir()]


def spec_dir() -> Path:
    """The folder of the built-in building specs (in the wheel or the checkout)."""
    return _package_dir(SPECS)


def _find(name: str, dirs: list[Path], what: str) -> Path:
    for d in dirs:
        if (d / name).is_file():
            return (d / name).resolve()
    looked = ", ".join(map(str, dirs))
    raise FileNotFoundError(f"{what} {name!r} not found among the built-in files (looked in {looked})")


def model_file(name: str) -> Path:
    """A built-in EnergyPlus model (`.idf`) by file name."""
    return _find(name, model_dirs(), "model file")


def weather_file(name: str) -> Path:
    """A built-in weather (`.epw`) by file name."""
    return _find(name, weather_dirs(), "weather file")


def tariff_file(name: str) -> Path:
    """A built-in tariff (`buildings/tariffs/*.toml`) by file name, with or without `.toml`."""
    name = name if name.endswith(".toml") else f"{name}.toml"
    return _find(name, [_package_dir("tariffs")], "tariff file")


def builtin_specs() -> dict[str, Path]:
    """The package's own building specs by name (the file's stem): `--building datacenter-crac`."""
    return {p.stem: p for p in sorted(spec_dir().glob("*.toml"))}


def spec_file(building: str | Path) -> Path:
    """A spec by path, or a built-in one by name; fails naming the built-in ones."""
    path = Path(building).expanduser()
    if path.is_file():
        return path.resolve()
    specs = builtin_specs()
    if str(building) in specs:
        return specs[str(building)]
    raise FileNotFoundError(
        f"building spec {str(building)!r} not found: give a .toml path or one of {', '.join(specs)}"
    )


def is_builtin_spec(path: Path) -> bool:
    """Whether a spec file is one of the package's own (bare file names in it are built-in files)."""
    return Path(path).resolve().parent == spec_dir().resolve()


def saved_building(saved: dict) -> str | None:
    """The spec a run trained on (its config.json's `building`), as `load_building` takes it: a built-in spec by
    name (saved by path by another checkout or install), a user's by path; None: the data center."""
    building = saved.get("building")
    if building and (not Path(building).is_file() or Path(building).parent.match("parallel_eplus/buildings/specs")):
        building = Path(building).stem
    return building
