"""Safe output files: checked before any work, written whole or not at all.

Every output of ehss goes through this module. :func:`check_outputs` runs before a
command does its work and refuses, with one clear message, anything that would lose a
file: an output that is one of the inputs (also through symlinks and hard links), two
outputs on one file, a JSON sidecar that would replace a file ehss did not write for that
output, a missing or unwritable folder, and an existing path that a rename would destroy
(a folder, symlink, FIFO, device, socket or read-only file). :func:`atomic_path` then
writes each output to a temporary file beside it and renames it into place on success.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import secrets
import stat
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

from ehss.errors import DataError, EhssError

__all__ = [
    "WriteError",
    "SIDECAR_KEY",
    "atomic_path",
    "check_folder",
    "check_outputs",
    "check_sidecar",
    "check_writable",
    "parse_document",
    "read_small_file",
    "sidecar_path",
]

#: Key that marks a JSON sidecar written by ehss; its value is the table's file name.
SIDECAR_KEY = "ehss_sidecar_of"
# A sidecar is a few kB; anything much larger is not one of ours (and is not read).
_SIDECAR_MAX_BYTES = 64 * 2**20


class WriteError(EhssError, OSError):
    """An output could not be written after the checks passed (e.g. the disk is full).

    Nothing is left behind: the temporary file is removed and the old file kept.
    """


_KINDS = (
    (stat.S_ISLNK, "a symbolic link"),
    (stat.S_ISFIFO, "a named pipe (FIFO)"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
    (stat.S_ISDIR, "a folder"),
)


def _name(path: Path | str) -> str:
    return repr(str(path))


def _parent(path: Path) -> Path:
    return path.parent if str(path.parent) else Path(".")


@contextlib.contextmanager
def _temporary_file(folder: Path, name: str, what: str = "") -> Iterator[Path]:
    """Create an empty temporary file in ``folder`` for the output ``name``; remove it on
    the way out unless it was renamed.

    The temporary name keeps the output's suffix (writers choose formats by it). It is
    recorded before the file is created, so an interrupt raised at any point (Ctrl-C, or
    SIGTERM turned into an exception by the command line) still finds and removes it.

    Raises
    ------
    DataError
        If the file cannot be created (folder not writable, name too long).
    """
    suffix = Path(name).suffix
    what = what or _name(folder / name)
    tmp: Path | None = None
    try:
        try:
            for _ in range(100):
                tmp = folder / f".{name}.{secrets.token_hex(6)}{suffix}"
                try:
                    os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
                    break
                except FileExistsError:  # not ours: never remove it
                    tmp = None
            else:  # pragma: no cover - 100 collisions of 48 random bits
                raise FileExistsError(errno.EEXIST, "no free temporary name")
        except OSError as exc:
            tmp = None
            if exc.errno == errno.ENAMETOOLONG:
                raise DataError(f"cannot write {what}: the name is too long (the temporary "
                                "file beside it needs 14 characters more)") from None
            reason = exc.strerror or type(exc).__name__
            raise DataError(f"cannot write {what}: folder {_name(folder)} is not writable "
                            f"({reason})") from None
        yield tmp
    finally:
        if tmp is not None:
            with contextlib.suppress(FileNotFoundError):
                tmp.unlink()


def _probe_folder(folder: Path, name: str, what: str = "") -> None:
    """Create and remove the temporary file :func:`atomic_path` will use for the output
    ``name``: the only reliable test of writability (permission bits say nothing for
    root, nor on read-only mounts) and of the name's length."""
    with _temporary_file(folder, name, what):
        pass


def check_writable(path: str | Path, *, probe: bool = True) -> Path:
    """Check, before any work is done, that ``path`` can be written without loss.

    Parameters
    ----------
    path : str or Path
        The output file.
    probe : bool, default True
        Also create and remove a temporary file in the folder, named as the output's
        temporary file will be, to find an unwritable folder or a name too long now
        rather than after the work.

    Returns
    -------
    Path
        ``path`` as a Path.

    Raises
    ------
    DataError
        If the folder does not exist, is not a folder or is not writable, or ``path``
        exists and is a folder, symbolic link, FIFO, device, socket or read-only file
        (renaming onto it would replace it).
    """
    path = Path(path)
    parent = _parent(path)
    try:
        parent_st = parent.stat()
    except FileNotFoundError:
        raise DataError(f"cannot write {_name(path)}: folder {_name(parent)} does not "
                        "exist") from None
    except NotADirectoryError:
        raise DataError(f"cannot write {_name(path)}: a part of {_name(parent)} is a file, "
                        "not a folder") from None
    except OSError as exc:
        raise DataError(f"cannot write {_name(path)}: folder {_name(parent)} is not "
                        f"accessible ({exc.strerror or type(exc).__name__})") from None
    if not stat.S_ISDIR(parent_st.st_mode):
        raise DataError(f"cannot write {_name(path)}: {_name(parent)} is a file, not a folder")
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        st = None
    except OSError as exc:
        raise DataError(f"cannot write {_name(path)}: {exc.strerror or exc}") from None
    if st is not None:
        for test, kind in _KINDS:
            if test(st.st_mode):
                raise DataError(f"cannot write {_name(path)}: it is {kind}, which the output "
                                "would replace; choose another name")
        if not st.st_mode & stat.S_IWUSR or not os.access(path, os.W_OK):
            raise DataError(f"cannot write {_name(path)}: the file is read-only")
    if probe:
        _probe_folder(parent, path.name)
    return path


def check_folder(path: str | Path) -> Path:
    """Check before any work that files can be written into the folder ``path``.

    The folder may not exist yet (it is then created by the writer), but its parent must.

    Raises
    ------
    DataError
        If ``path`` exists and is not a folder, its parent does not exist, or the folder
        (or the parent, when the folder is still to be made) is not writable.
    """
    path = Path(path)
    if path.is_dir():
        _probe_folder(path, "ehss-probe", f"into {_name(path)}")
        return path
    if path.exists() or path.is_symlink():
        raise DataError(f"cannot write into {_name(path)}: it exists and is not a folder")
    parent = _parent(path)
    if not parent.is_dir():
        what = "does not exist" if not parent.exists() else "is a file, not a folder"
        raise DataError(f"cannot create folder {_name(path)}: {_name(parent)} {what}")
    _probe_folder(parent, "ehss-probe", f"folder {_name(path)}")
    return path


def read_small_file(path: Path, where: str, *, max_bytes: int,
                    error: type[EhssError] = DataError) -> bytes:
    """The bytes of a small document (a parameter set, a model) at ``path``.

    Every refusal is one ``error`` that starts with ``where`` (e.g. ``"model file
    'm.json'"``): a folder, not a regular file, larger than ``max_bytes`` (it is then
    not read), missing or unreadable.
    """
    try:
        if path.is_dir():
            raise error(f"{where} is a folder")
        if path.exists() and not path.is_file():
            raise error(f"{where} is not a regular file (a pipe or a device?)")
        size = path.stat().st_size
        if size > max_bytes:
            raise error(f"{where} is {size} bytes, more than such a file holds "
                        f"(at most {max_bytes} bytes)")
        return path.read_bytes()
    except FileNotFoundError:
        raise error(f"{where} does not exist") from None
    except OSError as exc:
        raise error(f"cannot read {where}: {exc.strerror or exc}") from None


def parse_document(raw: bytes, where: str, *, parse: Callable[[str], Any],
                   syntax_error: type[ValueError], syntax: str, kind: str,
                   encoding: str = "utf-8", advice: str = "",
                   error: type[EhssError] = DataError) -> Any:
    """The document ``raw`` (read by :func:`read_small_file`) decoded and parsed.

    Every refusal is one ``error`` that starts with ``where``: not ``encoding`` text (the
    message ends with ``advice``), not valid ``syntax`` (``parse`` raised
    ``syntax_error``), or nested too deeply to be ``kind``.
    """
    try:
        text = raw.decode(encoding)
    except UnicodeDecodeError as exc:
        raise error(f"{where} is not UTF-8 text (byte {exc.start}: "
                    f"{raw[exc.start:exc.start + 1]!r}){advice}") from None
    try:
        return parse(text)
    except syntax_error as exc:
        raise error(f"{where} is not valid {syntax}: {exc}") from None
    except RecursionError:
        raise error(f"{where} is nested too deeply to be {kind}") from None


def sidecar_path(table: str | Path) -> Path:
    """The JSON sidecar beside a table: ``run.csv`` → ``run.json``."""
    return Path(table).with_suffix(".json")


def check_sidecar(sidecar: str | Path, table: str | Path) -> None:
    """Refuse to replace an existing ``sidecar`` unless ehss wrote it for ``table``.

    A sidecar written by ehss is a JSON object whose :data:`SIDECAR_KEY` names the
    table's file; anything else at that path is the user's file and is kept.

    Raises
    ------
    DataError
        If ``sidecar`` exists and is not the sidecar of ``table``.
    """
    sidecar, table = Path(sidecar), Path(table)
    try:
        st = os.lstat(sidecar)
    except FileNotFoundError:
        return
    except OSError as exc:
        raise DataError(f"cannot write {_name(sidecar)}: {exc.strerror or exc}") from None
    ours = False
    if stat.S_ISREG(st.st_mode) and st.st_size <= _SIDECAR_MAX_BYTES:
        try:
            doc = json.loads(sidecar.read_bytes())
        except (OSError, ValueError):
            doc = None
        ours = isinstance(doc, dict) and doc.get(SIDECAR_KEY) == table.name
    if not ours:
        raise DataError(f"{_name(sidecar)} exists and is not the JSON sidecar ehss wrote "
                        f"for {_name(table)}, so writing {_name(table)} would replace it; "
                        "move it or choose another output name")


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist (yet): compare the resolved names
        return a.resolve() == b.resolve()


def check_outputs(
    outputs: Iterable[str | Path | tuple[str | Path, str]],
    *,
    inputs: Iterable[str | Path] = (),
) -> list[Path]:
    """Check before any work that every output can be written without losing a file.

    Parameters
    ----------
    outputs : iterable of path or (path, description)
        The files the work will write. A description (e.g. ``"the JSON sidecar of
        'run.csv'"``) is added to messages about that file.
    inputs : iterable of path
        The files the work reads; no output may be one of them, nor the JSON sidecar
        beside one of them (``run.csv`` → ``run.json``), which holds its metadata.

    Returns
    -------
    list of Path
        The outputs, in order.

    Raises
    ------
    DataError
        If an output is one of the inputs or an input's sidecar (also through a symbolic
        or hard link), two outputs are one file, or :func:`check_writable` refuses an
        output.
    """
    items: list[tuple[Path, str]] = []
    for item in outputs:
        path, note = item if isinstance(item, tuple) else (item, "")
        items.append((Path(path), f" ({note})" if note else ""))
    ins = [Path(p) for p in inputs]
    for path, note in items:
        for src in ins:
            if _same_file(path, src):
                raise DataError(f"output {_name(path)}{note} is the input {_name(src)}; "
                                "writing it would replace the input: choose another name")
            side = sidecar_path(src)
            if side != src and os.path.lexists(side) and _same_file(path, side):
                raise DataError(f"output {_name(path)}{note} is the JSON sidecar of the "
                                f"input {_name(src)} (its units, parameters and seed); "
                                "writing it would lose them: choose another name")
    for path, _ in items:
        check_writable(path)
    for i, (path, note) in enumerate(items):
        for other, other_note in items[:i]:
            if _same_file(path, other):
                raise DataError(f"two outputs would be written to one file: {_name(other)}"
                                f"{other_note} and {_name(path)}{note}")
    return [p for p, _ in items]


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` on success.

    If the body raises (an error, Ctrl-C, or SIGTERM turned into an exception by the
    command line), the temporary file is removed and ``path`` is untouched, so a failed
    run never leaves a half-written or overwritten output. The temporary file keeps the
    suffix of ``path``, so writers that choose a format by extension still can.

    Raises
    ------
    DataError
        If :func:`check_writable` refuses ``path``.
    WriteError
        If writing fails with an OSError (a full disk, say); ``path`` is untouched.
    """
    path = check_writable(path, probe=False)
    with _temporary_file(_parent(path), path.name) as tmp:
        try:
            yield tmp
        except WriteError:
            raise
        except OSError as exc:  # disk full, quota, I/O error: one line, nothing written
            reason = exc.strerror or str(exc).strip().splitlines()[0] or type(exc).__name__
            raise WriteError(f"cannot write {_name(path)}: {reason}") from None
        # the temporary file is 0600; give the result the usual permissions (umask)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        tmp.replace(path)
