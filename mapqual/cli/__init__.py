"""The `mapqual` command line: one typer app, one module per command group."""

from __future__ import annotations

import sys
import warnings

import typer
from pydantic import ValidationError

from worker.errors import InputError, InputWarning, SlamFailed

app = typer.Typer(
    rich_markup_mode=None,
    name="mapqual",
    help="Score how good a map a SLAM algorithm builds of a building.\n\n"
    "The manual: docs/ in the repository (docs/index.md; build it with `mkdocs build`), "
    "served at /manual/ by `mapqual serve`. `mapqual COMMAND --help` for one command.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)

# Each command module adds its commands to `app` on import. Heavy imports (numba kernels,
# matplotlib) stay inside the command functions so that `mapqual --help` starts fast.
# (command modules are imported here, one line each)
from mapqual.cli import batch as _batch  # noqa: E402,F401
from mapqual.cli import evaluate as _evaluate  # noqa: E402,F401
from mapqual.cli import export as _export  # noqa: E402,F401
from mapqual.cli import predict as _predict  # noqa: E402,F401
from mapqual.cli import problem as _problem  # noqa: E402,F401
from mapqual.cli import run as _run  # noqa: E402,F401
from mapqual.cli import runs as _runs  # noqa: E402,F401
from mapqual.cli import score as _score  # noqa: E402,F401
from mapqual.cli import service as _service  # noqa: E402,F401
from mapqual.cli import simulate as _simulate  # noqa: E402,F401
from mapqual.cli import slam as _slam  # noqa: E402,F401
from mapqual.cli import viewer as _viewer  # noqa: E402,F401
from mapqual.cli import world as _world  # noqa: E402,F401


def main() -> None:
    """Console entry point: bad input is one line on stderr and exit code 2, never a traceback."""
    warnings.showwarning = _show_warning
    try:
        app()
    except InputError as exc:
        print(f"mapqual: error: {exc}", file=sys.stderr)
        sys.exit(2)
    except ValidationError as exc:  # a setting from the environment (.env) that is invalid
        first = exc.errors()[0]
        where = ".".join(str(p) for p in first.get("loc", ())) or exc.title
        print(f"mapqual: error: setting {where}: {first['msg']}", file=sys.stderr)
        sys.exit(2)
    except SlamFailed as exc:  # an external SLAM program failed outside a run (mapqual slam)
        print(f"mapqual: error: {exc}", file=sys.stderr)
        sys.exit(1)
    except (BrokenPipeError, KeyboardInterrupt):
        sys.exit(130 if sys.exc_info()[0] is KeyboardInterrupt else 1)


_default_showwarning = warnings.showwarning


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """An InputWarning (a documented repair of the input) as one line on stderr."""
    if issubclass(category, InputWarning):
        print(f"mapqual: warning: {message}", file=sys.stderr)
    else:
        _default_showwarning(message, category, filename, lineno, file, line)
