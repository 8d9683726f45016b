"""How the command-line tools (``eval``, ``demos``, ``replay``, ``bench``, ``showcase``) report failures.

Every tool module has ``cli(argv=None)``, which parses ``argv`` and runs the tool's ``main`` through ``run_cli``:

- a **user error**, an input the user can fix (a missing or malformed suite, an unknown suite, policy or env id, a
  missing checkpoint, ``--env-kwargs`` that is not a JSON object, an env kwarg the env rejects, a count below 1), is
  one line on stderr, ``mani-skill-space TOOL: error: ...``, and exit status 2 (as for a malformed command line);
- anything else is a bug and shows its traceback.

A user error is a ``UserError``. The tools check their inputs up front, before any worker process starts, inside
``checking_inputs()``, which turns the ``ValueError`` or ``OSError`` of a check into a ``UserError`` with the same
message; errors raised while the tool runs stay what they are.

``--debug`` (anywhere among a tool's arguments) shows the traceback of a user error too.
"""

from __future__ import annotations

import json
import sys
from contextlib import contextmanager
from typing import Any, Callable, Iterator, Optional, Sequence, TypeVar

PROG = "mani-skill-space"
DEBUG_FLAG = "--debug"
DEBUG_HELP = f"{DEBUG_FLAG}: show the traceback of an input error (by default it is one line on stderr, exit status 2)."
USER_ERROR_EXIT_STATUS = 2

Args = TypeVar("Args")


class UserError(ValueError):
    """An input the user can fix; the command line shows it as one line, without a traceback."""


@contextmanager
def checking_inputs() -> Iterator[None]:
    """Marks a tool's input checks: a ``ValueError`` or ``OSError`` raised inside (a bad value, a missing or
    unreadable file the user named) becomes a ``UserError`` with the same message."""
    try:
        yield
    except UserError:
        raise
    except (ValueError, OSError) as error:
        raise UserError(one_line(error)) from error


def one_line(error: BaseException) -> str:
    lines = [line.strip() for line in str(error).splitlines() if line.strip()]
    return "; ".join(lines) or type(error).__name__


def run_cli(tool: str, parse: Callable[[list[str]], Args], main: Callable[[Args], Any], argv: Optional[Sequence[str]] = None) -> None:
    """Parse ``argv`` (the process's arguments by default) with ``parse`` and run ``main`` on the result; a
    ``UserError`` is printed as one line and exits with status 2 unless ``--debug`` is among the arguments."""
    arguments = list(sys.argv[1:] if argv is None else argv)
    debug = DEBUG_FLAG in arguments
    arguments = [a for a in arguments if a != DEBUG_FLAG]
    args = parse(arguments)
    try:
        main(args)
    except UserError as error:
        if debug:
            raise
        print(f"{PROG} {tool}: error: {error}", file=sys.stderr)
        raise SystemExit(USER_ERROR_EXIT_STATUS) from None


def tyro_parser(args_type: type[Args], tool: str, description: Optional[str], prog: Optional[str] = None) -> Callable[[list[str]], Args]:
    """A ``parse`` for ``run_cli``: tyro on ``args_type``, its help headed by ``description`` (the tool's module
    docstring) and the ``--debug`` flag; ``prog`` (``mani-skill-space TOOL`` by default) is how its usage names it."""
    import tyro

    text = f"{(description or '').strip()}\n\n{DEBUG_HELP}"
    return lambda arguments: tyro.cli(args_type, args=arguments, prog=prog or f"{PROG} {tool}", description=text)


def parse_json_object(text: str, option: str) -> dict[str, Any]:
    """The JSON object ``text`` given to ``option``; a ``ValueError`` names the option when it is not valid JSON or
    not an object (e.g. ``'[1, 2]'``)."""
    try:
        value = json.loads(text)
    except json.JSONDecodeError as error:
        raise ValueError(f"{option} is not valid JSON ({error}): {text!r}") from None
    if not isinstance(value, dict):
        raise ValueError(f"{option} must be a JSON object such as '{{\"domain\": \"moon\"}}', got {type(value).__name__} {text!r}")
    return value


def check_at_least(name: str, value: Optional[int], minimum: int) -> None:
    """A ``ValueError`` naming the option when an integer option is below ``minimum`` (None passes)."""
    if value is not None and value < minimum:
        raise ValueError(f"{name} must be at least {minimum}, got {value}")
