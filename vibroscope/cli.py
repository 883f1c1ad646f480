"""The ``vibroscope`` command line: composes the package's rooms and holds no numerics.

Each sub-command lives in its own module under :mod:`vibroscope.commands` and exposes
``add_parser(subparsers)`` (which registers the sub-command and sets ``func``).

Every problem is reported on one line of stderr, ``vibroscope CMD: error: MESSAGE``, with exit
status 1: a :class:`~vibroscope.errors.VibroscopeError` by its message, any other exception by
its type name and message followed by ``(run with --debug for the traceback)``. Python warnings
raised during a command print as ``vibroscope CMD: warning: MESSAGE`` (each message once);
Ctrl-C prints ``vibroscope CMD: interrupted`` and exits with 130; SIGTERM prints ``vibroscope
CMD: terminated`` and exits with 143, after the same clean-up (no temporary output is left). A
closed output pipe (``vibroscope info LOG | head``) ends the command quietly with 141.
``--debug`` (before or after the sub-command) shows the traceback instead. argparse's own usage
errors exit with 2.
"""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
import threading
import traceback
import warnings

from vibroscope.errors import VibroscopeError

#: sub-command modules, in the order `vibroscope --help` lists them
COMMANDS = ("demo", "info", "analyse", "modal", "convert", "simulate", "compare", "gap")

#: exit status after Ctrl-C (128 + SIGINT)
EXIT_INTERRUPTED = 130

#: exit status after SIGTERM (128 + SIGTERM)
EXIT_TERMINATED = 143

#: exit status when the reader of the output went away (128 + SIGPIPE), e.g. ``| head``
EXIT_BROKEN_PIPE = 141


class Terminated(BaseException):
    """Raised in the main thread by SIGTERM during a command, so that its clean-up runs (a
    ``BaseException`` like ``KeyboardInterrupt``: no ``except Exception`` swallows it)."""


def _raise_terminated(signum, frame):
    raise Terminated()


def _quiet_stdout() -> None:
    """Point stdout at /dev/null after its reader went away (no second error at exit)."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):
        pass


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every available sub-command registered."""
    parser = argparse.ArgumentParser(
        prog="vibroscope",
        description="Virtual Fourier analyser for vibration logs: spectra, FRFs, coherence, modal vectors.",
    )
    parser.add_argument("--debug", action="store_true",
                        help="show the full traceback of an error (also accepted after the sub-command)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        importlib.import_module(f"vibroscope.commands.{name}").add_parser(sub)
    return parser


def _split_debug(argv: list[str]) -> tuple[list[str], bool]:
    """`argv` without its ``--debug`` flags (anywhere before a ``--``), and whether one was given."""
    out, debug, literal = [], False, False
    for a in argv:
        if not literal and a == "--debug":
            debug = True
            continue
        if a == "--":
            literal = True
        out.append(a)
    return out, debug


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def _describe(exc: BaseException) -> str:
    """One line for an unexpected exception: its type name and message."""
    msg = _one_line(str(exc))
    return f"{type(exc).__name__}: {msg}" if msg else type(exc).__name__


def run_command(func, args, command: str, *, debug: bool = False, stream=None) -> int:
    """Run a sub-command's function with the command line's error, warning and interrupt handling.

    Parameters
    ----------
    func : callable
        The sub-command's ``run(args)``; returns the exit status (None is 0).
    args : argparse.Namespace
        The parsed command line, passed to `func`.
    command : str
        The sub-command's name, used in the messages.
    debug : bool, optional
        Re-raise errors (full traceback) instead of the one-line report; default False.
    stream : file-like, optional
        Where errors and warnings go; default ``sys.stderr`` at call time.

    Returns
    -------
    int
        `func`'s status; 1 after an error, 130 after ``KeyboardInterrupt``, 143 after SIGTERM, 141
        when stdout's reader went away (``BrokenPipeError``).
    """
    err = stream or sys.stderr
    prefix = f"vibroscope {command}"
    seen: set[str] = set()

    def show(message, category, filename, lineno, file=None, line=None):
        text = _one_line(str(message))
        if text not in seen:
            seen.add(text)
            print(f"{prefix}: warning: {text}", file=err, flush=True)

    old_term = None
    if threading.current_thread() is threading.main_thread():
        old_term = signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        with warnings.catch_warnings():
            warnings.showwarning = show
            status = int(func(args) or 0)
        sys.stdout.flush()  # a closed pipe shows here, not at exit
        return status
    except KeyboardInterrupt:
        if debug:
            traceback.print_exc(file=err)
        print(f"{prefix}: interrupted", file=err, flush=True)
        return EXIT_INTERRUPTED
    except Terminated:
        print(f"{prefix}: terminated", file=err, flush=True)
        return EXIT_TERMINATED
    except BrokenPipeError:
        _quiet_stdout()
        return EXIT_BROKEN_PIPE
    except SystemExit:
        raise
    except VibroscopeError as exc:
        if debug:
            raise
        print(f"{prefix}: error: {_one_line(str(exc))}", file=err, flush=True)
        return 1
    except Exception as exc:  # noqa: BLE001 - the command line reports every fault in one line
        if debug:
            raise
        print(f"{prefix}: error: {_describe(exc)} (run with --debug for the traceback)", file=err, flush=True)
        return 1
    finally:
        if old_term is not None:
            signal.signal(signal.SIGTERM, old_term)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``vibroscope`` console script; returns the exit status.

    Parameters
    ----------
    argv : list of str, optional
        The arguments after the program name; default ``sys.argv[1:]``.
    """
    argv, debug = _split_debug(list(sys.argv[1:] if argv is None else argv))
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
    except KeyboardInterrupt:
        print("vibroscope: interrupted", file=sys.stderr, flush=True)
        return EXIT_INTERRUPTED
    except BrokenPipeError:  # `vibroscope --help | head`
        _quiet_stdout()
        return EXIT_BROKEN_PIPE
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    return run_command(args.func, args, args.command, debug=debug or args.debug)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
