"""Each algorithm's settings and the learners' own knobs: plain data classes (a run saves them in its config.json)."""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import ClassVar


class FromText:
    """`--sac`/`--mpc`/`--mbpo "name=value,..."`: a dataclass's fields by name, each converted to its default's
    type (a tuple of layer sizes as `64x64`)."""

    flag: ClassVar[str]

    def __post_init__(self):
        pass

    @classmethod
    def from_text(cls, text: str | None, base=None):
        """Fields named in `text` over `base` (default: the defaults)."""
        settings = replace(base) if base is not None else cls()
        for item in filter(None, (p.strip() for p in (text or "").split(","))):
            key, sep, value = item.partition("=")
            key = key.strip().replace("-", "_")
            if not sep or not hasattr(settings, key):
                names = ", ".join(f.name for f in fields(cls))
                raise ValueError(f"{cls.flag} {item!r}: expected NAME=VALUE with NAME one of {names}")
            default = getattr(cls, key)
            if value.strip().lower() == "none":  # an optional setting left unset (`rail_k=none`)
                if "None" not in str(next(f.type for f in fields(cls) if f.name == key)):
                    raise ValueError(f"{cls.flag} {item!r}: {key} takes a value, not none")
                parsed = None
            elif isinstance(default, bool):
                parsed = value.strip().lower() in ("1", "true", "yes", "on")
            elif default is None:
                parsed = float(value)
            elif isinstance(default, tuple):
                parsed = tuple(int(v) for v in value.lower().split("x"))
            else:
                parsed = type(default)(float(value)) if isinstance(default, int) else type(default)(value)
            setattr(settings, key, parsed)
        settings.__post_init__()
        return settings


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
    """Stable-Baselines3's SAC (off-policy) for comparison runs.

    64x64 ReLU (SB3's activation for SAC): the problem is small (6-10 observations, 4 actions), and on 2 shared
    cores the gradient steps, not the network's capacity, bound wall time; 256x256 (SB3's default) costs ~10x
    per step. One gradient step per vector step (0.5 per env step with 2 workers) keeps 1M env steps at a few
    hours. The replay buffer holds the whole 1M-step budget (~80 MB).
    """

    flag: ClassVar[str] = "--sac"

    net_arch: tuple[int, ...] = (64, 64)
    learning_rate: float = 3e-4
    buffer_size: int = 1_000_000
    learning_starts: int = 10_000  # env steps before the first update (a week of every worker's weather): random
    # actions, or after --init-from-baseline the cloned actor's own
    batch_size: int = 256
    tau: float = 0.005
    gamma: float = 0.99
    train_freq: int = 1  # vector steps between updates
    gradient_steps: int = 1
    ent_coef: str = "auto"


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
