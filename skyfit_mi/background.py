"""Work done beside this process: one call run in a child process at the lowest priority.

A render keeps both cores busy while its kernels run, but between them it writes frames,
integrates the sky's irradiance and reads files on one core.  A child at nice 19 takes
almost no time from the render's threads and fills those idle moments: a relight's
prediction and its plot, which need nothing the render makes, come nearly free beside it
(docs/BENCHMARKS.md, "eighth measurement").

The child is a fresh interpreter (``sys.executable -c``), so the caller's main module is
never run again in it (as ``multiprocessing``'s 'spawn' would); the call and its arguments
go to it pickled on its stdin, the result comes back pickled on its stdout.  Ctrl-C is the
parent's to handle: the child ignores it and is killed when the parent lets go of it.
"""

import os
import pickle
import subprocess
import sys

from .errors import SkyfitError

#: Niceness of the child (Linux: 19 is the lowest priority).
NICE = 19

#: The child's program.  It keeps its stdout for the reply and points file descriptor 1
#: (where a native library may print) at stderr, lowers its priority, takes the parent's
#: ``sys.path`` and the call from stdin, and runs :func:`_serve`.
_CHILD_SOURCE = """\
import os, pickle, signal, sys
signal.signal(signal.SIGINT, signal.SIG_IGN)
reply = os.fdopen(os.dup(1), "wb")
os.dup2(2, 1)
os.nice({nice})
sys.path[:], call, args, kwargs = pickle.load(sys.stdin.buffer)
from skyfit_mi.background import _serve
_serve(call, args, kwargs, reply)
"""


def _serve(call, args, kwargs, reply):
    """Run ``call`` ('module:function') with ``args`` and ``kwargs``; write ``('ok', result)``,
    ``('refused', SkyfitError)`` (bad input, raised again in the parent as it is) or
    ``('failed', traceback text)`` to ``reply``."""
    import importlib
    import traceback

    try:
        module, _, name = call.partition(":")
        out = ("ok", getattr(importlib.import_module(module), name)(*args, **kwargs))
    except SkyfitError as exc:
        out = ("refused", exc)
    except Exception:                                # noqa: BLE001 -- sent to the parent
        out = ("failed", traceback.format_exc())
    pickle.dump(out, reply, protocol=pickle.HIGHEST_PROTOCOL)
    reply.flush()


class Beside:
    """``call(*args, **kwargs)`` started now in a low-priority child process; :meth:`result`
    waits for it.  ``call`` names a module-level function, 'module:function'; its arguments
    and result must pickle.  Use as a context manager: leaving it kills a child whose result
    was not taken (an error in the parent's own work, Ctrl-C)."""

    def __init__(self, call, *args, nice=NICE, **kwargs):
        self.call = call
        self._proc = subprocess.Popen([sys.executable, "-c", _CHILD_SOURCE.format(nice=nice)],
                                      stdin=subprocess.PIPE, stdout=subprocess.PIPE)
        try:
            pickle.dump((list(sys.path), call, args, kwargs), self._proc.stdin,
                        protocol=pickle.HIGHEST_PROTOCOL)
            self._proc.stdin.close()
        except BaseException:
            self.close()
            raise

    def result(self):
        """The call's result.  A :class:`SkyfitError` it raised is raised here; any other
        failure, or the child's death, raises RuntimeError with the child's traceback or
        exit status."""
        try:
            kind, value = pickle.load(self._proc.stdout)
        except (EOFError, pickle.UnpicklingError):
            code = self._proc.wait()
            raise RuntimeError(f"the child process running {self.call} ended without a "
                               f"result (exit status {code})") from None
        finally:
            self.close()
        if kind == "ok":
            return value
        if kind == "refused":
            raise value
        raise RuntimeError(f"{self.call} failed in a child process:\n{value}")

    def close(self):
        """Kill the child if it still runs, and reap it."""
        if self._proc.poll() is None:
            self._proc.kill()
        self._proc.wait()
        self._proc.stdout.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False

