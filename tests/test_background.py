"""background.Beside: one call in a low-priority child process, its result, its failures;
each test with the child a fork and a fresh interpreter."""

import os
import time

import pytest

from skyfit_mi.background import NICE, Beside
from skyfit_mi.background import _forkable as forkable
from skyfit_mi.errors import SkyfitError, UnknownNameError


@pytest.fixture(autouse=True, params=["fork", "fresh interpreter"])
def start(request, monkeypatch):
    """Each test with either way of starting the child (background._forkable says which)."""
    import skyfit_mi.background as bg

    monkeypatch.setattr(bg, "_forkable", lambda: request.param == "fork")
    return request.param


def test_the_call_runs_in_a_child_at_low_priority_and_returns_its_result():
    with Beside("os:getpid") as pid, Beside("os:nice", 0) as nice, \
            Beside("builtins:divmod", 17, 5) as qr:
        assert pid.result() != os.getpid()
        nice._proc.wait()                # answered before the waiting parent raises it back
        assert nice.result() == NICE                 # Linux caps niceness at 19
        assert qr.result() == (3, 2)


def test_bad_input_in_the_child_is_raised_as_it_is():
    with Beside("skyfit_mi.errors:check_choice", "sky", "cloudy", ("clear",)) as job:
        with pytest.raises(UnknownNameError, match="unknown sky 'cloudy'; valid values"):
            job.result()
    assert issubclass(UnknownNameError, SkyfitError)


def test_a_failure_brings_its_traceback_and_a_death_its_exit_status():
    with Beside("math:sqrt", -1.0) as job:
        with pytest.raises(RuntimeError, match="(?s)math:sqrt failed in a child.*math domain"):
            job.result()
    with Beside("os:_exit", 3) as job:
        with pytest.raises(RuntimeError, match="ended without a result .exit status 3"):
            job.result()


def test_leaving_without_the_result_ends_the_child():
    t0 = time.perf_counter()
    with Beside("time:sleep", 60) as job:
        proc = job._proc
    assert proc.returncode is not None and time.perf_counter() - t0 < 30


FAILING = """
from skyfit_mi.errors import SetupError, SkyfitError


class OddError(SkyfitError):
    def __init__(self, what, why):
        super().__init__(f"{what}: {why}")


def no_backend():
    raise SetupError("no libLLVM >= 17 was found")


def odd():
    raise OddError("frame 3", "too dark")
"""


def test_setup_and_odd_errors_come_back_as_one_line_and_a_result_is_taken_once(tmp_path,
                                                                               monkeypatch):
    """A SetupError comes back as it is; a SkyfitError that does not pickle as a SkyfitError of
    its message; a result cannot be taken twice."""
    from skyfit_mi.errors import SetupError

    (tmp_path / "failing_calls.py").write_text(FAILING)
    monkeypatch.syspath_prepend(str(tmp_path))
    with Beside("failing_calls:no_backend") as job:
        with pytest.raises(SetupError, match="no libLLVM"):
            job.result()
        with pytest.raises(RuntimeError, match="already taken"):
            job.result()
    with Beside("failing_calls:odd") as job:
        with pytest.raises(SkyfitError, match="^frame 3: too dark$"):
            job.result()


def test_a_child_starved_of_a_core_is_given_up_and_the_call_made_here(monkeypatch):
    """Where the child cannot be given the parent's priority back (an unprivileged user) and
    gets less than STARVED of a core, the parent kills it and makes the call itself."""
    import skyfit_mi.background as bg

    def refused(*args):
        raise PermissionError("not allowed")
    monkeypatch.setattr(bg.os, "setpriority", refused)
    monkeypatch.setattr(bg, "WATCH_S", 0.2)
    with Beside("time:sleep", 1.0) as job:           # asleep: no CPU, as if starved
        t0 = time.perf_counter()
        assert job.result() is None
        assert job._proc.returncode == -9 and time.perf_counter() - t0 >= 1.0
    with Beside("os:getpid") as job:                 # an answer given is the child's
        job._proc.wait()
        assert job.result() == job._proc.pid != os.getpid()


def test_the_child_is_a_fork_only_before_drjit_is_loaded_and_with_no_other_thread(monkeypatch):
    """Dr.Jit's thread pool and LLVM, and another thread's locks, do not survive a fork."""
    import sys
    import threading

    monkeypatch.delitem(sys.modules, "drjit", raising=False)
    assert forkable() == sys.platform.startswith("linux")
    monkeypatch.setitem(sys.modules, "drjit", None)
    assert not forkable()
    monkeypatch.delitem(sys.modules, "drjit")
    stop = threading.Event()
    other = threading.Thread(target=stop.wait)
    other.start()
    try:
        assert not forkable()
    finally:
        stop.set()
        other.join()


def test_a_stuck_child_is_given_up_and_the_call_made_here(monkeypatch):
    """A child that uses no core while waited on (a deadlock would wait forever) is killed and
    its call made in the parent, also where it has been given the parent's priority."""
    import skyfit_mi.background as bg

    monkeypatch.setattr(bg, "WATCH_S", 0.1)
    monkeypatch.setattr(bg, "STALLED_S", 0.3)
    with Beside("time:sleep", 1.0) as job:           # asleep: no CPU, as if stuck
        t0 = time.perf_counter()
        assert job.result() is None
        assert job._proc.returncode == -9 and time.perf_counter() - t0 >= 1.0
