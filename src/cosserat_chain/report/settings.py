"""What the report computes: its settings, the chain it reproduces and the loads placed above M_c.

Contract
--------
:class:`ReproduceSettings` holds every choice of the report, with the paper's values as
defaults; :func:`settings_from_mapping` builds it from a ``[reproduce]`` TOML table, strict on
keys, types and ranges. :func:`chain_for_reading` resolves the chain from the two readings of
Section 4's "seven particles" (:data:`READINGS`), and :func:`above_critical` replaces a load that
must make a model rotate but is not above its computed M_c.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any, get_type_hints

from ..models import get_model
from ..params import BOND_FACTORS, PARTICLE_FACTORS, ChainParams
from ..state import require_clamped

#: The paper's three models, named on purpose: the report reproduces the paper's
#: content, not whatever else is registered (the CLI's ``--model all`` does that).
MODELS = ("nonlinear", "sine", "linear")
#: Those of them that support full rotations (Fig. 3, the localization run).
ROTATING = tuple(name for name in MODELS if get_model(name).rotates)


@dataclass(frozen=True)
class ReproduceSettings:
    """What the report computes; the defaults reproduce the paper (Section 4).

    Attributes
    ----------
    m_max, dm : float
        Relaxation protocol of Fig. 2: loads dm, 2 dm, ..., m_max, then back down. The
        top is raised to :data:`ABOVE_CRITICAL` times the largest computed M_c when
        ``m_max`` does not reach past it (a chain stiffer than the paper's).
    rotation_moment : dict
        Moment per rotating model for Fig. 3 and the localization run (the paper's:
        0.25 and 0.3). One that is not above the model's computed M_c is replaced by
        :data:`ABOVE_CRITICAL` M_c, and the report says so.
    snapshot_times : tuple of float
        Times of the panels of Figs. 3a and 3b.
    animation_frames : int
    turns : int
        Full turns of the localization run (the paper: 1500).
    orbit_moment, orbit_down_to : float
        The sine model's rotating orbit is found at ``orbit_moment`` and continued down
        towards ``orbit_down_to`` until it ceases to exist. An ``orbit_moment`` not
        above the sine model's M_c is replaced by :data:`ABOVE_CRITICAL` M_c.
    n_list : tuple of int
        Chain half-lengths N for the continuum comparison.
    long_n_list : tuple of int
        Chain half-lengths N of the critical moment against the chain's length.
    diagram_damping : dict
        Per rotating model, the values of gamma_phi of the state diagram (both edges of
        the hysteresis loop, :func:`~cosserat_chain.experiments.diagram.state_diagram`).
        The nonlinear model's rows cost several times the sine model's (benchmarks/TIMINGS.md), so its
        default is one value; an empty tuple leaves a model out.
    reading : str or None
        Which reading of Section 4's "a finite 1D chain consists of seven particles" sets
        the chain's N (:data:`READINGS`): ``"clamped-ends-among-seven"`` (N = 3, the
        package's default chain) or ``"seven-between-walls"`` (N = 4: seven free particles
        and two clamped ones). None: the chain's own N. The statics stage computes both
        readings whichever is chosen.
    """

    m_max: float = 0.3
    dm: float = 0.01
    rotation_moment: dict[str, float] = field(default_factory=lambda: {"nonlinear": 0.25, "sine": 0.3})
    snapshot_times: tuple[float, ...] = (40.0, 41.0, 42.0, 43.0)
    animation_frames: int = 80
    turns: int = 1500
    orbit_moment: float = 0.22
    orbit_down_to: float = 0.1
    n_list: tuple[int, ...] = (3, 10, 30, 100, 300, 1000)
    long_n_list: tuple[int, ...] = (3, 10, 30, 100, 300)
    diagram_damping: dict[str, tuple[float, ...]] = field(
        default_factory=lambda: {"sine": (0.05, 0.1, 0.15, 0.2, 0.3, 0.5), "nonlinear": (0.2,)}
    )
    reading: str | None = None


#: The two readings of Section 4's "seven particles" and the N of each. The paper's chain has
#: "2N+1 particles with fixed particles at the boundaries": seven with the two clamped ends
#: among them (N = 3), or seven free particles between two clamped ones, the walls (N = 4).
READINGS = {"clamped-ends-among-seven": 3, "seven-between-walls": 4}


def reading_error(reading: object) -> str | None:
    """Why ``reading`` is not one of :data:`READINGS` (naming the field, the value and the allowed ones), or None."""
    if reading is None or reading in READINGS:
        return None
    allowed = ", ".join(f"{name!r} (N = {n})" for name, n in READINGS.items())
    return f"reading must be one of {allowed}, got {reading!r}"


def chain_for_reading(settings: ReproduceSettings, params: ChainParams | None = None) -> ChainParams:
    """The chain the report computes: ``params`` (default the paper's), with the N of ``settings.reading``.

    Raises
    ------
    ValueError
        For an unknown reading, a ``params`` whose N is not the reading's, one whose
        ends are not both clamped, or a graded one (factor fields given).
    """
    error = reading_error(settings.reading)
    if error:
        raise ValueError(error)
    if params is not None:
        # The report reproduces the paper, whose chain and continuum solutions are clamped.
        require_clamped(params, "the paper's reproduction (reproduce)")
        graded = [name for name in (*BOND_FACTORS, *PARTICLE_FACTORS) if getattr(params, name) is not None]
        if graded:
            # Its continua, waves and longer chains (N = 10 ... 10^4) have no graded counterpart.
            raise ValueError(
                f"the paper's reproduction (reproduce) computes the uniform chain, got a graded one: {', '.join(graded)}; "
                "leave the factor fields out, or compute the graded chain with critical, states, simulate, orbit or study"
            )
    if settings.reading is None:
        return params or ChainParams()
    n = READINGS[settings.reading]
    if params is None:
        return ChainParams(N=n)
    if params.N != n:
        raise ValueError(f"the chain's N = {params.N} contradicts reading = {settings.reading!r} (N = {n}); give one of them")
    return params


#: A load the report must place above a model's critical moment but is configured at or
#: below it is replaced by this multiple of the computed M_c.
ABOVE_CRITICAL = 1.25


def settings_from_mapping(mapping: dict[str, Any], source: str = "[reproduce]") -> ReproduceSettings:
    """:class:`ReproduceSettings` from a TOML table, strict on keys and types.

    Raises
    ------
    ValueError
        Naming an unknown key (with the allowed ones), or the key and value of one of the
        wrong type or out of range.
    """
    from pydantic import TypeAdapter, ValidationError

    allowed = [f.name for f in fields(ReproduceSettings)]
    unknown = [key for key in mapping if key not in allowed]
    if unknown:
        raise ValueError(f"unknown key(s) {unknown} in {source}; allowed keys: {', '.join(allowed)}")
    hints = get_type_hints(ReproduceSettings)
    checked, errors = {}, []
    for key, value in mapping.items():
        try:
            if isinstance(value, dict):
                # A table of lists (diagram_damping): TOML arrays are lists, the settings hold tuples.
                value = {k: tuple(v) if isinstance(v, list) else v for k, v in value.items()}
            checked[key] = TypeAdapter(hints[key]).validate_python(tuple(value) if isinstance(value, list) else value, strict=True)
        except ValidationError as err:
            errors += [f"{'.'.join(map(str, (key, *e['loc'])))}: {e['msg']} (got {e.get('input')!r})" for e in err.errors()]
    if errors:
        raise ValueError(f"invalid {source}: " + "; ".join(errors))
    settings = ReproduceSettings(**checked)
    problems = [
        f"{name} must be > 0, got {getattr(settings, name)!r}"
        for name in ("m_max", "dm", "orbit_moment", "turns", "animation_frames")
        if not (math.isfinite(getattr(settings, name)) and getattr(settings, name) > 0)
    ]
    problems += [
        f"rotation_moment.{m} must be a finite number, got {v!r}" for m, v in settings.rotation_moment.items() if not math.isfinite(v)
    ]
    problems += [f"rotation_moment needs {m}" for m in ROTATING if m not in settings.rotation_moment]
    problems += [
        f"{name} must be integers N >= 1" for name in ("n_list", "long_n_list") if not all(n >= 1 for n in getattr(settings, name))
    ]
    problems += [
        f"diagram_damping: unknown model {m!r} (the rotating ones: {', '.join(ROTATING)})"
        for m in settings.diagram_damping
        if m not in ROTATING
    ]
    problems += [
        f"diagram_damping.{m} must hold finite numbers > 0, got {list(v)!r}"
        for m, v in settings.diagram_damping.items()
        if not all(math.isfinite(x) and x > 0 for x in v)
    ]
    problems += [error for error in [reading_error(settings.reading)] if error]
    if problems:
        raise ValueError(f"invalid {source}: " + "; ".join(problems))
    return settings


def above_critical(configured: float, critical: float | None) -> tuple[float, str]:
    """The load to use where a model must rotate, and how it relates to M_c, in words.

    ``configured`` if it is above ``critical`` (or there is no fold), else
    :data:`ABOVE_CRITICAL` ``critical``.
    """
    if critical is None or not math.isfinite(critical):
        return configured, "the model has no static fold"
    if configured > critical:
        return configured, f"{configured / critical:.3g} times its M_c = {critical:.4g}"
    load = ABOVE_CRITICAL * critical
    return load, f"{ABOVE_CRITICAL:g} times its M_c = {critical:.4g}: the configured M = {configured:g} is not above M_c for this chain"
