"""background.Beside: one call in a low-priority child process, its result, its failures."""

import os
import time

import pytest

from skyfit_mi.background import NICE, Beside
from skyfit_mi.errors import SkyfitError, UnknownNameError


def test_the_call_runs_in_a_child_at_low_priority_and_returns_its_result():
    with Beside("os:getpid") as pid, Beside("os:nice", 0) as nice, \
            Beside("builtins:divmod", 17, 5) as qr:
        assert pid.result() != os.getpid()
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
