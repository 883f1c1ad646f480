"""Output naming and atomic writing for the sub-commands.

Rules every command follows:

- Default outputs go to the current directory (or ``--out DIR``), named after the input and the
  command (:func:`default_output`: ``<stem>_<command><suffix>``), never beside the input.
- Every output is checked before any work (:func:`check_outputs`, :func:`check_out_dir`): an
  output never overwrites an input; an existing output path must be a regular file that
  vibroscope wrote (:func:`vibroscope.provenance.written_by_vibroscope`; a folder for a figures
  folder, whose existing PNG files must be vibroscope's): a symbolic link, FIFO, socket, device
  node or a file vibroscope did not write is refused, named (only an earlier run's outputs are
  ever replaced); the folder it goes into must be writable (probed with a temporary file, so a
  read-only file system is found too).
- Relative output paths given with ``--out DIR`` are taken inside ``DIR``
  (:func:`resolve_outputs`).
- Every output is written under a temporary name in its own directory (``.<name>.tmp-<pid>``,
  the original suffix kept so that writers choosing a format by suffix still work) and moved
  into place (:func:`os.replace`) only when the whole command succeeded
  (:class:`AtomicOutputs`); on any exception or ``KeyboardInterrupt`` the temporaries are
  removed and earlier complete outputs stay as they were. The outputs of one command appear
  together or not at all: Ctrl-C or SIGTERM during the moves is held until they are done, and a
  failed move puts back the earlier outputs already replaced.
- Replacing an earlier output prints one line: ``replacing <path> (earlier output)``.
- What vibroscope wrote is recognised by the mark each format carries
  (:mod:`vibroscope.provenance`): an MCAP's writer library, an RRD's application id, a PNG's
  ``Software`` text, a JSON report's first key ``generator``, a TOML's first comment line, a
  Universal File's dataset 151.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import stat
import sys
import tempfile
import threading
from pathlib import Path
from typing import Iterable, Mapping

from vibroscope.errors import VibroscopeError
from vibroscope.provenance import written_by_vibroscope

__all__ = ["default_output", "same_file", "check_outputs", "check_out_dir", "check_writable", "special_kind",
           "check_ours", "resolve_outputs", "AtomicOutputs", "TEMP_MARK", "FOLDER_OPTIONS", "FIGURE_SUFFIX",
           "preload_outputs", "preloaded"]

#: what every temporary name contains (``.<name>.tmp-<pid>``)
TEMP_MARK = ".tmp-"

#: options of :func:`check_outputs` whose output is a folder by default (every other one names a file)
FOLDER_OPTIONS = ("--figures",)

#: what a figures folder holds (the only files of an existing folder that a command may replace)
FIGURE_SUFFIX = ".png"


def check_ours(path: str | os.PathLike, option: str = "output") -> None:
    """Refuse an existing output file that vibroscope did not write.

    Parameters
    ----------
    path : str or path-like
        The output file; nothing there passes.
    option : str, optional
        The option named in the message, e.g. ``"--json"``; default ``"output"``.

    Raises
    ------
    VibroscopeError
        ``--json X: not written by vibroscope: X; remove it or choose another path`` (also for
        a link, FIFO, device or folder there: :func:`special_kind` names those first).
    """
    if not os.path.lexists(path):
        return
    kind = special_kind(path)
    if kind is not None:
        raise VibroscopeError(f"{option}: {path} is {kind}: only vibroscope's own earlier outputs are replaced; "
                              f"give another path")
    if os.path.isdir(path):
        raise VibroscopeError(f"{option}: {path} is a folder: give a file name")
    if not written_by_vibroscope(path):
        raise VibroscopeError(f"{option}: not written by vibroscope: {path}; remove it or choose another path "
                              f"(only vibroscope's own earlier outputs are replaced)")


def _check_folder(folder: str | os.PathLike, option: str) -> None:
    """Refuse an existing figures folder holding a figure file (``*.png``) that vibroscope did not write
    (or a link, FIFO, device or folder of that name): a run could replace it."""
    if not os.path.isdir(folder):
        return
    try:
        names = sorted(os.listdir(folder))
    except OSError as exc:
        raise VibroscopeError(f"{option} {folder}: cannot list it ({exc.strerror or exc})") from None
    for name in names:
        if name.lower().endswith(FIGURE_SUFFIX):
            check_ours(Path(folder) / name, f"{option} {folder}")


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


def special_kind(path: str | os.PathLike) -> str | None:
    """What `path` is when it is something else than a regular file or a folder, else None.

    The path itself is looked at (:func:`os.lstat`): a symbolic link is a link whatever it
    points to.

    Parameters
    ----------
    path : str or path-like
        The path.

    Returns
    -------
    str or None
        ``"a symbolic link"``, ``"a FIFO"``, ``"a socket"``, ``"a character device"``,
        ``"a block device"``, ``"a special file"``; None for a regular file, a folder, or
        nothing there.
    """
    try:
        mode = os.lstat(path).st_mode
    except (OSError, ValueError):
        return None
    for test, name in ((stat.S_ISLNK, "a symbolic link"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISSOCK, "a socket"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device")):
        if test(mode):
            return name
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
        return None
    return "a special file"


def _existing_ancestor(path: Path) -> Path:
    """The nearest existing folder at or above `path` (what would hold it once created)."""
    p = Path(os.path.abspath(path))
    while not p.exists() and p.parent != p:
        p = p.parent
    return p


def check_writable(folder: str | os.PathLike, option: str) -> None:
    """Refuse, before any work, an output folder that cannot be written.

    The folder (or, when it does not exist yet, the nearest existing folder above it, in which it
    would be created) is probed by creating and removing a temporary file, which finds a
    read-only file system, missing permissions and paths under a file alike.

    Parameters
    ----------
    folder : str or path-like
        The folder an output goes into.
    option : str
        The option named in the message, e.g. ``"--json out/s.json"``.

    Raises
    ------
    VibroscopeError
        ``--out /ro: cannot write in /ro (read-only file system)``.
    """
    where = _existing_ancestor(Path(folder))
    if not where.is_dir():
        raise VibroscopeError(f"{option}: cannot create a folder under {where}: it is not a folder")
    with _held_signals():  # a Ctrl-C here never leaves the probe behind
        try:
            fd, probe = tempfile.mkstemp(prefix=f".vibroscope-probe-{os.getpid()}-", dir=where)
        except OSError as exc:
            raise VibroscopeError(f"{option}: cannot write in {where} ({exc.strerror or exc})") from None
        os.close(fd)
        os.unlink(probe)


def check_out_dir(out_dir: str | os.PathLike | None, option: str = "--out") -> None:
    """Refuse, before any work, an output folder that is not a folder or cannot be written.

    Parameters
    ----------
    out_dir : str or path-like, optional
        The folder (None: the current directory, probed by :func:`check_outputs` with each output
        that goes there).
    option : str, optional
        The option named in the message; default ``"--out"``.

    Raises
    ------
    VibroscopeError
        ``--out X is a file, not a folder``; ``--out X is a FIFO, not a folder``; ``--out X:
        cannot write in X (Permission denied)``.
    """
    if out_dir is not None and os.path.exists(out_dir) and not os.path.isdir(out_dir):
        kind = special_kind(out_dir) or "a file"
        raise VibroscopeError(f"{option} {out_dir} is {kind}, not a folder")
    if out_dir is not None:  # (the current directory is probed with each output that goes there)
        check_writable(out_dir, f"{option} {out_dir}")


def resolve_outputs(args, options: Iterable[str], out_dir: str | os.PathLike | None) -> None:
    """Take relative output paths inside ``--out DIR``: ``--out res --json s.json`` writes ``res/s.json``.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line; the attributes named in `options` are replaced in place.
    options : iterable of str
        Attribute names of output paths (e.g. ``"json"``, ``"rrd"``, ``"figures"``).
    out_dir : str or path-like, optional
        ``--out``; None leaves every path as given (relative to the current directory).
    """
    if out_dir is None:
        return
    for name in options:
        v = getattr(args, name, None)
        if v is not None and not os.path.isabs(v):
            setattr(args, name, Path(out_dir) / v)


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
                  inputs: Mapping[str, str | os.PathLike | Iterable | None],
                  folders: Iterable[str] = FOLDER_OPTIONS) -> None:
    """Refuse before any work an output that is an input, is not a regular file, or cannot be written.

    Parameters
    ----------
    outputs : mapping
        Option (e.g. ``"--json"``) -> output path or None (not written).
    inputs : mapping
        What the input is (e.g. ``"log"``) -> input path, a list of paths, or None.
    folders : iterable of str, optional
        The options of `outputs` that name a folder (default :data:`FOLDER_OPTIONS`); every
        other one names a file.

    Raises
    ------
    VibroscopeError
        ``--json X is the input log X: an output never overwrites an input``; ``--json X is a
        FIFO: only vibroscope's own earlier outputs are replaced``; ``--json X: not written by
        vibroscope: X; remove it or choose another path``; ``--json X is a folder``; ``--rrd X:
        cannot write in D (Permission denied)``; a figures folder holding a PNG file that
        vibroscope did not write, named.
    """
    flat = []
    for what, p in inputs.items():
        if p is None:
            continue
        if isinstance(p, (str, os.PathLike)):
            flat.append((what, p))
        else:
            flat += [(what, q) for q in p if q is not None]
    folders = set(folders)
    for opt, o in outputs.items():
        if o is None:
            continue
        for what, i in flat:
            if same_file(o, i):
                raise VibroscopeError(f"{opt} {o} is the input {what} {i}: an output never overwrites an input")
        kind = special_kind(o)
        if kind is not None:
            raise VibroscopeError(f"{opt} {o} is {kind}: only vibroscope's own earlier outputs are replaced; "
                                  f"give another path")
        if opt in folders:
            if os.path.exists(o) and not os.path.isdir(o):
                raise VibroscopeError(f"{opt} {o} is a file, not a folder")
            _check_folder(o, opt)
            check_writable(o, f"{opt} {o}")
        else:
            if os.path.isdir(o):
                raise VibroscopeError(f"{opt} {o} is a folder: give a file name")
            check_ours(o, opt)
            check_writable(Path(o).parent, f"{opt} {o}")


@contextlib.contextmanager
def _held_signals():
    """Hold SIGINT and SIGTERM for the duration (main thread only); deliver them on exit.

    A signal that arrives inside is recorded; on exit the original handlers are restored and the
    first recorded signal is handed to its handler (``KeyboardInterrupt`` for Ctrl-C).
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    got: list[int] = []
    old = {}
    for sig in (signal.SIGINT, signal.SIGTERM):
        try:
            old[sig] = signal.signal(sig, lambda s, f: got.append(s))
        except (ValueError, OSError):  # pragma: no cover - not settable here
            pass
    try:
        yield
    finally:
        for sig, h in old.items():
            signal.signal(sig, h)
        if got:
            h = old.get(got[0])
            if callable(h):
                h(got[0], None)
            elif got[0] == signal.SIGINT and h != signal.SIG_IGN:
                raise KeyboardInterrupt
            elif h == signal.SIG_DFL:
                os.kill(os.getpid(), got[0])


def _temp_name(path: Path) -> Path:
    return path.parent / f".{path.stem}{TEMP_MARK}{os.getpid()}{path.suffix}"


class AtomicOutputs:
    """A set of outputs written under temporary names and moved into place together.

    Use as a context manager: :meth:`file` and :meth:`directory` return the temporary path to
    write to; on a clean exit every temporary replaces its final path (:meth:`commit`), on an
    exception (``KeyboardInterrupt`` included) every temporary is removed (:meth:`discard`) and
    the exception propagates.

    A figures directory replaces an earlier one whole when that one holds only PNG files that
    vibroscope wrote (an earlier run's figures); otherwise (a folder with other files, such as
    ``.``) the new files are moved in one by one, so nothing else in it is removed, and a file
    of the same name that vibroscope did not write is refused before the first move.

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
        kind = special_kind(final)
        if kind is not None:
            raise VibroscopeError(f"output {final} is {kind}: only vibroscope's own earlier outputs are replaced")
        if final.is_file() and not written_by_vibroscope(final):
            raise VibroscopeError(f"output: not written by vibroscope: {final}; remove it or choose another path "
                                  f"(only vibroscope's own earlier outputs are replaced)")

    def file(self, path: str | os.PathLike) -> Path:
        """The temporary path to write the output file `path` to (its folder is created).

        Parameters
        ----------
        path : str or path-like
            The final output file.

        Returns
        -------
        Path

        Raises
        ------
        VibroscopeError
            If `path` is an input, a folder, not a regular file (a link, FIFO, device), or a
            file that vibroscope did not write.
        """
        final = Path(path)
        self._guard(final)
        if final.is_dir():
            raise VibroscopeError(f"output {final} is a folder: cannot write a file there")
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

        Raises
        ------
        VibroscopeError
            If `path` is an input, a file, or a link, FIFO or device.
        """
        final = Path(path)
        self._guard(final)
        if final.exists() and not final.is_dir():
            raise VibroscopeError(f"{final} exists and is not a folder: cannot write figures there")
        final.parent.mkdir(parents=True, exist_ok=True)
        tmp = final.parent / f".{final.name}{TEMP_MARK}{os.getpid()}"
        if tmp.exists():
            shutil.rmtree(tmp)
        self._dirs.append((tmp, final))  # listed before it exists: a Ctrl-C right after mkdir still removes it
        tmp.mkdir()
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

    def _moves(self) -> list[tuple[Path, Path]]:
        """Every (temporary, final) file move of the commit, checked before the first one."""
        moves = [(tmp, final) for tmp, final in self._files if tmp.exists()]  # a writer may write nothing
        for tmp, final in self._dirs:
            if final.exists() and not self._swap_whole(final):
                moves += [(p, final / p.name) for p in sorted(tmp.iterdir())]
        for _, final in moves:
            self._guard(final)
            if final.is_dir():
                raise VibroscopeError(f"output {final} is a folder: cannot replace it by a file")
        return moves

    def _swap_whole(self, final: Path) -> bool:
        """Whether an existing figures folder holds only PNG files vibroscope wrote (an earlier run's),
        none an input."""
        return all(p.suffix.lower() == FIGURE_SUFFIX and written_by_vibroscope(p) for p in final.iterdir()) \
            and not any(same_file(p, i) for p in final.iterdir() for i in self._inputs)

    def commit(self) -> None:
        """Move every temporary into place, all or none.

        Every final path is checked first (an input, a link, FIFO or device is refused); the moves
        then run with SIGINT and SIGTERM held (delivered once they are done), and a failed move
        puts back what was replaced before it.

        Raises
        ------
        VibroscopeError
            If a final path became an input or a special file since it was planned.
        """
        self._moves()  # every check before the first move
        undo: list[tuple[Path, Path | None]] = []  # (final, where its earlier version waits, or None)
        aside_n = 0

        def aside(final: Path) -> Path:
            nonlocal aside_n
            aside_n += 1
            return final.parent / f".{final.name}.old{aside_n}{TEMP_MARK}{os.getpid()}"

        with _held_signals():
            try:
                for tmp, final in self._files:
                    if not tmp.exists():
                        continue
                    self._guard(final)
                    old = None
                    if final.exists():
                        self._say(final)
                        old = aside(final)
                        os.replace(final, old)
                    undo.append((final, old))
                    os.replace(tmp, final)
                for tmp, final in self._dirs:
                    if not final.exists():
                        undo.append((final, None))
                        os.replace(tmp, final)
                        continue
                    self._say(final)
                    if self._swap_whole(final):
                        old = aside(final)
                        os.replace(final, old)
                        undo.append((final, old))
                        os.replace(tmp, final)
                        continue
                    for p in sorted(tmp.iterdir()):
                        dest = final / p.name
                        self._guard(dest)
                        old = None
                        if dest.exists():
                            old = aside(dest)
                            os.replace(dest, old)
                        undo.append((dest, old))
                        os.replace(p, dest)
                    shutil.rmtree(tmp, ignore_errors=True)
            except BaseException:
                for final, old in reversed(undo):  # put the earlier outputs back
                    try:
                        if final.is_dir() and not final.is_symlink():
                            shutil.rmtree(final)
                        elif final.exists():
                            final.unlink()
                        if old is not None:
                            os.replace(old, final)
                    except OSError:
                        pass
                raise
            for _, old in undo:
                if old is not None:
                    if old.is_dir() and not old.is_symlink():
                        shutil.rmtree(old, ignore_errors=True)
                    else:
                        try:
                            old.unlink()
                        except OSError:
                            pass
        self._files, self._dirs = [], []

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


#: the running :func:`preload_outputs` thread, joined by :func:`preloaded`
_PRELOAD: list = []


def preload_outputs(*, rrd: bool, figures: bool) -> None:
    """Import the libraries of the outputs (rerun with pyarrow, not pandas; matplotlib and PIL) in
    a background thread while the analysis computes, so that a fresh process does not import
    them, one after the other, after the analysis (about a second of the 2-core machine's time:
    imports run while the analysis waits in compiled code without the GIL, or on the idle core).

    A failed import is left for the output's own import to report. :func:`preloaded` joins the
    thread: call it before forking (:class:`vibroscope.viewers.figures.PendingFigures`), so that
    no worker inherits an import lock held by the thread.

    Parameters
    ----------
    rrd : bool
        A rerun recording (or viewer) will be written.
    figures : bool
        PNG figures will be written.
    """
    if not (rrd or figures) or _PRELOAD:
        return

    def load() -> None:
        with contextlib.suppress(Exception):
            if figures:
                from vibroscope.viewers.figures import preload

                preload()
            if rrd:
                from vibroscope.viewers.rerun_view import preload

                preload(pandas=False)  # this process hands rerun numpy arrays only: no pandas import

    t = threading.Thread(target=load, name="vibroscope-preload", daemon=True)
    _PRELOAD.append(t)
    t.start()


def preloaded() -> None:
    """Wait for the :func:`preload_outputs` thread, if one was started."""
    while _PRELOAD:
        _PRELOAD.pop().join()
