"""Calls made in a child process, for code that may take its process down with it.

A native library can abort instead of raising (Mitsuba's RGBE reader on a damaged file), so
such calls run in :class:`Child`: a fresh, isolated interpreter (``sys.executable -I -c``, so
the caller's main module is never re-run) with the parent's ``sys.path``, serving pickled calls
on its stdin and stdout.  It starts at the first call and after a death, ignores Ctrl-C, and is
killed past a call's deadline (a corrupted heap can leave it spinning).
"""

import atexit
import importlib
import os
import pickle
import select
import signal
import subprocess
import sys
import tempfile
import threading

#: The child's program: Ctrl-C ignored, replies on a copy of its stdout while fd 1 (where a
#: native library may print) points at stderr, the parent's ``sys.path``, then :func:`_serve`.
_SOURCE = """\
import os, pickle, signal, sys
signal.signal(signal.SIGINT, signal.SIG_IGN)
replies = os.fdopen(os.dup(1), "wb")
os.dup2(2, 1)
sys.path[:] = pickle.load(sys.stdin.buffer)
from skyfit_mi.child import _serve
_serve(sys.stdin.buffer, replies)
"""


class ChildDied(Exception):
    """The child process died during a call; the message says how, in one line."""


class CallFailed(Exception):
    """The call raised in the child; the message is its error in one line."""


def one_line(exc):
    """An exception's last non-empty message line, at most 200 characters (or its type's name)."""
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    return (lines[-1] if lines else type(exc).__name__)[:200]


def _serve(requests, replies):
    """The child's loop: take (function 'module:function', args) from ``requests``, reply
    ``('ok', result)`` or ``('error', one line)`` on ``replies``, until ``requests`` ends."""
    while True:
        try:
            function, args = pickle.load(requests)
        except EOFError:
            return
        try:
            module, _, name = function.partition(":")
            reply = ("ok", getattr(importlib.import_module(module), name)(*args))
        except Exception as exc:                    # noqa: BLE001 -- sent to the parent
            reply = ("error", one_line(exc))
        pickle.dump(reply, replies, protocol=pickle.HIGHEST_PROTOCOL)
        replies.flush()


class Child:
    """One child process (module doc) serving :meth:`call`, one call at a time."""

    def __init__(self):
        self._proc = None
        self._pid = None                 # the process that started the child
        self._log = None                 # the child's stderr since its last reply
        self._lock = threading.Lock()
        atexit.register(self.close)

    def _start(self):
        if self._pid != os.getpid():     # a fork's copy: the child is the parent's
            self._proc = self._log = None
        self.close()
        self._log = tempfile.TemporaryFile(buffering=0)
        self._proc = subprocess.Popen([sys.executable, "-I", "-c", _SOURCE],
                                      stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                      stderr=self._log)
        self._pid = os.getpid()
        pickle.dump(list(sys.path), self._proc.stdin)

    def call(self, function, *args, timeout=None):
        """``function(*args)`` in the child: ``function`` is 'module:function'; arguments and
        result must pickle.  ``timeout`` [s]: the deadline for its answer (None: none).

        Raises CallFailed (the call raised) or ChildDied (the child died, or did not answer
        within ``timeout`` and was killed), each with a one-line message.
        """
        with self._lock:
            if self._proc is None or self._pid != os.getpid() or self._proc.poll() is not None:
                self._start()
            proc = self._proc
            try:
                pickle.dump((function, args), proc.stdin, protocol=pickle.HIGHEST_PROTOCOL)
                proc.stdin.flush()
                answered = timeout is None or select.select([proc.stdout], [], [], timeout)[0]
                reply = pickle.load(proc.stdout) if answered else None
            except MemoryError:
                self.close(kill=True)
                raise
            except Exception as exc:                # noqa: BLE001 -- EOF, broken pipe..
                why = self._death(proc, exc)
                self.close(kill=True)
                raise ChildDied(why) from None
            except BaseException:                   # Ctrl-C: leave no child working
                self.close(kill=True)
                raise
            if reply is None:
                self.close(kill=True)
                raise ChildDied(f"no answer within {timeout:g} s (killed)")
            self._log.seek(0)
            self._log.truncate()
        kind, value = reply
        if kind == "ok":
            return value
        raise CallFailed(value)

    def _death(self, proc, exc):
        """How the child died, in one line: its signal or exit status and its last stderr line."""
        try:
            code = proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            return f"its reply was unreadable ({type(exc).__name__})"
        if code < 0:
            try:
                how = signal.Signals(-code).name
            except ValueError:
                how = f"signal {-code}"
        else:
            how = f"exit status {code}"
        self._log.seek(0)
        tail = [ln.strip() for ln in self._log.read()[-4000:].decode("utf-8", "replace")
                .splitlines() if ln.strip()]
        return f"{how}, {tail[-1][:160]}" if tail else how

    def close(self, kill=False):
        """End the child: close its stdin and wait for it (``kill``: kill it first)."""
        proc, log, self._proc, self._log = self._proc, self._log, None, None
        if proc is not None:
            if kill:
                proc.kill()
            for pipe in (proc.stdin, proc.stdout):
                try:
                    pipe.close()
                except OSError:                     # a dead child's pipe: nothing to flush
                    pass
            try:
                proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        if log is not None:
            log.close()
