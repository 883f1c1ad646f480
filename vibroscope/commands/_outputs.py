"""Output naming and atomic writing for the sub-commands.

Rules every command follows:

- Default outputs go to the current directory (or ``--out DIR``), named after the input and the
  command (:func:`default_output`: ``<stem>_<command><suffix>``), never beside the input.
- Every output is checked against every input before any work (:func:`check_outputs`): an
  output never overwrites an input.
- Every output is written under a temporary name in its own directory (``.<name>.tmp-<pid>``,
  the original suffix kept so that writers choosing a format by suffix still work) and moved
  into place (:func:`os.replace`) only when the whole command succeeded
  (:class:`AtomicOutputs`); on any exception or ``KeyboardInterrupt`` the temporaries are
  removed and earlier complete outputs stay as they were.
- Replacing an earlier output prints one line: ``replacing <path> (earlier output)``.
"""

from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path
from typing import Iterable, Mapping

from vibroscope.errors import VibroscopeError

__all__ = ["default_output", "same_file", "check_outputs", "check_out_dir", "AtomicOutputs", "TEMP_MARK"]

#: what every temporary name contains (``.<name>.tmp-<pid>``)
TEMP_MARK = ".tmp-"


def default_output(source: str | os.PathLike, command: str, suffix: str = "",
                   out_dir: str | os.PathLike | None = None) -> Path:
    """Default output path ``<out_dir>/<stem>_<command><suffix>``.

    Parameters
    ----------
    source : str or path-like
        The input the output is named after (its stem is used).
    command : str
        The sub-command, e.g. ``"analyse"``.
    suffix : str, optional
        E.g. ``".rrd"``, ``"_figures"``; default ``""``.
    out_dir : str or path-like, optional
        The folder; default the current directory.

    Returns
    -------
    Path
    """
    base = Path(out_dir) if out_dir is not None else Path.cwd()
    return base / f"{Path(source).stem}_{command}{suffix}"


def check_out_dir(out_dir: str | os.PathLike | None, option: str = "--out") -> None:
    """Refuse an output folder that exists as something else than a folder.

    Parameters
    ----------
    out_dir : str or path-like, optional
        The folder (None: the current directory, always fine).
    option : str, optional
        The option named in the message; default ``"--out"``.

    Raises
    ------
    VibroscopeError
        ``--out X is a file, not a folder``.
    """
    if out_dir is not None and os.path.exists(out_dir) and not os.path.isdir(out_dir):
        raise VibroscopeError(f"{option} {out_dir} is a file, not a folder")


def same_file(a: str | os.PathLike, b: str | os.PathLike) -> bool:
    """Whether two paths name the same file (same inode when both exist, else the same resolved path).

    Parameters
    ----------
    a, b : str or path-like
        The paths.

    Returns
    -------
    bool
    """
    try:
        if os.path.exists(a) and os.path.exists(b):
            return os.path.samefile(a, b)
    except OSError:
        pass
    try:
        return Path(a).resolve() == Path(b).resolve()
    except (OSError, RuntimeError, ValueError):
        return os.path.abspath(a) == os.path.abspath(b)


def check_outputs(outputs: Mapping[str, str | os.PathLike | None],
                  inputs: Mapping[str, str | os.PathLike | Iterable | None]) -> None:
    """Refuse before any work when an output is the same file as an input.

    Parameters
    ----------
    outputs : mapping
        Option (e.g. ``"--json"``) -> output path or None (not written).
    inputs : mapping
        What the input is (e.g. ``"log"``) -> input path, a list of paths, or None.

    Raises
    ------
    VibroscopeError
        ``--json X is the input log X: an output never overwrites an input``.
    """
    flat = []
    for what, p in inputs.items():
        if p is None:
            continue
        if isinstance(p, (str, os.PathLike)):
            flat.append((what, p))
        else:
            flat += [(what, q) for q in p if q is not None]
    for opt, o in outputs.items():
        if o is None:
            continue
        for what, i in flat:
            if same_file(o, i):
                raise VibroscopeError(f"{opt} {o} is the input {what} {i}: an output never overwrites an input")


def _temp_name(path: Path) -> Path:
    return path.parent / f".{path.stem}{TEMP_MARK}{os.getpid()}{path.suffix}"


class AtomicOutputs:
    """A set of outputs written under temporary names and moved into place together.

    Use as a context manager: :meth:`file` and :meth:`directory` return the temporary path to
    write to; on a clean exit every temporary replaces its final path (:meth:`commit`), on an
    exception (``KeyboardInterrupt`` included) every temporary is removed (:meth:`discard`) and
    the exception propagates.

    A figures directory replaces an earlier one whole when that one holds only PNG files (an
    earlier run's figures); otherwise (a folder with other files, such as ``.``) the new files
    are moved in one by one, so nothing else in it is removed.

    Parameters
    ----------
    inputs : iterable of path-like, optional
        Input files: an output that resolves to one of them is refused at commit (a second
        guard after :func:`check_outputs`).
    stream : file-like, optional
        Where the ``replacing <path> (earlier output)`` lines go; default ``sys.stdout``.
    """

    def __init__(self, inputs: Iterable[str | os.PathLike] = (), stream=None):
        self._inputs = [Path(p) for p in inputs if p is not None]
        self._stream = stream
        self._files: list[tuple[Path, Path]] = []  # (temp, final)
        self._dirs: list[tuple[Path, Path]] = []

    def __enter__(self) -> "AtomicOutputs":
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc_type is None:
            try:
                self.commit()
            except BaseException:
                self.discard()
                raise
        else:
            self.discard()
        return False

    def _guard(self, final: Path) -> None:
        for i in self._inputs:
            if same_file(final, i):
                raise VibroscopeError(f"output {final} is the input {i}: an output never overwrites an input")

    def file(self, path: str | os.PathLike) -> Path:
        """The temporary path to write the output file `path` to (its folder is created).

        Parameters
        ----------
        path : str or path-like
            The final output file.

        Returns
        -------
        Path
        """
        final = Path(path)
        self._guard(final)
        final.parent.mkdir(parents=True, exist_ok=True)
        tmp = _temp_name(final)
        self._files.append((tmp, final))
        return tmp

    def directory(self, path: str | os.PathLike) -> Path:
        """A fresh temporary folder to write the output folder `path` into.

        Parameters
        ----------
        path : str or path-like
            The final output folder.

        Returns
        -------
        Path
        """
        final = Path(path)
        self._guard(final)
        if final.exists() and not final.is_dir():
            raise VibroscopeError(f"{final} exists and is not a folder: cannot write figures there")
        final.parent.mkdir(parents=True, exist_ok=True)
        tmp = final.parent / f".{final.name}{TEMP_MARK}{os.getpid()}"
        if tmp.exists():
            shutil.rmtree(tmp)
        tmp.mkdir()
        self._dirs.append((tmp, final))
        return tmp

    def final(self, temp_path: str | os.PathLike) -> Path:
        """Where a path written under a temporary (file or inside a temporary folder) ends up.

        Parameters
        ----------
        temp_path : str or path-like
            A path returned by :meth:`file`, or inside a folder returned by :meth:`directory`.

        Returns
        -------
        Path
        """
        p = Path(temp_path)
        for tmp, fin in self._files + self._dirs:
            if p == tmp:
                return fin
            try:
                return fin / p.relative_to(tmp)
            except ValueError:
                continue
        return p

    def _say(self, path: Path) -> None:
        print(f"replacing {path} (earlier output)", file=self._stream or sys.stdout)

    def commit(self) -> None:
        """Move every temporary into place (files with :func:`os.replace`)."""
        for tmp, final in self._files:
            if not tmp.exists():  # the writer chose not to write (e.g. rerun missing)
                continue
            self._guard(final)
            if final.exists():
                self._say(final)
            os.replace(tmp, final)
        self._files = []
        for tmp, final in self._dirs:
            self._commit_dir(tmp, final)
        self._dirs = []

    def _commit_dir(self, tmp: Path, final: Path) -> None:
        if not final.exists():
            os.replace(tmp, final)
            return
        old = list(final.iterdir())
        self._say(final)
        if all(p.is_file() and p.suffix.lower() == ".png" for p in old) and not any(
                same_file(p, i) for p in old for i in self._inputs):
            aside = final.parent / f".{final.name}.old{TEMP_MARK}{os.getpid()}"
            os.replace(final, aside)
            os.replace(tmp, final)
            shutil.rmtree(aside, ignore_errors=True)
            return
        for p in sorted(tmp.iterdir()):
            dest = final / p.name
            self._guard(dest)
            os.replace(p, dest)
        shutil.rmtree(tmp, ignore_errors=True)

    def discard(self) -> None:
        """Remove every temporary (the final outputs are left as they were)."""
        for tmp, _ in self._files:
            try:
                tmp.unlink()
            except OSError:
                pass
        for tmp, _ in self._dirs:
            shutil.rmtree(tmp, ignore_errors=True)
        self._files, self._dirs = [], []
