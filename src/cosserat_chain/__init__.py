"""cosserat-chain: discrete Cosserat chains of finite-size particles that translate and rotate.

The package implements the three models of the paper (nonlinear springs, sine-Cosserat
eq. (2), linear Cosserat eq. (3)) with geometry-derived coefficients, compiled damped
dynamics under moment loads, and self-describing results.

The names below are the public API, importable from the top level
(``from cosserat_chain import simulate, critical_point``). Each is imported when first
used (PEP 562), so that ``import cosserat_chain`` and the command line start quickly:
the compiled kernels, SciPy and xarray load only when something needs them.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from ._version import __version__

#: Public name -> the module that defines it.
_API = {
    # parameters, loads, models
    "ChainParams": "params",
    "Loads": "loads",
    "PointLoad": "loads",
    "Schedule": "loads",
    "moment_load": "loads",
    "available_models": "models",
    "get_model": "models",
    "register_model": "models",
    # dynamics
    "simulate": "experiments.simulation",
    "integrate": "numerics.dynamics",
    "integrate_batch": "numerics.batch",
    "integrate_adaptive": "numerics.adaptive",
    "relax": "numerics.relaxation",
    "relax_batch": "numerics.relaxation",
    "disordered": "params",
    "relaxation_sweep": "experiments.sweep",
    "relaxation_sweeps": "experiments.sweep",
    "localization_run": "experiments.localization",
    "energy_budget": "analysis.energy",
    # statics and stability
    "solve_equilibrium": "numerics.newton",
    "critical_point": "experiments.critical",
    "continue_in_moment": "numerics.continuation",
    "locate_fold": "numerics.continuation",
    "continue_fold": "numerics.fold_curve",
    "compliance": "numerics.continuation",
    "static_stability": "numerics.stability",
    "dynamic_stability": "numerics.stability",
    "hopf_points": "numerics.hopf",
    # rotating states and the map of states
    "periodic_orbit": "experiments.orbits",
    "state_diagram": "experiments.diagram",
    # theory and waves
    "convergence": "analysis.continuum",
    "dispersion": "analysis.dispersion",
    "wave_summary": "analysis.dispersion",
    "finite_modes": "analysis.dispersion",
    # studies, files, the report
    "spec_from_mapping": "experiments.study",
    "run_study": "study_runner",
    "read_dataset": "io",
    "write_dataset": "io",
    "load_params": "io",
    "reproduce": "report",
    "ReproduceSettings": "report",
    "Status": "status",
    "CosseratChainError": "errors",
}

#: The same names as :data:`_API` (a literal list, for linters; a test keeps the two equal).
__all__ = [
    "ChainParams",
    "CosseratChainError",
    "Loads",
    "PointLoad",
    "ReproduceSettings",
    "Schedule",
    "Status",
    "__version__",
    "available_models",
    "compliance",
    "continue_in_moment",
    "convergence",
    "critical_point",
    "disordered",
    "dispersion",
    "energy_budget",
    "finite_modes",
    "get_model",
    "integrate",
    "integrate_adaptive",
    "integrate_batch",
    "load_params",
    "localization_run",
    "locate_fold",
    "continue_fold",
    "moment_load",
    "periodic_orbit",
    "read_dataset",
    "register_model",
    "relax",
    "relax_batch",
    "relaxation_sweep",
    "relaxation_sweeps",
    "reproduce",
    "run_study",
    "simulate",
    "solve_equilibrium",
    "spec_from_mapping",
    "state_diagram",
    "static_stability",
    "dynamic_stability",
    "hopf_points",
    "wave_summary",
    "write_dataset",
]


def __getattr__(name: str) -> Any:
    module = _API.get(name)
    if module is None:
        raise AttributeError(f"module 'cosserat_chain' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value  # later lookups skip this function
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_API))


if TYPE_CHECKING:  # for type checkers and IDEs, which do not run __getattr__
    from .analysis.continuum import convergence
    from .analysis.dispersion import dispersion, finite_modes, wave_summary
    from .analysis.energy import energy_budget
    from .errors import CosseratChainError
    from .experiments.critical import critical_point
    from .experiments.diagram import state_diagram
    from .experiments.localization import localization_run
    from .experiments.orbits import periodic_orbit
    from .experiments.simulation import simulate
    from .experiments.study import spec_from_mapping
    from .experiments.sweep import relaxation_sweep, relaxation_sweeps
    from .io import load_params, read_dataset, write_dataset
    from .loads import Loads, PointLoad, Schedule, moment_load
    from .models import available_models, get_model, register_model
    from .numerics.adaptive import integrate_adaptive
    from .numerics.batch import integrate_batch
    from .numerics.continuation import compliance, continue_in_moment, locate_fold
    from .numerics.dynamics import integrate
    from .numerics.fold_curve import continue_fold
    from .numerics.hopf import hopf_points
    from .numerics.newton import solve_equilibrium
    from .numerics.relaxation import relax, relax_batch
    from .numerics.stability import dynamic_stability, static_stability
    from .params import ChainParams, disordered
    from .report import ReproduceSettings, reproduce
    from .status import Status
    from .study_runner import run_study
