"""The ``posecrb`` command line: a thin click shell over the library.

Exceptions become exit codes in exactly one place (``main``):
0 ok; 1 data or solver error (file:line and reason); 2 usage error;
130 interrupted (SIGINT), 143 terminated (SIGTERM; temporaries are removed first).
Python warnings (numpy's RuntimeWarning included) never reach the user as raw text:
``main`` routes each through the posecrb logger as one line on stderr (filters such as
``-W error::RuntimeWarning`` still apply, which is how the tests prove none occurs).
Subcommands live in ``posecrb.commands.<name>`` and are discovered
automatically; each module exposes a click command as ``command``.
"""
from __future__ import annotations

import importlib
import logging
import os
import pkgutil
import sys
import warnings

import click

from . import __version__
from .errors import PosecrbError, UsageError
from .io.files import Terminated, handle_sigterm, remove_temporaries

log = logging.getLogger("posecrb")


class _StderrHandler(logging.Handler):
    def emit(self, record: logging.LogRecord) -> None:
        level = ("error" if record.levelno >= logging.ERROR else
                 "warning" if record.levelno >= logging.WARNING else "info")
        click.echo(f"posecrb: {level}: {record.getMessage()}", err=True)


def _configure_logging(verbose: int, quiet: bool) -> None:
    logger = logging.getLogger("posecrb")
    logger.handlers[:] = [_StderrHandler()]
    logger.setLevel(logging.ERROR if quiet else logging.DEBUG if verbose > 1 else
                    logging.INFO if verbose else logging.WARNING)


@click.group(context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(__version__, prog_name="posecrb",
                      message=f"%(prog)s %(version)s from {os.path.dirname(os.path.abspath(__file__))} "
                              f"(Python {sys.version.split()[0]}, {sys.executable})")
@click.option("-v", "--verbose", count=True, help="More log output on stderr (-vv for debug).")
@click.option("-q", "--quiet", is_flag=True, help="Only errors on stderr.")
def cli(verbose: int, quiet: bool) -> None:
    """Fisher information, Cramér-Rao bounds and D-optimality bounds for pose-graph SLAM.

    FILE arguments take a path to a g2o or TORO file, or a bare dataset name
    (e.g. `intel`) looked up in --data-dir, $POSECRB_DATA, ./datasets,
    ../shared/datasets and ~/.cache/posecrb. Results go to stdout, logs and
    warnings to stderr. Exit codes: 0 ok, 1 data or solver error, 2 usage error.
    """
    _configure_logging(verbose, quiet)


def _register_commands() -> None:
    from . import commands

    for mod in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        if mod.name.startswith("_"):
            continue
        module = importlib.import_module(f"{commands.__name__}.{mod.name}")
        command = getattr(module, "command", None)
        if isinstance(command, click.Command):
            cli.add_command(command)


_register_commands()


def _warning_origin(filename: str) -> str:
    """``posecrb.fim`` for .../posecrb/fim.py; the file's base name otherwise."""
    parts = os.path.normpath(filename).split(os.sep)
    if "posecrb" in parts:
        k = len(parts) - 1 - parts[::-1].index("posecrb")
        mod = ".".join(parts[k:])
        return mod[:-3] if mod.endswith(".py") else mod
    return os.path.basename(filename)


def _route_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """warnings.showwarning replacement: one line through the posecrb logger, no source line."""
    text = " ".join(str(message).split())
    origin = _warning_origin(filename)
    if issubclass(category, RuntimeWarning):
        log.warning("numerical problem in %s (%s); results may be inaccurate", origin, text)
    else:
        log.warning("%s from %s: %s", category.__name__, origin, text)


def main(argv: list[str] | None = None) -> int:
    """Entry point: run the CLI and map every exception to an exit code."""
    with warnings.catch_warnings(), handle_sigterm():
        warnings.showwarning = _route_warning      # restored by catch_warnings on exit
        try:
            return _main(argv)
        finally:
            remove_temporaries()


def _main(argv: list[str] | None) -> int:
    try:
        cli.main(args=argv, prog_name="posecrb", standalone_mode=False)
    except click.exceptions.Exit as exc:
        return int(exc.exit_code or 0)
    except click.UsageError as exc:
        exc.show()
        return 2
    except UsageError as exc:
        click.echo(f"posecrb: usage error: {exc}", err=True)
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
                   "(set POSECRB_DEBUG=1 for a traceback)", err=True)
        return 1
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
