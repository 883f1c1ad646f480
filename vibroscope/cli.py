"""The ``vibroscope`` command line: composes the package's rooms and holds no numerics.

Each sub-command lives in its own module under :mod:`vibroscope.commands` and exposes
``add_parser(subparsers)`` (which registers the sub-command and sets ``func``) .
"""

from __future__ import annotations

import argparse
import importlib
import sys

from vibroscope.errors import VibroscopeError

#: sub-command modules, in the order `vibroscope --help` lists them
COMMANDS = ("demo", "info", "analyse", "modal", "convert", "simulate", "compare", "gap")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every available sub-command registered."""
    parser = argparse.ArgumentParser(
        prog="vibroscope",
        description="Virtual Fourier analyser for vibration logs: spectra, FRFs, coherence, modal vectors.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        importlib.import_module(f"vibroscope.commands.{name}").add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``vibroscope`` console script; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except VibroscopeError as exc:
        print(f"vibroscope {args.command}: error: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
