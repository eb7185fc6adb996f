"""Writing output files: atomically (temporary file, then rename), with the user's umask.

Every file skyfit-mi writes goes through :func:`atomic_write`, so an interrupted run leaves no
half-written file and an unwritable path gives one :class:`~skyfit_mi.errors.OutputError`.
"""

import datetime as dt
import io
import json
import os
import socket
import tempfile
import time
from pathlib import Path

import numpy as np

from .errors import OutputError


def _umask():
    """The process's umask (read without changing it for longer than the call)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def ensure_dir(path, what="output folder"):
    """Create folder ``path`` (and parents) or raise :class:`OutputError` saying why not."""
    path = Path(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise OutputError(f"{what} {str(path)!r} is a file, not a folder; give a folder path.") \
            from None
    except OSError as exc:
        raise OutputError(f"cannot create {what} {str(path)!r}: {exc.strerror or exc}; give a "
                          "writable folder.") from None
    if not os.access(path, os.W_OK | os.X_OK):
        raise OutputError(f"{what} {str(path)!r} is not writable; give a writable folder.")
    return path


def check_dir(path, what="output folder"):
    """``path`` as a Path, or :class:`OutputError` unless it is a writable folder or one that
    :func:`ensure_dir` could create; nothing is created."""
    path = Path(path)
    if path.exists():
        if not path.is_dir():
            raise OutputError(f"{what} {str(path)!r} is a file, not a folder; give a folder path.")
        if not os.access(path, os.W_OK | os.X_OK):
            raise OutputError(f"{what} {str(path)!r} is not writable; give a writable folder.")
        return path
    parent = next(p for p in path.absolute().parents if p.exists())
    if not parent.is_dir() or not os.access(parent, os.W_OK | os.X_OK):
        why = "Not a directory" if not parent.is_dir() else "Permission denied"
        raise OutputError(f"cannot create {what} {str(path)!r}: {why}; give a writable folder.")
    return path


def output_prefix(prefix, default_name):
    """The path prefix of a command's files from ``-o``: ``default_name`` inside it where it is
    a folder (existing, or new written with a trailing slash), else ``prefix`` itself."""
    if str(prefix).endswith(("/", os.sep)) or Path(prefix).is_dir():
        return Path(prefix) / default_name
    return Path(prefix)


def atomic_write(path, write):
    """Call ``write(tmp_path)`` on a temporary file beside ``path``, then rename it to ``path``
    with mode 0666 less the umask; a failure leaves ``path`` untouched and no temporary file."""
    path = Path(path)
    if path.is_dir():
        raise OutputError(f"output {str(path)!r} is a folder; give a file path.")
    ensure_dir(path.parent)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f"{path.suffix}.tmp"
                                   if not path.suffix else path.suffix, dir=path.parent)
    except OSError as exc:
        raise OutputError(f"cannot write {str(path)!r}: {exc.strerror or exc}.") from None
    os.close(fd)
    try:
        write(tmp)
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except OSError as exc:
        raise OutputError(f"cannot write {str(path)!r}: {exc.strerror or exc}.") from None
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return path


def write_text(path, text):
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    return atomic_write(path, lambda p: Path(p).write_text(text, encoding="utf-8"))


def jsonable(x):
    """JSON form of the NumPy scalars/arrays, dates and paths found in skyfit documents."""
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, (np.floating, np.integer, np.bool_)):
        return x.item()
    if isinstance(x, (dt.datetime, dt.date, dt.time)):
        return x.isoformat()
    if isinstance(x, Path):
        return str(x)
    raise TypeError(f"not JSON serialisable: {type(x).__name__}")


def to_json(doc):
    """``doc`` as indented JSON text (NumPy values, dates and paths converted)."""
    return json.dumps(doc, indent=1, default=jsonable, allow_nan=True)


def write_json(path, doc):
    """Write ``doc`` as indented JSON to ``path`` atomically."""
    return write_text(path, to_json(doc) + "\n")


def write_bytes(path, data):
    """Write ``data`` (bytes) to ``path`` atomically."""
    return atomic_write(path, lambda p: Path(p).write_bytes(data))


def figure_png(fig, dpi=120, close=True):
    """A matplotlib figure as PNG bytes, closed if ``close``."""
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    try:
        fig.savefig(buf, dpi=dpi, format="png")
    finally:
        if close:
            plt.close(fig)
    return buf.getvalue()


def save_figure(fig, path, dpi=120, close=True):
    """Save a matplotlib figure as PNG atomically (:func:`figure_png`)."""
    return write_bytes(path, figure_png(fig, dpi, close))


#: Name of the lock file a writer holds in its output folder.
LOCK_NAME = ".skyfit.lock"


def _alive(pid):
    """Whether process ``pid`` (> 0) exists on this host."""
    if not isinstance(pid, int) or pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:                      # someone else's process: it exists
        return True
    return True


#: A lock file younger than this [s] that names no owner yet is a live run's, between creating
#: it and writing its owner into it; an older one is a run's killed in between (stale).
FRESH_LOCK_S = 5.0
#: How long [s] a run waits for such a young lock file to name its owner, and how often it looks.
LOCK_WAIT_S, LOCK_POLL_S = 1.0, 0.05


class FolderLock:
    """Exclusive use of an output folder by one process (a context manager): an O_EXCL lock
    file naming its owner; one whose process is gone from this host, or one left unreadable
    for :data:`FRESH_LOCK_S`, is taken over (``stale``: its owner record, pid 'unknown' if
    unreadable).  A folder the lock made is removed again if the run fails leaving it empty,
    so that a refused input leaves none."""

    def __init__(self, folder, what="output folder"):
        self.path = Path(folder) / LOCK_NAME
        self.what = what
        self.stale = None
        self.made = False

    def _owner(self):
        try:
            owner = json.loads(self.path.read_text())
        except (OSError, ValueError):
            return None
        return owner if isinstance(owner, dict) else None

    def _age(self):
        """The lock file's age [s] by its mtime; 0 if it is gone (a new try then takes it)."""
        try:
            return time.time() - self.path.stat().st_mtime
        except OSError:
            return 0.0

    def _in_use(self, by):
        return OutputError(
            f"{self.what} {str(self.path.parent)!r} is in use by {by}; wait for it to finish, "
            f"or, if that run no longer exists, delete {self.path}.")

    def __enter__(self):
        self.made = not self.path.parent.exists()
        ensure_dir(self.path.parent, self.what)
        me = {"host": socket.gethostname(), "pid": os.getpid(),
              "since": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds")}
        wait_until = time.monotonic() + LOCK_WAIT_S
        while True:
            try:
                fd = os.open(self.path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666 & ~_umask())
            except FileExistsError:
                owner = self._owner()
                if owner is None and self._age() < FRESH_LOCK_S:     # its owner is writing it
                    if time.monotonic() < wait_until:
                        time.sleep(LOCK_POLL_S)
                        continue
                    raise self._in_use(f"another process (its lock file {self.path.name} "
                                       "names no owner yet)") from None
                if owner is not None and (owner.get("host") != me["host"]
                                          or _alive(owner.get("pid"))):
                    raise self._in_use(f"process {owner.get('pid')} on {owner.get('host')} "
                                       f"since {owner.get('since')}") from None
                if self.stale is not None:
                    raise OutputError(f"cannot lock {self.what} {str(self.path.parent)!r}: "
                                      "another process keeps taking it.") from None
                self.stale = owner or {"pid": "unknown"}
                self.path.unlink(missing_ok=True)
                continue
            except OSError as exc:
                raise OutputError(f"cannot lock {self.what} {str(self.path.parent)!r}: "
                                  f"{exc.strerror or exc}.") from None
            with os.fdopen(fd, "w") as f:
                json.dump(me, f)
            return self

    def __exit__(self, exc_type, *exc):
        self.path.unlink(missing_ok=True)
        if self.made and exc_type is not None:        # a failed run leaves no folder it made
            try:
                self.path.parent.rmdir()
            except OSError:                           # not empty: what it wrote stays
                pass
        return False
