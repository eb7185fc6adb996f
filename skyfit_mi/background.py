"""Work done beside this process: one call run in a child process at the lowest priority.

A render keeps both cores busy while its kernels run, but between them it writes frames,
integrates the sky's irradiance and reads files on one core.  A child at nice 19 takes
almost no time from the render's threads and fills those idle moments: a relight's
prediction and its plot, which need nothing the render makes, come nearly free beside it
(docs/BENCHMARKS.md, "eighth measurement").

The child is a fork of this process where that is safe (Linux, no other thread running and
Dr.Jit not loaded: its thread pool and LLVM do not survive a fork): it starts at once with
this process's imports and the call's arguments as they are, and answers pickled on a pipe
(the tenth measurement: 0.45 s sooner and 0.2 s of a core less than a new interpreter).  It
shares this process's open files, so a caller holding a lock on one starts it before taking
the lock.  Otherwise the child is a fresh, isolated interpreter (``sys.executable -I -c``:
the current folder is not on its path), so the caller's main module is never run again in it
(as ``multiprocessing``'s 'spawn' would); it takes the parent's ``sys.path``, then the call
and its arguments, pickled on its stdin, and answers on its stdout.  Ctrl-C is the parent's
to handle: the child ignores it and is killed when the parent lets go of it.

When the parent comes for the result, a child still working is given the parent's priority
back where the system allows it; where it does not, and other work keeps the child from a
core (less than STARVED of a core over WATCH_S seconds), the call is run again in the parent,
so that a busy machine never leaves a nice-19 child waited on for minutes.  A child that
stops using a core altogether (STALLED over STALLED_S: stuck) is given up alike.
"""

import os
import pickle
import select
import signal
import subprocess
import sys
import threading
import time

from .errors import SetupError, SkyfitError

#: Niceness of the child (Linux: 19 is the lowest priority).
NICE = 19
#: While waited on, a child that gets less than STARVED of a core over WATCH_S seconds is
#: given up and its call run in the parent; one given the parent's priority, only if it uses
#: less than STALLED of a core over STALLED_S seconds (stuck: a deadlock would wait forever).
STARVED, WATCH_S = 0.2, 1.0
STALLED, STALLED_S = 0.01, 10.0
#: Seconds a child that has answered is given to exit before it is killed.
EXIT_S = 5.0

#: The fresh interpreter's program: Ctrl-C ignored from the start, the reply on a copy of its
#: stdout, the parent's ``sys.path`` first (so that the call's arguments unpickle as they would
#: in the parent), then :func:`_child` with the call read from stdin.
_CHILD_SOURCE = """\
import os, pickle, signal, sys
signal.signal(signal.SIGINT, signal.SIG_IGN)
reply = os.dup(1)
sys.path[:] = pickle.load(sys.stdin.buffer)
from skyfit_mi.background import _child
_child({nice}, lambda: pickle.load(sys.stdin.buffer), reply)
"""


def _forkable():
    """Whether the child can be a fork of this process (module doc)."""
    return (sys.platform.startswith("linux") and "drjit" not in sys.modules
            and threading.active_count() == 1)


def _child(nice, request, reply_fd):
    """The child's side: Ctrl-C left to the parent, file descriptor 1 (where a native library
    may print) pointed at stderr, the lower priority, then :func:`_serve` of ``request()``
    (the call) answering on ``reply_fd``."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    os.dup2(2, 1)
    os.nice(nice)
    with os.fdopen(reply_fd, "wb") as reply:
        _serve(request, reply)


def _call(call, args, kwargs):
    """``call`` ('module:function') applied to ``args`` and ``kwargs``."""
    import importlib

    module, _, name = call.partition(":")
    return getattr(importlib.import_module(module), name)(*args, **kwargs)


def _serve(request, reply):
    """Take (call, args, kwargs) from ``request()``, run it, and write to ``reply`` one of
    ``('ok', result)``, ``('refused', error)`` (bad input or a back-end that cannot start,
    raised again in the parent as it is, or as a SkyfitError of its message if it does not
    pickle) or ``('failed', traceback text)``."""
    import traceback

    try:
        out = ("ok", _call(*request()))
    except (SkyfitError, SetupError) as exc:
        out = ("refused", exc)
    except Exception:                                # noqa: BLE001 -- sent to the parent
        out = ("failed", traceback.format_exc())
    try:
        data = pickle.dumps(out, protocol=pickle.HIGHEST_PROTOCOL)
        pickle.loads(data)
    except Exception:                                # noqa: BLE001 -- e.g. an odd exception
        data = pickle.dumps(("refused", SkyfitError(str(out[1]))) if out[0] == "refused"
                            else ("failed", traceback.format_exc()))
    reply.write(data)
    reply.flush()


def _cpu_seconds(pid):
    """CPU time [s] process ``pid`` has used (Linux /proc), or None where it cannot be read."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            fields = f.read().rsplit(b")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return None


class _Fork:
    """A forked child (``multiprocessing``'s 'fork') running :func:`_child`, answering on a
    pipe; with the part of :class:`subprocess.Popen` that :class:`Beside` uses."""

    stdin = None

    def __init__(self, request, nice):
        import multiprocessing

        read, write = os.pipe()
        self.stdout = os.fdopen(read, "rb")
        self._process = multiprocessing.get_context("fork").Process(
            target=_child, args=(nice, lambda: request, write), daemon=True)
        try:
            self._process.start()
        finally:
            os.close(write)                          # the child's: EOF when it ends
        self.pid = self._process.pid

    @property
    def returncode(self):
        return self._process.exitcode

    def wait(self, timeout=None):
        self._process.join(timeout)
        if self._process.exitcode is None:
            raise subprocess.TimeoutExpired("fork", timeout)
        return self._process.exitcode

    def kill(self):
        self._process.kill()


class Beside:
    """``call(*args, **kwargs)`` started now in a low-priority child process; :meth:`result`
    waits for it.  ``call`` names a module-level function, 'module:function'; its arguments
    and result must pickle.  Use as a context manager: leaving it kills a child whose result
    was not taken (an error in the parent's own work, Ctrl-C)."""

    def __init__(self, call, *args, nice=NICE, **kwargs):
        self.call, self._request = call, (call, args, kwargs)
        if _forkable():
            self._proc = _Fork(self._request, int(nice))
            return
        self._proc = subprocess.Popen(
            [sys.executable, "-I", "-c", _CHILD_SOURCE.format(nice=int(nice))],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE)
        try:
            for message in (list(sys.path), self._request):
                pickle.dump(message, self._proc.stdin, protocol=pickle.HIGHEST_PROTOCOL)
            self._proc.stdin.close()
        except BaseException:
            self.close()
            raise

    def result(self):
        """The call's result.  A :class:`SkyfitError` (or SetupError) it raised is raised
        here; any other failure, or the child's death, raises RuntimeError with the child's
        traceback or exit status.  A starved child's call is run here instead (module doc)."""
        if self._proc.stdout.closed:
            raise RuntimeError(f"the result of {self.call} was already taken")
        reply = None
        try:
            reply = pickle.load(self._proc.stdout) if self._wait() else None
        except Exception:                            # noqa: BLE001 -- EOF, a broken reply
            code = self._proc.wait()
            raise RuntimeError(f"the child process running {self.call} ended without a "
                               f"result (exit status {code})") from None
        finally:                                     # a child that answered exits by itself
            self.close(grace=EXIT_S if reply is not None else 0.0)
        if reply is None:                            # starved: the call is made here
            return _call(*self._request)
        kind, value = reply
        if kind == "ok":
            return value
        if kind == "refused":
            raise value
        raise RuntimeError(f"{self.call} failed in a child process:\n{value}")

    def _wait(self):
        """Wait until the child's reply can be read (True), first giving the child this
        process's priority where allowed; False if it is starved of a core, or stuck."""
        pid = self._proc.pid
        try:
            os.setpriority(os.PRIO_PROCESS, pid, os.getpriority(os.PRIO_PROCESS, 0))
            raised = True
        except OSError:                              # not allowed (unprivileged), or gone
            raised = False
        # starved: less than STARVED of a core over WATCH_S; given this process's priority, only
        # a stuck child (a deadlock) uses less than STALLED of one over STALLED_S
        share, window = (STALLED, STALLED_S) if raised else (STARVED, WATCH_S)
        used, since = _cpu_seconds(pid), time.monotonic()
        while not select.select([self._proc.stdout], [], [], WATCH_S)[0]:
            now, cpu = time.monotonic(), _cpu_seconds(pid)
            if used is None or cpu is None or now - since < window:
                continue
            if cpu - used < share * (now - since):
                return False
            used, since = cpu, now
        return True

    def close(self, grace=0.0):
        """Kill the child if it still runs after ``grace`` seconds, and reap it."""
        try:
            self._proc.wait(timeout=grace)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait()
        for pipe in (self._proc.stdin, self._proc.stdout):
            if pipe is not None:
                pipe.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False
