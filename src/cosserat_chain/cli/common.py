"""The Typer application and what every command shares: option types, errors, progress bars.

The CLI is thin by design: options -> ChainParams and loads -> experiment -> NetCDF / JSON.
Each command lives in its own module of this package and registers itself on ``app``.
"""

from __future__ import annotations

import atexit
import functools
import gc
import importlib
import math
import os
import signal
import sys
import tempfile
import threading
from contextlib import ExitStack
from enum import Enum
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn

import typer
from pydantic import ValidationError
from tqdm import tqdm

from ..io import (
    FIGURE_FORMATS,
    OutputError,
    check_output,
    load_config,
    netcdf_image,
    output_lock,
    write_bytes,
    write_fallback,
    write_figure,
)
from ..memory import MemoryEstimateError, available, size_text
from ..params import MAX_MAGNITUDE, ChainParams
from ..status import Status

if TYPE_CHECKING:  # loads import numba: the command line imports them where a command needs them
    from ..loads import Loads


class _App(typer.Typer):
    """The Typer application, whose every command turns a memory refusal or a ``MemoryError`` into a message (exit 2).

    The computations estimate their large arrays before allocating them
    (:mod:`cosserat_chain.memory`); this is the net for an allocation no estimate
    foresaw (a chain of 10^9 particles meets one in its first array).

    Each command's module is imported when the command is needed (:meth:`defer`): a run
    of the command line (:meth:`__call__`) imports the module of the command it names,
    anything else that reads the commands (``--help``, a wrong name, completion, a test's
    runner) imports them all and lists them in the order :meth:`defer` gave.
    """

    def __init__(self, *args, **kwargs):
        self._commands: list = []
        self._modules: dict[str, str] = {}  # command name -> the module of this package that registers it
        self._chosen: str | None = None  # the command a run names, whose module alone it imports
        self._importing = False
        super().__init__(*args, **kwargs)

    def defer(self, modules: dict[str, str]) -> None:
        """Register the commands by name, each with the module of this package that defines it, in the order of ``--help``."""
        self._modules = dict(modules)

    @property
    def registered_commands(self) -> list:
        """The commands, their modules imported first (only the named command's during a run), in :meth:`defer`'s order."""
        if not self._importing:
            wanted = self._modules if self._chosen is None else {self._chosen: self._modules[self._chosen]}
            missing = [name for name in dict.fromkeys(wanted.values()) if f"{__package__}.{name}" not in sys.modules]
            self._importing = True  # a module being imported registers its commands (appends) without a recursion
            try:
                for name in missing:
                    importlib.import_module(f".{name}", __package__)
            finally:
                self._importing = False
            order = {name: rank for rank, name in enumerate(self._modules)}
            self._commands.sort(key=lambda info: order.get(info.name or typer.main.get_command_name(info.callback.__name__), len(order)))
        return self._commands

    @registered_commands.setter
    def registered_commands(self, commands: list) -> None:
        self._commands = commands

    def __call__(self, *args, **kwargs):
        """Run the command line: import the named command's module only (all of them for group options, help, completion).

        At exit the objects alive are frozen out of the garbage collector (:func:`gc.freeze`):
        the interpreter's teardown then skips the full collections over every object the imports
        made (NumPy, Numba, SciPy), the largest cost of a short command after the imports.
        Outputs are written and closed by the commands themselves, never left to a collector.

        SIGTERM (a batch scheduler's stop, ``kill``) ends a command as Ctrl-C does, where no
        handler of the caller's is installed: checkpoints, frames and cells computed so far are
        kept and the exit status is 130.
        """
        terminate = None
        if threading.current_thread() is threading.main_thread() and signal.getsignal(signal.SIGTERM) is signal.SIG_DFL:
            terminate = signal.signal(signal.SIGTERM, _stopped)
        try:
            return self._run(*args, **kwargs)
        finally:
            if terminate is not None:
                signal.signal(signal.SIGTERM, terminate)

    def _run(self, *args, **kwargs):
        argv = kwargs.get("args", args[0] if args else None)
        argv = sys.argv[1:] if argv is None else list(argv)
        completing = any(key.startswith("_") and key.endswith("_COMPLETE") for key in os.environ)
        chosen = argv[0] if argv and argv[0] in self._modules and not completing else None
        atexit.unregister(gc.freeze)  # once, however many runs a process makes (the tests run many)
        atexit.register(gc.freeze)
        self._chosen = chosen
        try:
            return super().__call__(*args, **kwargs)
        finally:
            self._chosen = None

    def command(self, *args, **kwargs):
        register = super().command(*args, **kwargs)

        def decorate(function):
            @functools.wraps(function)
            def guarded(*call_args, **call_kwargs):
                try:
                    return function(*call_args, **call_kwargs)
                except MemoryEstimateError as err:  # an estimate refused the work before it started
                    fail(str(err))
                except MemoryError as err:
                    fail(
                        f"not enough memory: {err or 'an allocation failed'} ({size_text(available())} free); "
                        "a shorter chain (N) or fewer stored states fit"
                    )
                except KeyboardInterrupt:
                    # The net for the commands without their own Ctrl-C handling (those that keep their frames or
                    # cells catch it themselves and say what they kept): exit 130 saying so, not a traceback.
                    exit_on(
                        Status.INTERRUPTED,
                        f"{function.__name__} was interrupted before it finished: its result is not complete (files it wrote "
                        "whole before that stay, none is half-written)",
                    )
                finally:
                    _LOCKS.close()  # the outputs' locks of this command (a test runs many commands in one process)

            return register(guarded)

        return decorate


def _stopped(signum, frame) -> NoReturn:
    """SIGTERM's handler while a command runs: the commands' Ctrl-C paths keep what was computed."""
    raise KeyboardInterrupt


# No Rich markup in the help: it would take the TOML tables "[[loads]]" and "[reproduce]" for style tags and drop them.
app = _App(add_completion=True, help="Discrete Cosserat chains of finite-size particles.", no_args_is_help=True, rich_markup_mode=None)

#: The locks of the running command's outputs (:func:`outputs_or_exit`), released when it returns.
_LOCKS = ExitStack()

#: The ``--model`` value that stands for every offered model (a name the registry reserves).
ALL_MODELS = "all"


def model_names(*, rotating: bool = False) -> tuple[str, ...]:
    """The registered models, in registration order; with ``rotating``, those that support full rotations."""
    from ..models import available_models, get_model  # the compiled kernels load here, not when the CLI starts

    return tuple(name for name in available_models() if not rotating or get_model(name).rotates)


def _offered(rotating: bool, all_models: bool) -> tuple[str, ...]:
    names = model_names(rotating=rotating)
    return (*names, ALL_MODELS) if all_models else names


def model_option(default: str, description: str, *, rotating: bool = False, all_models: bool = False):
    """A ``--model`` option over the registry (annotate the parameter ``str``).

    The value is checked against the registry when the command runs, so a model
    registered after the CLI was imported (a plugin, a test) is accepted, and a
    wrong name gets the current list. (This Typer takes its choices only from an
    Enum or a Literal, fixed when the function is defined; hence a parser.) The
    help text points to ``cosserat-chain models`` instead of listing them: listing
    them would load every model's compiled kernels whenever the command line starts,
    ``--help`` included.

    Parameters
    ----------
    default : str
    description : str
        First sentence of the help text.
    rotating : bool
        Offer only the models that support full rotations (``Model.rotates``).
    all_models : bool
        Offer :data:`ALL_MODELS` as well, for every registered model (:func:`chosen_models`).
    """

    def parse(value: str) -> str:
        offered = _offered(rotating, all_models)
        if value not in offered:
            raise typer.BadParameter(f"{value!r} is not one of {', '.join(map(repr, offered))}.")
        return value

    which = "a registered model that supports full rotations" if rotating else "a registered model"
    also = f", or {ALL_MODELS} for every one" if all_models else ""
    return typer.Option(
        default, parser=parse, metavar="<model>", help=f"{description} The name of {which}{also} (`cosserat-chain models` lists them)."
    )


def chosen_models(choice: str) -> list[str]:
    """The models a ``--model`` value names: every registered one for :data:`ALL_MODELS`."""
    return list(model_names()) if choice == ALL_MODELS else [choice]


class MethodName(str, Enum):
    verlet = "verlet"
    yoshida4 = "yoshida4"


def finite_or_none(value: float) -> float | None:
    """JSON has no NaN or infinity: map them to null."""
    return float(value) if math.isfinite(value) else None


#: Exit codes of the commands, one per outcome (documented in docs/exit-codes.md): 0 a result,
#: 2 bad input (see :func:`fail`), 3 a run that did not produce what was asked (blew up,
#: solver failure, not converged, an output that could not be written), 4 a run stopped at
#: its time limit (resumable), 5 a run that completed but failed its accuracy checks,
#: 130 interrupted (Ctrl-C; what was computed is kept).
EXIT_CODES = {
    Status.COMPLETED: 0,
    Status.INACCURATE: 5,
    Status.STATIC: 0,
    Status.ROTATING: 0,
    Status.BLEW_UP: 3,
    Status.FAILED: 3,
    Status.MAX_STEPS: 3,
    Status.STEP_TOO_SMALL: 3,
    Status.NOT_CONVERGED: 3,
    Status.TIME_LIMIT: 4,
    Status.INTERRUPTED: 130,
}


def snic_line(point: dict, vary: str, fold: str, drive: str, drive_value: float | None) -> str:
    """The line on where a diagram's homoclinic end meets the static fold (a SNIC from there on), for ``diagram`` and ``system diagram``.

    Parameters
    ----------
    point : dict
        The diagram's ``snic_point``: ``between`` (two values of ``vary``), ``method`` (``solved``,
        ``extrapolated`` or ``not_located``), ``value``, ``accuracy``, ``from`` and ``reason`` as the method has them.
    vary : str
        The varied parameter's name.
    fold : str
        What the fold is called ("M_c", "the fold").
    drive, drive_value : str, float or None
        The drive's name and its value at the solved point.
    """
    where = f"between {vary} = {point['between'][0]:g} and {point['between'][1]:g}"
    if point["method"] == "solved":
        value = f"{point['value']:.13g} +- {point['accuracy']:.1g} (solved by the augmented system, {drive} = {drive_value:.10g} there)"
    elif point["method"] == "extrapolated":
        value = f"{point['value']:.6g}, extrapolated from {vary} = {point['from'][0]:g}, {point['from'][1]:g} ({point['reason']})"
    else:
        value = f"not located ({point['reason']})"
    return f"the homoclinic end meets {fold} (a SNIC from there on) {where}: {vary} = {value}"


def exit_on(status: str, message: str) -> None:
    """Warn on stderr and exit with the status's code unless it is a result (:data:`EXIT_CODES`)."""
    status = Status(status)
    if not status.ok:
        typer.secho(f"{status}: {message}", err=True, fg=typer.colors.YELLOW)
        raise typer.Exit(EXIT_CODES[status])


def fail(message: str, code: int = 2) -> NoReturn:
    """Print ``error: message`` on stderr and exit with ``code`` (2: bad input)."""
    typer.secho(f"error: {message}", err=True, fg=typer.colors.RED)
    raise typer.Exit(code)


def held_or_exit(params: ChainParams, particle: int) -> None:
    """Refuse (exit 2), for a static computation, a chain that can move rigidly or a loaded particle outside it or held by an end."""
    from ..params import FIXED_ROWS
    from ..state import ROW_INDEX, column, require_held

    try:
        require_held(params)
    except ValueError as err:
        fail(f"--config: {err}")
    try:
        col = column(params, particle)
    except ValueError as err:
        fail(f"--particle: {err}")
    # The ends' rows by their kind, not by the index of every free degree of freedom (N may be 10^9).
    end = {0: 0, params.n_particles - 1: 1}.get(col)
    if end is not None and ROW_INDEX["phi"] in FIXED_ROWS[params.ends[end]]:
        fail(
            f"--particle: phi of particle {particle} is held fixed by the {('left', 'right')[end]} end ({params.ends[end]}); "
            "choose a free degree of freedom"
        )


def stiff_at_rest_or_exit(params: ChainParams, particle: int = 0) -> None:
    """Refuse (exit 2) a chain whose stiffness at rest is singular, naming its fields; return otherwise.

    For a computation that already failed (it costs a solve): E2 = 0 leaves v without
    stiffness, and fields far from order 1 (E1 or b = 1e-100) make K singular in double
    precision; such a chain has no static branch, and the computation's own message would
    name a fold or a NaN instead.
    """
    import numpy as np

    from ..numerics.continuation import moment_response

    if params.E2 == 0:
        fail(
            "E2 = 0 leaves the transverse displacements v without stiffness (k_v = 8 b^2 / d^2 E2 = 0): the chain has no "
            "unique static state and no static branch; the statics need E2 > 0"
        )
    try:
        response = moment_response(params, "linear", particle=particle)
        singular = not float(np.max(np.abs(response), initial=0.0)) <= MAX_MAGNITUDE
    except (MemoryEstimateError, MemoryError):
        return  # too long a chain to tell: the caller's own message stands
    except (ValueError, ArithmeticError):
        singular = True
    if singular:
        _singular_at_rest(params)


#: Half-length of the chain on which :func:`short_stiff_at_rest_or_exit` checks K at rest.
SHORT_N = 3


def short_stiff_at_rest_or_exit(params: ChainParams) -> None:
    """:func:`stiff_at_rest_or_exit` up front at a cost independent of N: on the chain cut to N = :data:`SHORT_N`.

    For a computation that solves the chain's own response at rest itself (``critical``): fields
    far from order 1 (E1 = 1e-100) make K singular at any length, and are refused here before
    the computation, whose quiet end they could otherwise be; the response it solves is then
    checked with :func:`compliance_or_exit`. A graded chain (its factors fix N) is checked whole.
    """
    stiff_at_rest_or_exit(params if params.graded or params.N <= SHORT_N else params.replace(N=SHORT_N))


def compliance_or_exit(params: ChainParams, compliance: float) -> None:
    """Refuse (exit 2, as :func:`stiff_at_rest_or_exit`) a chain whose compliance at rest, solved by the computation, is not finite and within MAX_MAGNITUDE."""
    if not abs(compliance) <= MAX_MAGNITUDE:
        _singular_at_rest(params)


def _singular_at_rest(params: ChainParams) -> NoReturn:
    fields = ", ".join(f"{name}={getattr(params, name)!r}" for name in ("E1", "E2", "h", "a", "b"))
    fail(
        f"the chain's stiffness at rest is singular in double precision ({fields}): it has no unique static state; the model is "
        "dimensionless, so give fields of order 1"
    )


def statics_failed(params: ChainParams, err: Exception, particle: int = 0) -> NoReturn:
    """Exit on the error of a computation from the static branch whose inputs were checked.

    A chain without stiffness at rest is bad input (code 2, :func:`stiff_at_rest_or_exit`);
    any other failure keeps its message (code 3).
    """
    stiff_at_rest_or_exit(params, particle)
    fail(f"the computation failed: {err}", code=EXIT_CODES[Status.FAILED])


def params_or_exit(config: Path | None) -> ChainParams:
    """Read the TOML config (or the paper's defaults); a bad field exits with its name and value.

    The commands that read only the chain take no loads from the file: a config with
    ``[[loads]]`` tables is refused (exit 2) rather than answered for another load than it says.
    """
    params, loads = config_or_exit(config)
    if len(loads):
        fail(
            f"--config {str(config)!r} has {len(loads)} [[loads]] table(s), which this command does not use (it reads the "
            "chain only; its load is its own --moment): leave them out of the file, or run simulate, rotate or sweep, which apply them"
        )
    return params


def config_or_exit(config: Path | None, load: list[str] | None = None) -> tuple[ChainParams, Loads]:
    """The chain and the loads of the TOML config (its ``[[loads]]``) and of ``--load ROW:PARTICLE=VALUE`` options.

    A bad field or load exits with its name and value (code 2).
    """
    from ..loads import Loads, parse_load

    try:
        params, loads = load_config(config)
        return params, Loads([*loads, *(parse_load(text) for text in load or ())]).validate(params)
    except ValidationError as err:
        fail(
            "invalid parameters:\n"
            + "\n".join(f"  {'.'.join(map(str, e['loc'])) or 'params'}: {e['msg']} (got {e.get('input')!r})" for e in err.errors())
        )
    except ValueError as err:
        fail(str(err))


class ProgressBar(tqdm):
    """A tqdm bar of whole counts that ends at 100 % when the work is done, or says why it stopped.

    A command ends it with :meth:`finish` once its computation has returned; a bar closed
    while an exception is raised (a bad input found late, Ctrl-C, an error) is marked
    ``stopped`` with the exception's name, its count left where the work stopped.
    """

    _ended = False

    def finish(self, status: str | None = None, note: str = "") -> None:
        """Close the bar after the computation returned with ``status`` (None: a result).

        A result ends at 100 %: the work there was is the count reached, where the work
        ended before its nominal total (a continuation that ended at a fold before its cap
        of points, a sweep that stopped at the onset); ``note`` says why, shown beside the
        count. Any other :class:`~cosserat_chain.status.Status` (``blew_up``,
        ``time_limit``, ``interrupted``, ...) leaves the count where the work stopped and
        shows ``stopped: STATUS``.
        """
        if not self.disable:
            if status is not None and not Status(status).ok:
                self.set_postfix_str(f"stopped: {Status(status)}" + (f" ({note})" if note else ""), refresh=False)
            else:
                if self.unit == "%":
                    self.update(100 - self.n)
                else:
                    # The count reached is all the work there was (a bar never updated ran one piece of work).
                    self.update(1 if self.n == 0 else 0)
                    self.total = self.n
                if note:
                    self.set_postfix_str(note, refresh=False)
        self._ended = True
        self.close()

    def close(self) -> None:
        self._stopped_by(sys.exc_info()[0])
        super().close()

    def _stopped_by(self, error: type[BaseException] | None) -> None:
        if not self._ended and not self.disable and error is not None:
            self.set_postfix_str(f"stopped: {error.__name__}", refresh=False)
        self._ended = True

    def __exit__(self, exc_type, exc_value, traceback) -> None:
        if exc_type is None:
            self.finish()
        else:
            self._stopped_by(exc_type)
            self.close()


#: Most particle-steps (particles x time steps) a command starts: some 10^5 s, more than a day, at the
#: engine's best speed of about 10^9 particle-steps a second on one core. Beyond it a run is refused
#: before it starts, with its estimate: such a run is a mistyped step, moment or count, not a plan.
MAX_WORK = 1e14

#: Most radians the spinning particle may turn in one step at its terminal spin M / gamma_phi: half a
#: turn, beyond which no turn can be told from its reverse (the turn count itself aliases).
MAX_TURN_PER_STEP = math.pi

#: Chains up to this many particles get their default time step computed for the checks before a
#: run; a longer one meets the run's own memory estimate first (the step's bound is O(N) work).
_CHECKED_PARTICLES = 10**6


#: The remedy for too many steps at the default step: it follows the chain's fastest mode.
LARGER_STEP = "a chain of numbers of order 1 (the default step follows the fastest mode sqrt(stiffness / inertia): E1, E2, m, j)"


def step_for_checks(params: ChainParams, model: str, dt: float | None) -> float | None:
    """The time step a run will take, ``dt`` or the model's default; None for a chain too long to check cheaply."""
    if dt is not None:
        return float(dt)
    if params.n_particles > _CHECKED_PARTICLES:
        return None
    from ..numerics.integrators import default_time_step

    return default_time_step(params, model)


def work_or_exit(steps: float, particles: int, what: str, remedy: str) -> None:
    """Refuse (exit 2), before it starts, work of more than :data:`MAX_WORK` particle-steps, with the estimate.

    Parameters
    ----------
    steps : float
        Time steps the work takes at least (all runs together).
    particles : int
        Particles of the chain.
    what : str
        How the estimate is made, e.g. ``"1e+09 starts x 2.4e+05 steps"``.
    remedy : str
        What to change.
    """
    work = steps * particles
    if not work <= MAX_WORK:  # also NaN
        fail(
            f"this would take at least {work:.3g} particle-steps ({what}, x {particles} particles), some "
            f"{work / 1e9 / 86400:.3g} days at 10^9 particle-steps a second; at most {MAX_WORK:.0e} are started: {remedy}"
        )


def spin_or_exit(params: ChainParams, moment: float, dt: float | None, option: str = "--moment", *, dt_option: bool = True) -> None:
    """Refuse (exit 2) a moment whose terminal spin |M| / gamma_phi turns its particle by more than half a turn a step of ``dt``."""
    if dt is None or params.gamma_phi == 0.0 or moment == 0.0:
        return
    spin = abs(moment) / params.gamma_phi
    if spin * dt > MAX_TURN_PER_STEP:
        fail(
            f"{option} {moment:g} spins its particle at up to |M| / gamma_phi = {spin:.3g} rad per unit time, {spin * dt:.3g} rad "
            f"per step of dt={dt:.3g}: more than half a turn a step, which no run can follow (its turns cannot be counted); "
            f"a moment below {MAX_TURN_PER_STEP * params.gamma_phi / dt:.3g}"
            + (f", or --dt <= {MAX_TURN_PER_STEP / spin:.3g}" if dt_option else "")
        )


def progress_bar(desc: str, unit: str) -> ProgressBar:
    """A :class:`ProgressBar` on stderr, shown only on a terminal (``disable=None``), counting whole ``unit``s."""
    return ProgressBar(total=None, unit=unit, unit_scale=False, desc=desc, disable=None, file=sys.stderr)


def bar_callback(bar: tqdm):
    """Turn a bar into the library's ``progress(done, total)`` callback.

    Whole counts (steps, loads, turns) are shown as they are; a quantity that is not a
    count (the loaded particle's angle along a branch, in radians) as a whole percentage,
    so that the bar never shows fractions; :meth:`ProgressBar.finish` takes either to
    100 % when the work is done.
    """

    def progress(done: float, total: float) -> None:
        if bar.disable:
            return
        if bar.unit != "%" and float(done).is_integer() and float(total).is_integer():
            bar.total = int(total)
            bar.update(int(done) - bar.n)
            return
        bar.unit, bar.total = "%", 100
        bar.update(max(0, min(100, int(100 * done / total))) - bar.n if total > 0 else 0)

    return progress


def number(
    default: float | None,
    help: str,
    *,
    above: float | None = None,
    at_least: float | None = None,
    at_most: float | None = None,
    flags: tuple[str, ...] = (),
):
    """A float option that must be finite (and > ``above`` or >= ``at_least``, <= ``at_most``), checked as the line is parsed.

    A bad value exits with code 2 and click's "Invalid value for '--name'" message,
    before anything is computed. (click's own ranges let NaN through: every comparison
    with NaN is false.)
    """

    def check(value: float | None) -> float | None:
        if value is None:
            return value
        if not math.isfinite(value):
            raise typer.BadParameter(f"must be a finite number, got {value!r}")
        if above is not None and not value > above:
            raise typer.BadParameter(f"must be > {above:g}, got {value!r}")
        if at_least is not None and not value >= at_least:
            raise typer.BadParameter(f"must be >= {at_least:g}, got {value!r}")
        if at_most is not None and not value <= at_most:
            raise typer.BadParameter(f"must be <= {at_most:g}, got {value!r}")
        return value

    return typer.Option(default, *flags, callback=check, help=help)


def whole(default: int | None, help: str, *, at_least: int, at_most: int | None = None, flags: tuple[str, ...] = ()):
    """A whole-number option in [``at_least``, ``at_most``], checked as the line is parsed.

    A bad value exits with code 2 and click's "Invalid value for '--name'" message naming the
    value and the range allowed (click's own ranges name the range only).
    """

    def check(value: int | None) -> int | None:
        if value is None:
            return value
        if value < at_least or (at_most is not None and value > at_most):
            allowed = f">= {at_least}" if at_most is None else f"in {at_least}..{at_most}"
            raise typer.BadParameter(f"must be a whole number {allowed}, got {value}")
        return value

    return typer.Option(default, *flags, callback=check, help=help)


def outputs_or_exit(
    outputs: dict[str, Path | None],
    inputs: dict[str, Path | None] | None = None,
    *,
    formats: dict[str, tuple[str, ...]] | None = None,
    folders: tuple[str, ...] = (),
) -> None:
    """Check every output of a command and take its lock before the command computes; exit 2 naming the bad one.

    Each output is checked by :func:`cosserat_chain.io.check_output`, then locked
    (:func:`cosserat_chain.io.output_lock`) until the command returns: a second run
    writing the same file is refused here, naming the process that writes it.

    Parameters
    ----------
    outputs : {option: path or None}
    inputs : {option: path or None}
        The command's input files: no output may be one of them, nor two outputs the same file.
    formats : {option: allowed suffixes}
        Default: :data:`FIGURE_FORMATS` for ``--plot``, any suffix otherwise.
    folders : options whose path is a folder (``reproduce --out``)
    """
    formats = {"--plot": FIGURE_FORMATS, **(formats or {})}
    given = {option: path for option, path in outputs.items() if path is not None}
    try:
        for option, path in given.items():
            others = {name: other for name, other in given.items() if name != option}
            check_output(path, option, formats=formats.get(option), inputs={**(inputs or {}), **others}, folder=option in folders)
        for option, path in given.items():
            _LOCKS.enter_context(output_lock(path, option, folder=option in folders))
    except OutputError as err:
        fail(str(err))


def default_checkpoint(out: Path | None) -> Path | None:
    """OUT.checkpoint.nc next to ``--out``, or no checkpoint without ``--out``."""
    return None if out is None else out.with_name(f"{out.stem}.checkpoint.nc")


def checkpoint_or_exit(
    checkpoint: Path | None,
    out: Path | None,
    *,
    resume: bool,
    force: bool,
    inputs: dict[str, Path | None] | None = None,
    needed_by: str | None = None,
) -> Path | None:
    """The checkpoint file of a command with ``--checkpoint``, ``--resume`` and ``--force``, its outputs checked; or exit 2 saying why not.

    The file is ``--checkpoint`` or :func:`default_checkpoint` of ``--out``. ``--out`` and
    the checkpoint are checked as outputs (:func:`outputs_or_exit`) before any work, and an
    existing checkpoint is replaced only with ``--force`` (or continued with ``--resume``):
    it may hold hours of an earlier run.

    Parameters
    ----------
    checkpoint, out : path or None
    resume, force : bool
    inputs : {option: path or None}
        The command's input files (no output may be one of them).
    needed_by : str, optional
        The option that asks for a checkpoint (``--checkpoint-every``): without a file it is
        refused like ``--resume``.
    """
    checkpoint = checkpoint if checkpoint is not None else default_checkpoint(out)
    asking = "--resume" if resume else needed_by
    if asking is not None and checkpoint is None:
        fail(f"{asking} needs --checkpoint or --out (whose checkpoint is OUT.checkpoint.nc)")
    if resume and force:
        fail("--resume and --force contradict each other: --resume continues the checkpoint, --force replaces it")
    outputs_or_exit({"--out": out, "--checkpoint": checkpoint}, inputs)
    if checkpoint is not None and checkpoint.exists() and not (resume or force):
        fail(
            f"the checkpoint {str(checkpoint)!r} exists (an earlier run): give --resume to continue it, "
            "or --force to start afresh and replace it"
        )
    return checkpoint


#: The command that writes each kind of result file (its ``experiment`` attribute).
_WRITTEN_BY = {
    "critical_point": "critical",
    "relaxation_sweep": "sweep",
    "localization_run": "rotate",
    "periodic_orbit": "orbit",
    "rotation_characteristic": "orbit",
    "parameter_study": "study",
}


def run_or_exit(run: Path, *, velocities: bool = False):
    """The run of ``simulate --out`` stored in ``run`` (an xarray Dataset); exit 2 naming what the file is otherwise.

    A run holds u, v and phi over time and particle (and their velocities where
    ``velocities``), checked field by field (:func:`cosserat_chain.inputs.check_run`): a
    damaged or edited run is named with what is wrong. Any other file is named: a result
    of another command (by its ``experiment`` attribute), or not a file of this package.
    """
    from ..inputs import check_run
    from ..io import read_dataset
    from ..state import ROWS

    try:
        ds = read_dataset(run)
    except ValueError as err:
        fail(f"RUN: {err}")
    if any(row in ds.variables and set(ds.variables[row].dims) == {"time", "particle"} for row in ROWS):
        try:
            check_run(ds, f"RUN {str(run)!r}", velocities=velocities)
        except ValueError as err:
            fail(str(err))
        return ds
    experiment = ds.attrs.get("experiment")
    command = _WRITTEN_BY.get(experiment)
    kind = f"the output of `cosserat-chain {command}` ({experiment})" if command else "not a run of this package"
    own_plot = f"; `{command} --plot` draws its own figure" if command in ("critical", "sweep", "orbit", "study") else ""
    fail(f"RUN {str(run)!r} is {kind}, with no states over time: draw, animate and export read the runs of `simulate --out`{own_plot}")


def save_dataset(dataset, out: Path | None, option: str = "--out") -> None:
    """Write a result to ``out``; if that fails now that the work is done, keep it in a fallback file and say where (exit 3).

    The fallback is a new file ``STEM.recovered-XXXXXXXX.nc`` (a random part no other user
    can predict, mode 0600: :func:`cosserat_chain.io.write_fallback`) in the working
    folder, else in the system's temporary folder.
    """
    if out is None:
        return
    image = netcdf_image(dataset)
    try:
        write_bytes(image, out)
        return
    except (OSError, OutputError) as err:
        reason = f"{err.strerror or err}" if isinstance(err, OSError) else str(err)
    stem, suffix = Path(out).stem or "result", Path(out).suffix or ".nc"
    for folder in (Path.cwd(), Path(tempfile.gettempdir())):
        try:
            fallback = write_fallback(image, folder, stem, suffix)
        except OSError:
            continue
        fail(f"could not write {option} {str(out)!r} ({reason}); the result is saved in {str(fallback)!r}", code=3)
    fail(f"could not write {option} {str(out)!r} ({reason}), nor a fallback in the working or temporary folder: the result is lost", code=3)


def save_figure(fig, path: Path, option: str = "--plot") -> None:
    """Write a matplotlib figure to ``path`` (format from the extension) atomically; a failure exits 3 naming the option."""
    try:
        write_figure(fig, path, dpi=150)
    except (OSError, OutputError, ValueError) as err:
        fail(f"could not write {option} {str(path)!r}: {err}", code=3)


def _version(value: bool) -> None:
    if value:
        from .._version import __version__

        typer.echo(f"cosserat-chain {__version__}")
        raise typer.Exit()


@app.callback()
def main(
    version: bool = typer.Option(False, "--version", callback=_version, is_eager=True, help="Print the version and exit."),
) -> None:
    """Simulate chains of rectangular particles that translate and rotate (nonlinear, sine and linear Cosserat models)."""
