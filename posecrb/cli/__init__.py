"""The ``posecrb`` command line: a thin click shell over the library.

Exceptions become exit codes in exactly one place (``main``):
0 ok; 1 data or solver error (file:line and reason); 2 usage error;
130 interrupted (SIGINT), 143 terminated (SIGTERM; temporaries are removed first).
Python warnings (numpy's RuntimeWarning included) never reach the user as raw text:
``main`` routes each through the posecrb logger as one line on stderr (filters such as
``-W error::RuntimeWarning`` still apply, which is how the tests prove none occurs); so are the
warnings other libraries log (matplotlib's about a read-only home directory, say). stdout and
stderr show a byte of a file name that is not valid UTF-8 as ``\\xNN`` (the output layer's
``posecrb-escape`` handler) in every locale, instead of failing.
Subcommands live in ``posecrb.cli.commands.<name>``, each module exposing a click command as
``command``; they are listed in ``COMMANDS`` and imported only when invoked, so ``posecrb --help``
loads neither numpy/scipy nor numba.
"""
from __future__ import annotations

import contextlib
import gc
import importlib
import logging
import os
import sys
import warnings
from collections.abc import Iterator
from typing import NoReturn, TextIO

import click

from .._version import __version__
from ..core.errors import ArgumentError, PosecrbError, UsageError
from ..core.outputs import ESCAPE, remove_temporaries
from .lazy_numpy import defer_unused_imports
from .signals import Terminated, handle_sigterm

log = logging.getLogger("posecrb")


class _StderrHandler(logging.Handler):
    def emit(self, record: logging.LogRecord) -> None:
        level = ("error" if record.levelno >= logging.ERROR else
                 "warning" if record.levelno >= logging.WARNING else "info")
        click.echo(f"posecrb: {level}: {record.getMessage()}", err=True)


class _LibraryLogHandler(logging.Handler):
    """Warnings other libraries log (to the root logger's handlers), as one posecrb line each."""

    def __init__(self) -> None:
        super().__init__(logging.WARNING)

    def emit(self, record: logging.LogRecord) -> None:
        if record.name == "posecrb" or record.name.startswith("posecrb."):
            return                                  # posecrb's own records have their handler
        log.warning("%s: %s", record.name.split(".")[0], " ".join(record.getMessage().split()))


@contextlib.contextmanager
def _routed_output() -> Iterator[None]:
    """While a command runs: other libraries' log warnings through posecrb's logger, and stdout and
    stderr escaping undecodable file-name bytes (module docstring); both undone afterwards."""
    handler = _LibraryLogHandler()
    root = logging.getLogger()
    root.addHandler(handler)
    restore = []
    for stream in (sys.stdout, sys.stderr):
        errors, reconfigure = getattr(stream, "errors", None), getattr(stream, "reconfigure", None)
        if errors is not None and reconfigure is not None:
            with contextlib.suppress(ValueError, OSError):
                reconfigure(errors=ESCAPE)
                restore.append((reconfigure, errors))
    try:
        yield
    finally:
        root.removeHandler(handler)
        for reconfigure, errors in restore:
            with contextlib.suppress(ValueError, OSError):
                reconfigure(errors=errors)


def _configure_logging(verbose: int, quiet: bool) -> None:
    logger = logging.getLogger("posecrb")
    logger.handlers[:] = [_StderrHandler()]
    logger.setLevel(logging.ERROR if quiet else logging.DEBUG if verbose > 1 else
                    logging.INFO if verbose else logging.WARNING)


# The command table: name -> (module under posecrb.cli.commands, short help shown by `posecrb --help`).
# `posecrb --help` lists commands from this table without importing any command module (start-up
# time: the command modules import scipy, sksparse and numba); tests/cli/test_lazy_commands.py checks that
# every entry matches its command's own help.
COMMANDS: dict[str, tuple[str, str]] = {
    "bounds": ("bounds", "D-optimality of each FILE: FIM log-det at an estimate and its graph-only bounds (one "
                         "Table I/II row per file)."),
    "crlb": ("crlb", "Cramér-Rao lower bound of FILE at an estimate: exact trace, MSE bound, per-pose blocks."),
    "datasets": ("datasets", "Dataset manifest, lookup, download (verified) and synthetic graphs."),
    "experiment": ("experiment", "The paper's and the thesis's experiments (Monte Carlo CRLB, T- vs D-optimality, "
                                 "thesis ch. 6)."),
    "fim": ("fim", "Fisher information matrix of FILE at an estimate: size, nnz, log-det, trace, rank."),
    "info": ("info", "Describe pose-graph FILE(s): format, dimension, sizes, connectivity, degrees, noise ranges."),
    "regress": ("regress", "Recompute lb, ub, ub_lambda (tolerance 1e-9 relative) and fim_logdet, objective, "
                           "trace_crlb at the certified optimum (1e-6; from the model's Fisher information, "
                           "fim_variant=consistent, recorded in the file) and compare them with the expected file."),
    "select": ("select", "Measurement selection: keep K edges, D-optimal, with a certificate."),
    "solve": ("solve", "Certifiably correct pose-graph optimisation of FILE (SE-Sync's Riemannian staircase)."),
    "tables": ("tables", "Rebuild the paper's Tables I-IV: FIM log-det at the certified optimum, ub and lb with "
                         "their times (I/II) and the construction time of the whole FIM vs the weighted Laplacians "
                         "(III/IV)."),
    "timeline": ("timeline", "D- and T-optimality of every prefix of FILE as the graph grows: lb, ub, t_opt_graph "
                             "and the FIM log-det per step, computed incrementally, and the gain of every loop "
                             "closure."),
    "verify": ("verify", "Is an estimate another program computed the global optimum? Certificate, basin and "
                         "distances to the certified optimum."),
}


class LazyGroup(click.Group):
    """A click group whose subcommands come from ``COMMANDS`` and are imported on first use."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(COMMANDS)

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        if cmd_name not in COMMANDS:
            return None
        module = importlib.import_module(f"{__name__}.commands.{COMMANDS[cmd_name][0]}")
        command: click.Command = module.command
        return command

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        """The "Commands" section from the table (as click renders it), without importing any command."""
        limit = formatter.width - 6 - max(len(name) for name in COMMANDS)
        rows = [(name, _short_help(name, limit)) for name in sorted(COMMANDS)]
        with formatter.section("Commands"):
            formatter.write_dl(rows)


def _short_help(name: str, limit: int) -> str:
    """click's short help: the explicit ``short_help`` whole, else the help's first sentence cut at limit.

    Computed by click's own public ``Command.get_short_help_str`` on a stand-in command, so the
    listing matches what click renders for the real command without importing it."""
    text = COMMANDS[name][1]
    stand_in = (click.Command(name, short_help=text) if name in _EXPLICIT_SHORT_HELP
                else click.Command(name, help=text))
    return stand_in.get_short_help_str(limit)


_EXPLICIT_SHORT_HELP = {"select", "verify"}   # commands declared with short_help= (shown whole, wrapped)


# Named by `posecrb --version`, so a user (and `make`) can tell which checkout or install runs.
_PACKAGE_DIR = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(__version__, prog_name="posecrb",
                      message=f"%(prog)s %(version)s from {_PACKAGE_DIR} "
                              f"(Python {sys.version.split()[0]}, {sys.executable})")
@click.option("-v", "--verbose", count=True, help="More log output on stderr (-vv for debug).")
@click.option("-q", "--quiet", is_flag=True, help="Only errors on stderr.")
@click.option("--strict", is_flag=True,
              help="A dataset name whose file fails the manifest's checksum is an error, not a warning.")
@click.pass_context
def cli(ctx: click.Context, verbose: int, quiet: bool, strict: bool) -> None:
    """Fisher information, Cramér-Rao bounds and D-optimality bounds for pose-graph SLAM.

    FILE arguments take a path to a g2o or TORO file, or a bare dataset name
    (e.g. `intel`) looked up in --data-dir, $POSECRB_DATA, ./datasets and
    ~/.cache/posecrb. Results go to stdout, logs and warnings to stderr.
    Exit codes: 0 ok, 1 data or solver error, 2 usage error.
    """
    from ..datasets.search import strict_checksums  # noqa: PLC0415 -- only once a command runs

    _configure_logging(verbose, quiet)
    ctx.with_resource(strict_checksums(strict))


def _warning_origin(filename: str) -> str:
    """``posecrb.models.paper.fim`` for a file of this package; the file's base name otherwise
    (by location, not by name: a checkout directory may itself be called ``posecrb``)."""
    path = os.path.normpath(os.path.abspath(filename))
    if path.startswith(_PACKAGE_DIR + os.sep):
        mod = "posecrb." + os.path.relpath(path, _PACKAGE_DIR).replace(os.sep, ".")
        return mod[:-3] if mod.endswith(".py") else mod
    return os.path.basename(filename)


def _route_warning(message: Warning | str, category: type[Warning], filename: str, lineno: int,
                   file: TextIO | None = None, line: str | None = None) -> None:
    """warnings.showwarning replacement: one line through the posecrb logger, no source line."""
    text = " ".join(str(message).split())
    origin = _warning_origin(filename)
    if issubclass(category, RuntimeWarning):
        log.warning("numerical problem in %s (%s); results may be inaccurate", origin, text)
    else:
        log.warning("%s from %s: %s", category.__name__, origin, text)


def main(argv: list[str] | None = None) -> int:
    """Entry point: run the CLI and map every exception to an exit code."""
    defer_unused_imports()
    with warnings.catch_warnings(), handle_sigterm(), _routed_output():
        warnings.showwarning = _route_warning      # restored by catch_warnings on exit
        try:
            return _main(argv)
        finally:
            remove_temporaries()


def run() -> NoReturn:
    """The program's entry point (the ``posecrb`` command, ``python -m posecrb``): ``main`` on the
    command line, then the process exits with its code.

    Before the exit every object still alive moves to the collector's permanent generation
    (``gc.freeze``): the interpreter's shutdown runs full collections over all of them, and after a
    command that used the compiled kernels (numba) those are numba's typing and lowering registries,
    hundreds of thousands of objects walked several times over for nothing. Frozen objects are still
    freed by reference counting; the output was written and flushed by then, and nothing of posecrb's
    waits for a collection at exit (docs/decisions/fixed-costs.md)."""
    code = main()
    gc.freeze()
    sys.exit(code)


def _main(argv: list[str] | None) -> int:
    try:
        cli.main(args=argv, prog_name="posecrb", standalone_mode=False)
    except click.exceptions.Exit as exc:
        return int(exc.exit_code or 0)
    except click.UsageError as exc:
        exc.show()
        return 2
    except UsageError as exc:   # a library ArgumentError is shown with the option's name
        click.echo(f"posecrb: usage error: {exc.cli_message() if isinstance(exc, ArgumentError) else exc}", err=True)
        return 2
    except click.Abort as exc:
        # click turns KeyboardInterrupt into Abort
        if isinstance(exc.__cause__ or exc.__context__, KeyboardInterrupt):
            click.echo("posecrb: interrupted", err=True)
            return 130
        click.echo("posecrb: aborted", err=True)
        return 1
    except PosecrbError as exc:
        click.echo(f"posecrb: error: {exc}", err=True)
        return 1
    except KeyboardInterrupt:
        click.echo("posecrb: interrupted", err=True)
        return 130
    except Terminated as exc:
        click.echo(f"posecrb: terminated (signal {exc.signum}); partial output removed", err=True)
        return 128 + int(exc.signum)
    except BrokenPipeError:
        # Output piped into `head` and friends: not an error of ours.
        sys.stderr.close()
        return 0
    except Exception as exc:  # a bug: say so without a traceback unless asked
        if os.environ.get("POSECRB_DEBUG"):
            raise
        click.echo(f"posecrb: internal error: {type(exc).__name__}: {exc} "
                   "(a bug in posecrb: please report it; set POSECRB_DEBUG=1 for a traceback)", err=True)
        return 1
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
