"""The console entry point: run the command group, map errors to exit codes and one line."""

from __future__ import annotations

import errno
import os
import signal
import sys
import traceback

import click

from vid2sim.base.errors import InputError, Terminated
from vid2sim.base.fileio import OUTPUT_ERRNOS
from vid2sim.cli.group import cli

# --------------------------------------------------------------------------- entry point


def _on_termination(signum: int, _frame) -> None:
    # Once only: a second signal must not cut the cleanup that the first one starts short.
    signal.signal(signum, signal.SIG_IGN)
    raise Terminated(signum)


def _termination_signals() -> list[int]:
    """SIGTERM (kill, batch schedulers, systemd) and SIGHUP (terminal closed): handled as
    Ctrl-C is, so no staging folder or temporary file stays behind."""
    return [s for s in (getattr(signal, "SIGTERM", None), getattr(signal, "SIGHUP", None))
            if s is not None]


#: errno values that say an input is unreadable for a reason the user must fix.
_INPUT_ERRNOS = frozenset({errno.ENOENT, errno.EISDIR, errno.ENOTDIR, errno.ELOOP,
                           errno.ENAMETOOLONG})


def _os_error_line(exc: OSError) -> str | None:
    """One line for an OSError that is the user's to fix (a read-only or full output, an
    unreadable input); None for any other (an internal error)."""
    name = exc.filename if exc.filename is not None else None
    what = exc.strerror or str(exc)
    if exc.errno in OUTPUT_ERRNOS:
        hint = ("free some space or write elsewhere" if exc.errno in
                (errno.ENOSPC, errno.EDQUOT, errno.EFBIG) else "check the permissions")
    elif exc.errno in _INPUT_ERRNOS:
        hint = "check the path"
    else:
        return None
    return f"error: {name + ': ' if name else ''}{what} ({hint})"


def main(argv: list[str] | None = None) -> int:
    """Console entry point: maps errors to exit codes.

    0 success; 2 bad input, usage, or an output location the user must fix (read-only,
    full); 130 / 143 interrupted by SIGINT / SIGTERM (outputs as before the run); 1 an
    internal error.
    """
    verbose = any(a in ("-v", "--verbose") or (a.startswith("-v") and set(a[1:]) == {"v"})
                  for a in (argv if argv is not None else sys.argv[1:]))
    if not verbose:
        # FFmpeg inside OpenCV prints its own lines for a broken video ("moov atom not
        # found"); our one-line error says the same with the file name. -v shows them.
        os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")
        # and OpenCV's own log ("Could not find decoder for codec_id=0") likewise; it read
        # its environment when imported, so it is told directly.
        import cv2

        cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    previous = {}
    try:
        for s in _termination_signals():
            previous[s] = signal.signal(s, _on_termination)
    except ValueError:  # not the main thread (an embedding application): its own business
        previous = {}
    try:
        return _run(argv, verbose)
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


def _run(argv: list[str] | None, verbose: bool) -> int:
    try:
        # A command that calls ctx.exit(code) (batch: 1 when a row failed) comes back
        # here as click's return value in non-standalone mode.
        rv = cli.main(args=argv, prog_name="vid2sim", standalone_mode=False)
    except InputError as exc:
        click.echo(f"error: {exc}", err=True)
        if verbose:
            traceback.print_exc()
        return 2
    except click.exceptions.Exit as exc:
        return int(exc.exit_code or 0)
    except click.ClickException as exc:
        exc.show()
        return 2
    except (click.exceptions.Abort, KeyboardInterrupt) as exc:
        # click turns Ctrl-C (and our SIGTERM, a KeyboardInterrupt) into Abort.
        cause = exc if isinstance(exc, KeyboardInterrupt) else (exc.__cause__ or exc.__context__)
        if isinstance(cause, Terminated):
            click.echo(f"terminated by signal {cause.signum}; outputs left as they were",
                       err=True)
            return 128 + cause.signum
        click.echo("interrupted; outputs left as they were" if cause is not None else "aborted",
                   err=True)
        return 130
    except BrokenPipeError:
        return 0
    except RecursionError:
        # json, yaml and XML parsers recurse per nesting level; readers turn this into an
        # error naming their file, this is the last line for one that does not.
        click.echo("error: an input is nested too deeply to read (run with -v to see where)",
                   err=True)
        if verbose:
            traceback.print_exc()
        return 2
    except MemoryError:
        click.echo("error: out of memory: an input is too large for this machine (see "
                   "docs/limits.md)", err=True)
        return 2
    except OSError as exc:
        line = _os_error_line(exc)
        if line is None:
            return _internal_error(exc, verbose)
        click.echo(line, err=True)
        if verbose:
            traceback.print_exc()
        return 2
    except Exception as exc:  # noqa: BLE001 - the last line of defence for internal errors
        return _internal_error(exc, verbose)
    return rv if isinstance(rv, int) else 0


def _internal_error(exc: BaseException, verbose: bool) -> int:
    click.echo(f"internal error: {type(exc).__name__}: {exc} (run with -v for the traceback; "
               "please report it)", err=True)
    if verbose:
        traceback.print_exc()
    return 1


def entry_point() -> None:
    """The ``vid2sim`` console script."""
    sys.exit(main())
