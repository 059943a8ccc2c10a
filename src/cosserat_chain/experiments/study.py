"""Parameter studies: a validated spec, its grid of independent cells, and the computation of one cell.

Contract
--------
A :class:`StudySpec` (usually read from TOML) lists, per swept ``ChainParams``
field, a list of values or a linear/log range; the fixed fields; the models; the
quantities to compute; the loads for ``mean_angular_velocity``; and the settings
of the relaxation protocol; and the extra loads that act on every cell besides the
moment (``[[loads]]`` tables, :func:`~cosserat_chain.loads.load_from_table`: they share the
key ``loads`` with the moments of ``mean_angular_velocity``, a number being a moment and a
table a load). :meth:`StudySpec.check` reports unknown keys and
impossible parameter combinations (e.g. overlapping particles), naming the
offending entries, before anything runs; :meth:`StudySpec.check_memory` refuses, on the
machine that will run the cells, a chain too long for the memory its quantities' own
estimates ask for.

Every cell of the grid (one value per swept field, one model) is independent.
:func:`compute_cells` computes a chunk of cells that share N and the model: the
relaxation quantities of all of them in one batch of the dynamics engine
(:func:`~cosserat_chain.experiments.sweep.relaxation_sweeps`,
:func:`~cosserat_chain.numerics.relaxation.relax_batch`), the static ones cell by
cell. Each cell's values equal those of the chunk of that cell alone
(:func:`compute_cell`): a batch member's states equal its single run's bits. It never
raises; a failure is returned as the cell's error message, and the other cells go on.
:func:`empty_results` and :func:`store_cell` build the result Dataset, whose
dimensions are the swept fields (in spec order), ``model`` and, if asked for, ``load``.

Time step
---------
A batch shares one compiled loop only among members that take the same step, and each
cell's default step (0.1 / omega_max) is its own. Without ``sweep.dt``, a cell therefore
relaxes at its default step rounded down to a power of 2^(1/8) (:func:`cell_time_step`;
less than 9 % smaller): cells of similar stiffness then share a loop, and the step is a
function of the cell alone, so that its values depend neither on the chunk it ran in
nor on what an earlier, interrupted run had finished.

Quantities
----------
``M_c``, ``phi0_at_fold``
    The fold of the static branch (:func:`~cosserat_chain.numerics.continuation.locate_fold`); NaN without one.
``compliance``
    d phi_0 / dM at rest.
``onset_load``, ``stop_load``
    The relaxation protocol up to ``sweep.m_max`` in steps of ``sweep.dm`` (and down again
    for ``stop_load``); NaN if rotation never starts (or never stops).
``mean_angular_velocity``
    Per load of ``loads``: the mean angular velocity of the loaded particle after relaxing
    from rest at that load (0 if it comes to rest, NaN if neither at rest nor steady by
    ``sweep.t_max``).
``band_gap``
    Width of the gap between the transverse-acoustic and rotational-optical bands of the
    infinite linear chain (0 if they overlap); the same for every model.

Extra loads
-----------
Constant loads (``[[loads]]`` tables without ``kind``, or of a constant kind) act
throughout, besides the stepped or held moment, in every relaxation of the relaxation
quantities (``loads=`` of :func:`~cosserat_chain.experiments.sweep.relaxation_sweeps` and
:func:`~cosserat_chain.numerics.relaxation.relax_batch`). The static quantities (``M_c``,
``phi0_at_fold``, ``compliance``) follow the branch under the moment alone, so a spec with
extra loads and any of them is refused, naming them; ``band_gap`` is a property of the
infinite unloaded chain, which the loads do not enter. A load that changes in time is
refused (no static state holds under it), and so is one on a degree of freedom a cell's
ends hold fixed. The loads are in the spec's JSON (which the Dask workers receive) and in
the results' ``loads_json`` attribute.
"""

from __future__ import annotations

import inspect
import itertools
import json
import logging
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_serializer, model_validator

from ..analysis.dispersion import wave_summary
from ..loads import Loads, load_from_table, loads_from_tables, moment_load
from ..memory import FLOAT, MemoryEstimateError, require
from ..models.base import available_models
from ..numerics.continuation import compliance, continue_in_moment, locate_fold, require_branch_memory
from ..numerics.engine import require_batch_memory
from ..numerics.integrators import MAX_SPIN_PER_STEP, default_time_step, spin_hint
from ..numerics.relaxation import relax_batch
from ..params import ChainParams
from ..state import MIN_STATES
from .sweep import relaxation_sweeps

if TYPE_CHECKING:  # xarray is imported where a Dataset is built or read: commands without file output start without it
    import xarray as xr

log = logging.getLogger(__name__)

QUANTITIES = ("M_c", "phi0_at_fold", "compliance", "onset_load", "stop_load", "mean_angular_velocity", "band_gap")
Quantity = Literal["M_c", "phi0_at_fold", "compliance", "onset_load", "stop_load", "mean_angular_velocity", "band_gap"]
#: The quantities computed by relaxing the dynamics (batched over a chunk of cells).
RELAXATION_QUANTITIES = ("onset_load", "stop_load", "mean_angular_velocity")
#: The quantities of the static branch under the moment alone: they take no extra loads.
STATIC_QUANTITIES = ("M_c", "phi0_at_fold", "compliance")
#: Default time steps are rounded down to a power of 2 ** (1 / STEPS_PER_OCTAVE) (see the module docstring).
STEPS_PER_OCTAVE = 8
#: How a cell's time step is chosen; stored in the results, so that a file written under another rule is not resumed.
TIME_STEP_RULE = f"sweep.dt, else 0.1 / omega_max rounded down to a power of 2^(1/{STEPS_PER_OCTAVE})"


class Range(BaseModel):
    """``num`` values from ``start`` to ``stop`` (both included), evenly spaced on a linear or log scale."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)
    start: float
    stop: float
    num: int = Field(ge=1)
    scale: Literal["linear", "log"] = "linear"

    @model_validator(mode="after")
    def _positive_for_log(self) -> Range:
        if self.scale == "log" and not (self.start > 0 and self.stop > 0):
            raise ValueError(f"a log range needs start > 0 and stop > 0, got start={self.start}, stop={self.stop}")
        return self

    def values(self) -> list[float]:
        space = np.geomspace if self.scale == "log" else np.linspace
        return [float(v) for v in space(self.start, self.stop, self.num)]


class SweepSettings(BaseModel):
    """Relaxation-protocol settings for ``onset_load``, ``stop_load`` and ``mean_angular_velocity``."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)
    m_max: float = Field(0.4, gt=0)
    dm: float = Field(0.01, gt=0)
    t_max: float = Field(20000.0, gt=0)
    dt: float | None = Field(None, gt=0)


class StudySpec(BaseModel):
    """A parameter study (see the module docstring); unknown keys are errors.

    Strict on types: numbers must be numbers (not strings or booleans) and finite, and
    the values of N integers.
    """

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)
    parameters: dict[str, list[float] | Range]
    fixed: dict[str, float] = {}
    models: list[str] = ["nonlinear", "sine"]
    quantities: list[Quantity]
    loads: list[float] = []
    #: The ``[[loads]]`` tables among ``loads`` (extra loads on every cell); serialized back into ``loads``.
    extra_loads: list[dict[str, Any]] = []
    sweep: SweepSettings = SweepSettings()
    particle: int = 0

    @model_validator(mode="before")
    @classmethod
    def _split_loads(cls, data: Any) -> Any:
        """Numbers of ``loads`` are moments of mean_angular_velocity, its tables constant extra loads."""
        if not isinstance(data, dict):
            return data
        if "extra_loads" in data:
            raise ValueError("unknown key extra_loads: give the loads acting on every cell as tables in loads ([[loads]] in TOML)")
        entries = data.get("loads")
        if not isinstance(entries, list) or not any(isinstance(entry, dict) for entry in entries):
            return data
        for i, entry in enumerate(entries):
            if isinstance(entry, dict):
                load = load_from_table(entry, f"loads[{i}]")
                if not load.schedule.is_constant:
                    raise ValueError(
                        f"loads[{i}] (kind {entry.get('kind')!r}) changes in time: the loads of a study act on its "
                        "relaxations, which need constant loads (no static state holds under a load that changes)"
                    )
        return {
            **data,
            "loads": [entry for entry in entries if not isinstance(entry, dict)],
            "extra_loads": [entry for entry in entries if isinstance(entry, dict)],
        }

    @model_serializer(mode="wrap")
    def _merge_loads(self, handler) -> dict[str, Any]:
        # One key, as in the TOML: moments first, then the tables. Without tables the dump is that of
        # a spec from before extra loads existed, so that its files still resume.
        data = handler(self)
        tables = data.pop("extra_loads", [])
        if tables:
            data["loads"] = [*data["loads"], *tables]
        return data

    @field_validator("parameters", "fixed")
    @classmethod
    def _known_fields(cls, value: dict[str, Any], info) -> dict[str, Any]:
        allowed = [name for name in ChainParams.model_fields]
        unknown = [key for key in value if key not in allowed]
        if unknown:
            raise ValueError(f"unknown parameter(s) {unknown}; allowed: {', '.join(allowed)}")
        return value

    @field_validator("models")
    @classmethod
    def _known_models(cls, value: list[str]) -> list[str]:
        unknown = [m for m in value if m not in available_models()]
        if unknown or not value:
            raise ValueError(f"unknown model(s) {unknown}; allowed: {', '.join(available_models())}")
        return value

    @model_validator(mode="after")
    def _consistent(self) -> StudySpec:
        if not self.parameters:
            raise ValueError("parameters: give at least one swept field")
        overlap = sorted(set(self.parameters) & set(self.fixed))
        if overlap:
            raise ValueError(f"{overlap} both swept (parameters) and fixed")
        for name, values in self.parameters.items():
            if isinstance(values, list) and not values:
                raise ValueError(f"parameters.{name}: empty list")
        chain_lengths = self.parameters.get("N", [self.fixed["N"]] if "N" in self.fixed else [])
        fractions = [
            v for v in (chain_lengths.values() if isinstance(chain_lengths, Range) else chain_lengths) if not float(v).is_integer()
        ]
        if fractions:
            raise ValueError(f"N must take integer values (particles -N..N), got {fractions}")
        if "mean_angular_velocity" in self.quantities and not self.loads:
            raise ValueError("quantity mean_angular_velocity needs loads = [M1, M2, ...]")
        if not self.quantities:
            raise ValueError(f"quantities: give at least one of {', '.join(QUANTITIES)}")
        static = [name for name in self.quantities if name in STATIC_QUANTITIES]
        if self.extra_loads and static:
            raise ValueError(
                f"quantit{'y' if len(static) == 1 else 'ies'} {', '.join(static)} take{'s' if len(static) == 1 else ''} "
                "no extra loads: the static branch is followed under the moment alone; leave "
                f"{'it' if len(static) == 1 else 'them'} out of quantities, or the load tables out of loads "
                "(extra loads act on onset_load, stop_load and mean_angular_velocity)"
            )
        return self

    def extra(self) -> Loads:
        """The extra loads acting on every cell (the tables of ``loads``)."""
        return loads_from_tables(self.extra_loads)

    def axes(self) -> dict[str, list]:
        """Swept field -> its values (N as integers)."""
        out = {}
        for name, values in self.parameters.items():
            vals = values.values() if isinstance(values, Range) else [float(v) for v in values]
            out[name] = [int(round(v)) for v in vals] if name == "N" else vals
        return out

    def cells(self) -> list[tuple[tuple[int, ...], str, dict[str, float]]]:
        """Every cell: (index along each swept field, model, ChainParams fields)."""
        axes = self.axes()
        names = list(axes)
        cells = []
        for index in itertools.product(*(range(len(v)) for v in axes.values())):
            fields = {**self.fixed, **{name: axes[name][i] for name, i in zip(names, index)}}
            if "N" in fields:
                fields["N"] = int(fields["N"])
            cells.extend((index, model, fields) for model in self.models)
        return cells

    def check(self) -> None:
        """Build every cell's parameters; raise one ValueError listing every impossible combination."""
        problems = []
        seen = set()
        extra = self.extra()
        for index, _, fields in self.cells():
            if index in seen:
                continue
            seen.add(index)
            try:
                params = ChainParams(**fields)
                if self.particle and not -params.N < self.particle < params.N:
                    raise ValueError(f"particle={self.particle} is not a free particle of a chain with N={params.N}")
                extra.validate(params)
                self._check_spin(params, extra)
            except (ValidationError, ValueError) as err:
                swept = ", ".join(f"{k}={fields[k]}" for k in self.parameters)
                reason = "; ".join(e["msg"] for e in err.errors()) if isinstance(err, ValidationError) else str(err)
                problems.append(f"cell {swept}: {reason}")
        if problems:
            shown = "\n  ".join(problems[:10])
            more = f"\n  ... and {len(problems) - 10} more" if len(problems) > 10 else ""
            raise ValueError(f"{len(problems)} impossible parameter combination(s):\n  {shown}{more}")

    def check_memory(self) -> None:
        """Refuse a study whose longest chain does not fit in this machine's free memory, before any cell runs.

        Each quantity's own estimate, the one its computation checks first (a cell would
        otherwise fail with it, one by one): the branch from rest of ``M_c`` and ``phi0_at_fold``
        (:func:`~cosserat_chain.numerics.continuation.require_branch_memory`, at
        :func:`~cosserat_chain.numerics.continuation.continue_in_moment`'s default points), the
        states of ``compliance`` (:data:`~cosserat_chain.state.MIN_STATES`) and one member of the
        relaxations' batch (:func:`~cosserat_chain.numerics.engine.require_batch_memory`).
        The memory is that of the machine this runs on: the CLI checks an embedded cluster's.

        Raises
        ------
        ValueError
            Naming N's entry, its value, and the memory needed against the memory free.
        """
        wanted = set(self.quantities)
        longest = max((fields for _, _, fields in self.cells()), key=lambda fields: fields.get("N", ChainParams().N))
        params = ChainParams(**longest)
        entry = "parameters.N" if "N" in self.parameters else "fixed.N" if "N" in self.fixed else "N (the default)"
        try:
            if wanted & {"M_c", "phi0_at_fold"}:
                require_branch_memory(params, inspect.signature(continue_in_moment).parameters["max_points"].default)
            if "compliance" in wanted:
                n = params.n_particles
                require(MIN_STATES * FLOAT * 3 * n, f"{MIN_STATES} states of {n} particles (N={params.N})", "a shorter chain")
            if wanted & set(RELAXATION_QUANTITIES):
                require_batch_memory([params])
        except MemoryEstimateError as err:
            raise ValueError(f"{entry} = {params.N}: every cell of this chain would fail: {err}") from None

    def _check_spin(self, params: ChainParams, extra: Loads) -> None:
        """Refuse a cell whose largest load spins its particle faster than its relaxations' step follows.

        The moment M drives its particle to the spin M / gamma_phi
        (:func:`~cosserat_chain.numerics.integrators.spin_hint`): beyond what the step resolves, a
        relaxation would run to ``t_max`` without an answer, so the cell is refused before anything runs.
        """
        # The sweeps of onset_load and stop_load stop at the onset, below any such spin: only the loads.
        moments = [abs(m) for m in self.loads] if "mean_angular_velocity" in self.quantities else []
        if not moments or params.gamma_phi == 0.0:  # undamped rotation: no terminal spin to bound
            return
        loads = Loads([*extra, *moment_load(max(moments), self.particle)])
        spin = max(load.schedule.bound() for load in loads if load.row == "phi") / params.gamma_phi
        # The default step (0.1 / omega_max, several banded factorisations) is computed only where it
        # matters: a spin below MAX_SPIN_PER_STEP per unit time is followed by any step up to 1.
        if self.sweep.dt is None and spin < MAX_SPIN_PER_STEP:
            return
        for model in self.models:
            hint = spin_hint(params, loads, cell_time_step(params, model, self))
            if hint:
                raise ValueError(f"{model}: {hint} (loads are the moments of mean_angular_velocity; sweep.dt sets the step)")

    def to_json(self) -> str:
        return json.dumps(self.model_dump(mode="json"), sort_keys=True)


def spec_from_mapping(mapping: dict[str, Any], source: str = "study spec") -> StudySpec:
    """A checked :class:`StudySpec`; every problem is reported as one ValueError naming the entries."""
    try:
        spec = StudySpec(**mapping)
    except ValidationError as err:
        lines = [f"  {'.'.join(map(str, e['loc'])) or 'spec'}: {e['msg']}" for e in err.errors()]
        raise ValueError(f"invalid {source}:\n" + "\n".join(lines)) from None
    spec.check()
    return spec


def cell_time_step(params: ChainParams, model: str, spec: StudySpec) -> float:
    """The time step of a cell's relaxations: ``sweep.dt``, else the default step rounded down to a power of 2^(1/8).

    Rounding down keeps the step below the stability limit and less than 9 % below the
    default (0.1 / omega_max, about 60 steps per period of the fastest linear mode).
    """
    if spec.sweep.dt is not None:
        return spec.sweep.dt
    exponent = math.floor(STEPS_PER_OCTAVE * math.log2(default_time_step(params, model)))
    return 2.0 ** (exponent / STEPS_PER_OCTAVE)


def compute_cell(fields: dict[str, float], model: str, spec_json: str) -> dict[str, Any]:
    """The quantities of one cell (:func:`compute_cells` of one); never raises."""
    return compute_cells([fields], model, spec_json)[0]


def compute_cells(cells: Sequence[dict[str, float]], model: str, spec_json: str) -> list[dict[str, Any]]:
    """The quantities of a chunk of cells that share N and the model; never raises.

    A plain, importable function of plain arguments, so that Dask can ship it to any worker.

    Parameters
    ----------
    cells : sequence of dict
        Each cell's ``ChainParams`` fields (all with the same N).
    model : str
    spec_json : str
        :meth:`StudySpec.to_json` of the study.

    Returns
    -------
    list of dict
        Per cell, quantity -> value, or ``{"error": message}`` if it failed. The
        relaxation quantities of all cells run as one batch; if that batch raises (one
        member's step beyond its stability limit, one member blowing up), its cells are
        computed one by one, so that only the failing cell records an error. Ctrl-C
        (``KeyboardInterrupt``) is not caught.
    """
    spec = StudySpec(**json.loads(spec_json))  # the extra loads come with it, as tables of loads
    results: list[dict[str, Any]] = []
    live: list[tuple[int, ChainParams]] = []
    for i, fields in enumerate(cells):
        try:
            params = ChainParams(**fields)
            results.append(_static_quantities(params, model, spec))
            live.append((i, params))
        except Exception as err:  # a failed cell must not stop the study: record why
            results.append(_failure(err))
    if live and set(spec.quantities) & set(RELAXATION_QUANTITIES):
        relaxed = _relaxation_quantities_or_errors([params for _, params in live], model, spec)
        for (i, _), values in zip(live, relaxed):
            results[i] = values if "error" in values else {**results[i], **values}
    return results


def _failure(err: Exception) -> dict[str, str]:
    return {"error": f"{type(err).__name__}: {err}"}


def _static_quantities(params: ChainParams, model: str, spec: StudySpec) -> dict[str, Any]:
    wanted = set(spec.quantities)
    out: dict[str, Any] = {}
    if wanted & {"M_c", "phi0_at_fold"}:
        fold = locate_fold(params, model, particle=spec.particle)
        out["M_c"] = math.nan if fold is None else fold.moment
        out["phi0_at_fold"] = math.nan if fold is None else fold.phi0
    if "compliance" in wanted:
        out["compliance"] = compliance(params, model, particle=spec.particle)
    if "band_gap" in wanted:
        gap = wave_summary(params).gap
        out["band_gap"] = 0.0 if gap is None else gap[1] - gap[0]
    return {name: value for name, value in out.items() if name in wanted}


def _relaxation_quantities_or_errors(params_list: list[ChainParams], model: str, spec: StudySpec) -> list[dict[str, Any]]:
    """:func:`_relaxation_quantities`, or, if the batch raises, each member alone (a lone member's error recorded)."""
    try:
        return _relaxation_quantities(params_list, model, spec)
    except Exception as err:  # a failed cell must not stop the study: record why
        if len(params_list) == 1:
            return [_failure(err)]
        log.info("a batch of %d cells failed (%s); computing them one by one", len(params_list), err)
    return [_relaxation_quantities_or_errors([params], model, spec)[0] for params in params_list]


def _relaxation_quantities(params_list: list[ChainParams], model: str, spec: StudySpec) -> list[dict[str, Any]]:
    """The relaxation quantities of every member, all members in one batch per quantity."""
    wanted = set(spec.quantities)
    extra = spec.extra()
    steps = [cell_time_step(params, model, spec) for params in params_list]
    out: list[dict[str, Any]] = [{} for _ in params_list]
    if wanted & {"onset_load", "stop_load"}:
        sweeps = relaxation_sweeps(
            params_list, model, m_max=spec.sweep.m_max, dm=spec.sweep.dm, down="stop_load" in wanted, stop_at_onset=True,
            particle=spec.particle, t_max=spec.sweep.t_max, dt=steps, loads=extra,
        )  # fmt: skip
        if not all(sweep.completed for sweep in sweeps):
            # relaxation_sweeps returns the steps finished before Ctrl-C; a cell must not record a partial sweep.
            raise KeyboardInterrupt
        for values, sweep in zip(out, sweeps):
            values["onset_load"] = math.nan if sweep.onset_load is None else sweep.onset_load
            values["stop_load"] = math.nan if sweep.stop_load is None else sweep.stop_load
    if "mean_angular_velocity" in wanted:
        count = len(spec.loads)
        members = [params for params in params_list for _ in spec.loads]
        ends = relax_batch(
            members, model, [load for _ in params_list for load in spec.loads], particle=spec.particle, t_max=spec.sweep.t_max,
            dt=[step for step in steps for _ in spec.loads], loads=extra,
        )  # fmt: skip
        for i, (values, params) in enumerate(zip(out, params_list)):
            values["mean_angular_velocity"] = [
                float(end.angular_velocity[params.N + spec.particle]) for end in ends[i * count : (i + 1) * count]
            ]
    return [{name: value for name, value in values.items() if name in wanted} for values in out]


def empty_results(spec: StudySpec) -> xr.Dataset:
    """The result Dataset before any cell ran: every quantity NaN, ``done`` 0, ``error`` empty."""
    import xarray as xr

    axes = spec.axes()
    dims = [*axes, "model"]
    shape = [len(v) for v in axes.values()] + [len(spec.models)]
    coords: dict[str, Any] = {**axes, "model": spec.models}
    data: dict[str, Any] = {}
    for name in spec.quantities:
        if name == "mean_angular_velocity":
            coords["load"] = spec.loads
            data[name] = ([*dims, "load"], np.full([*shape, len(spec.loads)], np.nan))
        else:
            data[name] = (dims, np.full(shape, np.nan))
    data["done"] = (dims, np.zeros(shape, dtype=np.int8))
    data["error"] = (dims, np.full(shape, "", dtype=object))
    ds = xr.Dataset(data, coords=coords)
    ds["done"].attrs["long_name"] = "1 once the cell was computed (successfully or not)"
    ds["error"].attrs["long_name"] = "error message of a failed cell (empty if it succeeded)"
    ds.attrs["study_spec_json"] = spec.to_json()
    # The extra loads on every cell, as every run stores its loads (Loads.to_list); also in study_spec_json.
    ds.attrs["loads_json"] = json.dumps(spec.extra().to_list())
    ds.attrs["time_step_rule"] = TIME_STEP_RULE
    ds.attrs["experiment"] = "parameter_study"
    return ds


def store_cell(ds: xr.Dataset, spec: StudySpec, index: tuple[int, ...], model: str, values: dict[str, Any]) -> None:
    """Write one cell's values (or error) into ``ds`` in place."""
    where = {**{name: i for name, i in zip(spec.axes(), index)}, "model": spec.models.index(model)}
    if "error" in values:
        ds["error"][where] = values["error"]
    else:
        for name, value in values.items():
            ds[name][where] = value
    ds["done"][where] = 1
