"""The one vocabulary of outcomes: every run, relaxation step and solve reports a :class:`Status`.

Contract
--------
A :class:`Status` is a ``str`` enum, so it compares equal to its value
(``Status.COMPLETED == "completed"``) and files and JSON keep the plain strings.
:attr:`Status.ok` says whether the result is what was asked for; the command line
maps every status to its exit code in one place (``cli.common.exit_code``).
"""

from __future__ import annotations

from enum import StrEnum


class Status(StrEnum):
    """How a run, a relaxation step or a solve ended."""

    #: The run reached its end (``t_end``, the requested turns, the solver's end time).
    COMPLETED = "completed"
    #: The run reached its end, but its own accuracy checks failed (the energy balance,
    #: the rotation per step): its numbers are not to be trusted; a smaller dt is needed.
    INACCURATE = "inaccurate"
    #: A value became non-finite or left its bounds; the states before are kept.
    BLEW_UP = "blew_up"
    #: Ctrl-C; what was computed is kept.
    INTERRUPTED = "interrupted"
    #: Stopped at its step budget before reaching its goal; resumable.
    TIME_LIMIT = "time_limit"
    #: The adaptive solver could not go on (``max_steps`` or a step too small).
    FAILED = "failed"
    MAX_STEPS = "max_steps"
    STEP_TOO_SMALL = "step_too_small"
    #: A relaxation step ended at rest.
    STATIC = "static"
    #: A relaxation step ended in a steady rotation.
    ROTATING = "rotating"
    #: A relaxation step ended neither at rest nor rotating steadily by its time cap.
    NOT_CONVERGED = "not_converged"

    @property
    def ok(self) -> bool:
        """Whether the outcome is a result (not a failure, an interruption or a cap)."""
        return self in (Status.COMPLETED, Status.STATIC, Status.ROTATING)
