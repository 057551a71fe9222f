"""The plant's dynamics behind one interface: the `Propagator` protocol and its registry.

A propagator owns the translational state of N craft and advances it with a command held
constant over each step (zero-order hold). Built-in implementations (registered below):

| name       | model                                                   | state frame (`state()`)        | command frame (`step`)         |
|------------|---------------------------------------------------------|--------------------------------|--------------------------------|
| `linear`   | linear Keplerian ROE, exact ZOH (`roe_linear`)          | reference LVLH                 | reference LVLH (= own, linear) |
| `j2`       | ECI two-body + J2 (+ drag) of reference and craft (`absolute_j2`) | reference LVLH (rotating) | each craft's own LVLH    |
| `cw`       | Clohessy-Wiltshire / Hill, exact ZOH (`cw`)             | reference LVLH                 | reference LVLH                 |
| `inertial` | ECI two-body + J2 + drag, per-craft mass/area/C_D (`inertial`) | ECI (J2000-like, Earth-centred) | ECI, or each craft's own LVLH |

LVLH everywhere is frames.py's: x radial, y along-track, z cross-track (orbit normal).
`u_rad` is the reference argument of latitude: mean and unwrapped (u0 + n t) for `linear` and
`cw`; osculating in [0, 2 pi) for `j2` and `inertial` (of the reference craft).

A mission adds a model by decorating a factory (a class or function with typed keyword
arguments) with `@register_propagator("name")`; `make_propagator("name", **kwargs)` builds it,
and rejects an unknown name or keyword with the allowed ones in the message.
"""
from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Protocol, TypeVar, runtime_checkable

import numpy as np

from swarmhil.plant.dynamics import cw, inertial, roe_linear
from swarmhil.plant.dynamics.absolute_j2 import AbsoluteJ2Plant
from swarmhil.plant.dynamics.step_clock import StepClock


@runtime_checkable
class Propagator(Protocol):
    """Translational dynamics of N craft, command held constant over each step."""

    frame: str  # frame of state(): "lvlh" (reference LVLH) or "eci"

    @property
    def t_s(self) -> float:
        """Time since the initial state [s]."""
        ...

    @property
    def u_rad(self) -> float:
        """Reference argument of latitude [rad] (module docstring for mean/osculating)."""
        ...

    def step(self, accel_mps2: np.ndarray | None, dt_s: float) -> None:
        """Advance by dt_s with accel (N, 3) [m/s^2] in the propagator's command frame held over the step
        (None: coast)."""
        ...

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        """Positions (N, 3) [m] and velocities (N, 3) [m/s] in `frame` (copies)."""
        ...


F = TypeVar("F", bound=Callable[..., Propagator])
_REGISTRY: dict[str, Callable[..., Propagator]] = {}


def register_propagator(name: str) -> Callable[[F], F]:
    """Decorator: register a propagator factory under `name` (a second registration of a name is an error)."""

    def deco(factory: F) -> F:
        if name in _REGISTRY and _REGISTRY[name] is not factory:
            raise ValueError(f"propagator {name!r} is already registered ({_REGISTRY[name]!r})")
        _REGISTRY[name] = factory
        return factory

    return deco


def propagator_names() -> tuple[str, ...]:
    return tuple(sorted(_REGISTRY))


def make_propagator(name: str, **kwargs: object) -> Propagator:
    """Build the propagator registered as `name` with its typed keyword arguments (checked here)."""
    if name not in _REGISTRY:
        raise ValueError(f"unknown propagator {name!r}; known: {', '.join(propagator_names())}")
    factory = _REGISTRY[name]
    params = inspect.signature(factory).parameters
    allowed = [p for p, v in params.items() if v.kind in (v.KEYWORD_ONLY, v.POSITIONAL_OR_KEYWORD)]
    unknown = sorted(set(kwargs) - set(allowed))
    if unknown:
        raise ValueError(f"propagator {name!r} takes no argument {', '.join(unknown)}; allowed: {', '.join(allowed)}")
    missing = [p for p in allowed if params[p].default is inspect.Parameter.empty and p not in kwargs]
    if missing:
        raise ValueError(f"propagator {name!r} needs {', '.join(missing)}")
    return factory(**kwargs)


# ------------------------------------------------------------------------------ built-in models


@register_propagator("linear")
class LinearRoePropagator:
    """The linear Keplerian ROE model (roe_linear.propagate_roe), as plant/world.py has always run it:
    u = u0 + n t (unwrapped), t = k dt. `inc_rad`, `raan_rad` do not enter the Keplerian linear model."""

    frame = "lvlh"

    def __init__(self, *, a_m: float, inc_rad: float, raan_rad: float, u0_rad: float, roe_m: np.ndarray) -> None:
        self.a_m = float(a_m)
        self.inc_rad = float(inc_rad)
        self.raan_rad = float(raan_rad)
        self.n_radps = roe_linear.mean_motion(self.a_m)
        self.u0_rad = float(u0_rad)
        roe = np.array(roe_m, dtype=float, ndmin=2)
        if roe.ndim != 2 or roe.shape[1] != 6:
            raise ValueError(f"roe_m must be (N, 6), got shape {roe.shape}")
        self._roe = roe
        self._clock = StepClock()

    @property
    def t_s(self) -> float:
        return self._clock.t_s

    @property
    def u_rad(self) -> float:
        return self.u0_rad + self.n_radps * self.t_s

    def step(self, accel_mps2: np.ndarray | None, dt_s: float) -> None:
        accel = np.zeros((len(self._roe), 3)) if accel_mps2 is None else np.asarray(accel_mps2, dtype=float)
        if accel.shape != (len(self._roe), 3):
            raise ValueError(f"accel_mps2 must be ({len(self._roe)}, 3), got {accel.shape}")
        self._roe = roe_linear.propagate_roe(self._roe, accel, self.u_rad, self.n_radps, dt_s)
        self._clock.advance(dt_s)

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        return roe_linear.roe_to_lvlh(self._roe, self.u_rad, self.n_radps)

    def roe_m(self) -> np.ndarray:
        """(N, 6) ROE in metres (the model's own state)."""
        return self._roe.copy()


@register_propagator("j2")
class AbsoluteJ2Propagator:
    """absolute_j2.AbsoluteJ2Plant behind the protocol (same numbers): state in the reference's
    rotating LVLH; commands in each craft's own LVLH; u_rad osculating, in [0, 2 pi)."""

    frame = "lvlh"

    def __init__(
        self, *, a_m: float, inc_rad: float, raan_rad: float, u0_rad: float, roe_m: np.ndarray,
        drag: dict | None = None, j2: bool = True, max_step_s: float = 30.0,
    ) -> None:
        self.plant = AbsoluteJ2Plant(a_m, inc_rad, raan_rad, u0_rad, np.asarray(roe_m, float), j2=j2, drag=drag,
                                     max_step_s=max_step_s)
        self._clock = StepClock()

    @property
    def t_s(self) -> float:
        return self._clock.t_s

    @property
    def u_rad(self) -> float:
        return float(self.plant.reference_u())

    def step(self, accel_mps2: np.ndarray | None, dt_s: float) -> None:
        self.plant.step(accel_mps2, dt_s)
        self._clock.advance(dt_s)

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        return self.plant.relative_lvlh()


@register_propagator("cw")
def make_cw(
    *, a_m: float, u0_rad: float = 0.0, roe_m: np.ndarray | None = None, pos_m: np.ndarray | None = None,
    vel_mps: np.ndarray | None = None, inc_rad: float | None = None, raan_rad: float | None = None,
) -> cw.CwPropagator:
    """HCW about the circular reference of radius a_m; initial state as LVLH `pos_m`/`vel_mps` or as `roe_m`
    (mapped by the linear ROE -> LVLH map at u0, exact for HCW). inc/raan do not enter HCW."""
    del inc_rad, raan_rad
    if (roe_m is None) == (pos_m is None and vel_mps is None):
        raise ValueError("cw needs either roe_m or pos_m and vel_mps")
    if roe_m is not None:
        pos_m, vel_mps = roe_linear.roe_to_lvlh(np.array(roe_m, float, ndmin=2), u0_rad, cw.mean_motion(a_m))
    return cw.CwPropagator(a_m, pos_m, vel_mps, u0_rad=u0_rad)


register_propagator("inertial")(inertial.InertialPropagator)
