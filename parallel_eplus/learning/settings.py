"""Each algorithm's settings and the learners' own knobs: plain data classes (a run saves them in its config.json).

The settings a user types as `NAME=VALUE,...` (`--sac`, and `--mpc`/`--mbpo` in model_based/settings.py) are
`FromText` data classes: each field's type annotation says how its text is read (a boolean, an integer, a number,
one of a Literal's words, layer sizes as `64x64`, `none` where the type allows None), and its `setting(default,
help)` carries the one line `--mpc help` prints. A value that does not fit its type is refused by name.
"""

from __future__ import annotations

import functools
import math
import types
from dataclasses import dataclass, field, fields, replace
from typing import Any, ClassVar, Literal, Union, get_args, get_origin, get_type_hints

# How a boolean setting may be written (case-insensitive); anything else is refused, never read as False.
BOOLEANS = {"true": True, "yes": True, "on": True, "1": True, "false": False, "no": False, "off": False, "0": False}


def setting(default: Any, help: str) -> Any:
    """A settings field with its one-line description: the one place `--mpc help` (and the docs) read it from."""
    return field(default=default, metadata={"help": help})


def _optional(hint) -> tuple[Any, bool]:
    """(the type without None, whether None is allowed) for `X | None`."""
    if get_origin(hint) in (Union, types.UnionType) and type(None) in get_args(hint):
        rest = [a for a in get_args(hint) if a is not type(None)]
        return (rest[0] if len(rest) == 1 else Union[tuple(rest)]), True  # noqa: UP007
    return hint, False


def _choices(hint) -> tuple[str, ...]:
    """A Literal's words (empty for any other type)."""
    hint, _ = _optional(hint)
    return get_args(hint) if get_origin(hint) is Literal else ()


def _words(choices) -> str:
    return ", ".join(repr(c) for c in choices[:-1]) + f" or {choices[-1]!r}" if len(choices) > 1 else repr(choices[0])


def type_name(hint) -> str:
    """How `--mpc help` names a setting's type."""
    hint, optional = _optional(hint)
    if get_origin(hint) is Literal:
        name = "|".join(get_args(hint))
    elif get_origin(hint) is tuple:
        name = "sizes (64x64)"
    else:
        name = {bool: "bool", int: "int", float: "float", str: "text"}.get(hint, str(hint))
    return f"{name} or none" if optional else name


def show(value) -> str:
    """A setting's value as it is typed: `true`, `none`, `64x64`."""
    if value is None:
        return "none"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, tuple):
        return "x".join(map(str, value))
    return str(value)


class FromText:
    """`--sac`/`--mpc`/`--mbpo "name=value,..."`: a dataclass's fields by name, each read as its annotated type.

    Booleans take true/false, yes/no, on/off or 1/0 (any case); integers a whole number (`2_000`, `1e4`; not
    `2.7`); floats a finite number; a Literal one of its words; `X | None` also `none`; a tuple of layer sizes
    `64x64`. Anything else is a ValueError naming the flag, the setting and what it accepts. A name given twice:
    the last one counts (a run's `--config` file's settings, then the command line's).
    """

    flag: ClassVar[str]
    # The headings `--mpc help` prints, each before the field it names (the fields keep their order).
    SECTIONS: ClassVar[dict[str, str]] = {}

    def __post_init__(self):
        for name, hint in self.hints().items():
            value, choices = getattr(self, name), _choices(hint)
            if choices and value not in choices and not (value is None and _optional(hint)[1]):
                raise ValueError(f"{name} {value!r}: one of {_words(choices)}")

    @classmethod
    @functools.cache
    def hints(cls) -> dict[str, Any]:
        """Each field's resolved type annotation (`float | None`, `Literal[...]`), by name."""
        resolved = get_type_hints(cls)
        return {f.name: resolved[f.name] for f in fields(cls)}

    @classmethod
    def from_text(cls, text: str | None, base=None, flag: str | None = None):
        """Fields named in `text` over `base` (default: the defaults); `flag` names the option in errors (default:
        the class's own, e.g. `--mpc`)."""
        flag = flag or cls.flag
        settings = replace(base) if base is not None else cls()
        hints = cls.hints()
        for item in filter(None, (p.strip() for p in (text or "").split(","))):
            key, sep, value = item.partition("=")
            key, value = cls.renamed(key.strip().replace("-", "_"), value.strip(), flag)
            if not sep or key not in hints:
                from parallel_eplus.buildings.spec.sections import did_you_mean

                raise ValueError(f"{flag} {item!r}: expected NAME=VALUE with NAME one of {', '.join(hints)}"
                                 f"{did_you_mean(key, hints)} (`{cls.flag} help` describes each)")  # fmt: skip
            setattr(settings, key, cls.parse_value(key, value, flag))
        try:
            settings.__post_init__()
        except ValueError as e:
            raise ValueError(f"{flag} {e}") from None
        return settings

    @classmethod
    def renamed(cls, key: str, text: str, flag: str) -> tuple[str, str]:
        """A setting's name and text as they are called now (a class with renamed settings warns for the old)."""
        return key, text

    @classmethod
    def parse_value(cls, key: str, text: str, flag: str | None = None):
        """One setting's text read as its annotated type; a ValueError naming the flag, the setting and what it
        accepts where the text cannot mean one."""
        hint, optional = _optional(cls.hints()[key])
        text = text.strip()
        where = f"{flag or cls.flag} {key}={text!r}"
        if text.lower() == "none":  # an optional setting left unset (`rail_k=none`)
            if optional:
                return None
            raise ValueError(f"{where}: {key} takes a value, not none ({type_name(hint)})")
        if hint is bool:
            if text.lower() not in BOOLEANS:
                raise ValueError(f"{where}: a boolean: true, false, yes, no, on, off, 1 or 0")
            return BOOLEANS[text.lower()]
        if hint is int:
            try:
                return int(text)
            except ValueError:
                number = _number(text)
                if number is None or not number.is_integer():
                    raise ValueError(f"{where}: a whole number, e.g. {show(getattr(cls, key))}") from None
                return int(number)
        if hint is float:
            if (number := _number(text)) is None:
                raise ValueError(f"{where}: a finite number, e.g. {show(getattr(cls, key))}")
            return number
        if get_origin(hint) is Literal:
            if text not in get_args(hint):
                raise ValueError(f"{where}: one of {_words(get_args(hint))}")
            return text
        if get_origin(hint) is tuple:
            sizes = [_number(v) for v in text.lower().split("x")]
            if any(s is None or not s.is_integer() or s < 1 for s in sizes):
                raise ValueError(f"{where}: layer sizes, whole numbers >= 1 joined by x, e.g. 64x64")
            return tuple(int(s) for s in sizes)
        return text

    @classmethod
    def help_text(cls, width: int = 120) -> str:
        """Every setting with its type, default and one line (what `--mpc help` prints)."""
        import textwrap

        hints = cls.hints()
        name_w = max(len("setting"), *map(len, hints))
        type_w = max(len("type"), *(len(type_name(h)) for h in hints.values()))
        default_w = max(len("default"), *(len(show(f.default)) for f in fields(cls)))
        indent = 2 + name_w + 2 + type_w + 2 + default_w + 2
        title = f"{cls.flag} NAME=VALUE,...: {(cls.__doc__ or '').strip().splitlines()[0]}"
        lines = [*textwrap.wrap(title, width, subsequent_indent="    "), ""]
        lines.append(f"  {'setting':<{name_w}}  {'type':<{type_w}}  {'default':<{default_w}}  description")
        for f in fields(cls):
            if f.name in cls.SECTIONS:
                lines += ["", cls.SECTIONS[f.name]]
            head = f"  {f.name:<{name_w}}  {type_name(hints[f.name]):<{type_w}}  {show(f.default):<{default_w}}  "
            about = f.metadata.get("help", "")
            wrapped = textwrap.wrap(about, max(width - indent, 40)) or [""]
            lines.append(head + wrapped[0])
            lines += [" " * indent + rest for rest in wrapped[1:]]
        tail = (
            f"e.g. {cls.flag} {cls.example()}. Booleans take true/false, yes/no, on/off or 1/0; `none` unsets a "
            "setting whose type allows it; a name not listed, or a value its type cannot mean, is refused."
        )
        lines += ["", *textwrap.wrap(tail, width)]
        return "\n".join(lines)

    @classmethod
    def example(cls) -> str:
        """Two settings at their defaults, as they are typed."""
        return ",".join(f"{f.name}={show(f.default)}" for f in fields(cls)[:2])


def _number(text: str) -> float | None:
    """A finite float, or None."""
    try:
        number = float(text)
    except ValueError:
        return None
    return number if math.isfinite(number) else None


@dataclass
class TRPOSettings:
    """The paper's TRPO hyperparameters (Section 5.1.4), as sb3-contrib names them."""

    net_arch: tuple[int, ...] = (32, 32)  # tanh MLP
    target_kl: float = 0.01  # max_KL
    cg_max_steps: int = 10  # cg_iters
    cg_damping: float = 0.1
    gamma: float = 0.99
    gae_lambda: float = 0.98  # lam
    n_critic_updates: int = 5  # vf_iters
    learning_rate: float = 1e-3  # vf_stepsize
    critic_batch_size: int = 64  # OpenAI Baselines' value-function minibatch
    # The Gaussian policy's initial log standard deviation (SB3's default, 0, is the paper's too). A residual
    # policy starts from a working controller, where noise of one action unit would unsettle it.
    log_std_init: float = 0.0
    # > 0: gSDE (state-dependent exploration) with a noise matrix held this many steps per worker, so an offset
    # lasts long enough for the building to respond (96: a day of the data center); 0: independent noise per step.
    sde_sample_freq: int = 0


@dataclass
class PPOSettings:
    """Stable-Baselines3's PPO for comparison runs; network, gamma and GAE lambda come from TRPOSettings."""

    learning_rate: float = 3e-4
    n_epochs: int = 10
    batch_size: int = 256  # minibatch
    clip_range: float = 0.2


@dataclass
class SACSettings(FromText):
    """Stable-Baselines3's SAC (off-policy): `train --algorithm sac`, and SAC inside `--algorithm mbpo`.

    64x64 ReLU (SB3's activation for SAC): the problem is small (6-10 observations, 4 actions), and on 2 shared
    cores the gradient steps, not the network's capacity, bound wall time; 256x256 (SB3's default) costs ~10x
    per step. One gradient step per vector step (0.5 per env step with 2 workers) keeps 1M env steps at a few
    hours. The replay buffer holds the whole 1M-step budget (~80 MB).
    """

    flag: ClassVar[str] = "--sac"

    net_arch: tuple[int, ...] = setting((64, 64), "hidden layer sizes of the actor and of each critic (ReLU)")
    learning_rate: float = setting(3e-4, "Adam's learning rate for the actor, the critics and the entropy coefficient")
    buffer_size: int = setting(1_000_000, "transitions the replay buffer holds (the oldest go first)")
    # A week of every worker's weather: random actions, or after --init-from-baseline the cloned actor's own.
    learning_starts: int = setting(
        10_000, "env steps before the first update: random actions, or the cloned actor's with --init-from-baseline"
    )
    batch_size: int = setting(256, "transitions per gradient step (train's --batch-size is not used)")
    tau: float = setting(0.005, "soft update rate of the target critics")
    gamma: float = setting(0.99, "discount factor (default: train's --gamma)")
    train_freq: int = setting(1, "vector steps (one step of every worker) between updates")
    gradient_steps: int = setting(1, "gradient steps per update")
    ent_coef: str = setting("auto", "entropy coefficient: auto (learned), auto_0.1 (learned, starting at 0.1) or a "
                            "fixed number, e.g. 0.05")  # fmt: skip

    def __post_init__(self):
        super().__post_init__()
        value = _number(str(self.ent_coef).removeprefix("auto_"))
        if self.ent_coef != "auto" and (value is None or value <= 0):
            raise ValueError(f"ent_coef {self.ent_coef!r}: auto, auto_<start> (e.g. auto_0.1) or a number > 0")


@dataclass
class ComfortConstraint:
    """`--comfort-target` and how the multiplier follows it (learning/lagrangian.py)."""

    target_pct: float | None = None  # None: the reward's fixed comfort weights (the paper's reproduction)
    margin_c: float = 0.5  # the cost rises over this far inside the band's edges
    multiplier_init: float = 10.0  # energy costs ~1 per step in every built-in spec (power_weight × energy)
    rate: float = 0.3  # log-multiplier step per e-fold of measured over allowed samples out of band
    floor_pct: float = 0.05  # added to both shares out of band: a batch with none out lowers it, finitely
    multiplier_min: float = 0.1
    multiplier_max: float = 100.0  # there, 1 % of samples out of band costs about what all the energy does

    def check(self) -> None:
        if self.target_pct is not None and not 0.0 < self.target_pct < 100.0:
            raise ValueError(
                f"--comfort-target is a share of samples in band, in percent below 100: got {self.target_pct}"
            )
        if self.margin_c <= 0 or self.rate <= 0 or self.floor_pct <= 0:
            raise ValueError("the comfort constraint's margin, rate and floor must be > 0")
        if not 0 < self.multiplier_min <= self.multiplier_init <= self.multiplier_max:
            raise ValueError("the comfort multiplier must start within [multiplier_min, multiplier_max], both > 0")


@dataclass
class ImitationSettings:
    """How the policy is fitted to the recorded controls."""

    epochs: int = 10  # over the record and its re-drawn copies: 40 passes over the record itself
    learning_rate: float = 1e-3
    batch_size: int = 256
    # The cloned Gaussian's log standard deviation (on-policy; SAC's log-std head starts flat at it, before its
    # tanh): exploration around the built-in behaviour.
    # -2.0 is 0.135 of each action's half range (the data center's setpoint: ±2 K; its fans: ±0.35 kg/s).
    log_std: float = -2.0
    run_days: int | None = None  # days recorded per training weather; None: the run's episode length
    # Copies of the recorded steps with the spec's comfort temperatures re-drawn across the band ± `redraw_c`
    # (learning/imitation.py): the controls hold them still, so the clone must not learn to act on them.
    redraw_copies: int = 3
    redraw_c: float = 5.0
