"""Writing an output file whole or not at all: the one way every linknet writer puts a file in place.

``atomic_write(path, write)`` has ``write`` fill a temporary file in the target's own folder (same filesystem, so
the rename is atomic), flushes it to the disk, and renames it over ``path``. A write that fails (a full disk, a
file size limit, a writer's own error, Ctrl-C) removes the temporary and leaves at ``path`` what was there before:
no file, or the previous one intact; the failure is a ``WriteError`` naming the file and what happened.
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Callable

from linknet_core.errors import LinknetError


class WriteError(LinknetError):
    """An output could not be written (disk full, file too large, permissions, a folder that vanished); nothing
    was left at the path but what was there before. ``path`` is the file, ``reason`` what happened."""

    def __init__(self, path, reason: str, kept: bool = False, detail: str | None = None):
        self.path, self.reason = str(path), reason
        left = detail or ("the previous file there is kept" if kept else "nothing was left there")
        super().__init__(f"cannot write {path}: {reason} ({left})")


def failure_reason(exc: BaseException) -> str:
    """An OSError in a few words: 'No space left on device (errno 28)'; other errors as 'Type: message'."""
    if isinstance(exc, OSError) and exc.strerror and exc.errno:
        return f"{exc.strerror} (errno {exc.errno})"
    text = " ".join(str(exc).split()) or type(exc).__name__  # one line, whatever the library wrote
    return text if isinstance(exc, OSError) else f"{type(exc).__name__}: {text}"


def _mode_for(path: Path) -> int:
    """The permissions the file would have had if written in place: the previous file's, else 0o666 less the
    umask (a temporary file starts as 0o600)."""
    try:
        return path.stat().st_mode & 0o7777
    except OSError:
        mask = os.umask(0)
        os.umask(mask)
        return 0o666 & ~mask


def atomic_write(path, write: Callable[[str], object], *, errors: tuple = ()) -> Path:
    """Write ``path`` whole or not at all: ``write(tmp)`` writes a temporary file (named like ``path``, with the
    same suffix, in the same folder), which is synced and then renamed onto ``path``. Missing folders are
    created. An OSError (and any exception of a type in ``errors``, e.g. a writer's RuntimeError) becomes a
    ``WriteError`` naming ``path``; any other exception passes through; the temporary is removed either way."""
    shown = path  # named in errors as given, made absolute only for the rename
    path = Path(os.path.abspath(Path(path).expanduser()))
    kept = path.exists()
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=f".partial{path.suffix}", dir=path.parent)
        os.close(fd)
        write(tmp)
        os.chmod(tmp, _mode_for(path))
        fd = os.open(tmp, os.O_RDONLY)
        try:
            os.fsync(fd)  # a filesystem that allocates late reports a full disk here, not at write()
        finally:
            os.close(fd)
        os.replace(tmp, path)
        tmp = None
    except LinknetError:  # the writer's own refusal, already in words (a LinknetError is a ValueError)
        raise
    except (OSError, *errors) as exc:
        raise WriteError(shown, failure_reason(exc), kept) from exc
    finally:
        if tmp is not None:
            try:
                os.unlink(tmp)
            except OSError:
                pass
    return path


def rescue_path(path, tag: str = "rescued") -> Path:
    """Where to put what could not be written at ``path``: a new file in the temporary folder (``$TMPDIR``),
    named after it, that exists nowhere yet."""
    path = Path(path)
    fd, name = tempfile.mkstemp(prefix=f"linknet-{tag}-{path.stem}-", suffix=path.suffix)
    os.close(fd)
    os.unlink(name)
    return Path(name)
