"""child.Child: calls in a fresh interpreter, their results, their errors as one line, and
the child's death as one line while this process goes on."""

import os
import signal

import pytest

from skyfit_mi.child import CallFailed, Child, ChildDied

CALLS = """
import os


def pid_and_path(x):
    return os.getpid(), x


def fail():
    raise RuntimeError("reading the file\\n  at line 3\\nit is truncated")
"""


@pytest.fixture
def child(tmp_path, monkeypatch):
    """A child that can import ``calls`` (written here: the child takes this sys.path)."""
    (tmp_path / "calls.py").write_text(CALLS)
    monkeypatch.syspath_prepend(str(tmp_path))
    c = Child()
    yield c
    c.close()


def test_calls_run_in_one_child_and_return_their_results(child):
    pid, value = child.call("calls:pid_and_path", {"a": [1, 2]})
    assert pid != os.getpid() and value == {"a": [1, 2]}
    assert child.call("calls:pid_and_path", 3) == (pid, 3)         # the same child
    assert child.call("builtins:divmod", 17, 5) == (3, 2)


def test_an_error_is_one_line_and_the_child_goes_on(child):
    with pytest.raises(CallFailed, match="^it is truncated$"):
        child.call("calls:fail")
    with pytest.raises(CallFailed, match="^No module named 'nowhere'$"):
        child.call("nowhere:read")
    assert child.call("builtins:abs", -2) == 2


def test_a_death_is_one_line_and_the_next_call_gets_a_new_child(child):
    pid, _ = child.call("calls:pid_and_path", 0)
    with pytest.raises(ChildDied, match="^exit status 3$"):
        child.call("os:_exit", 3)
    first, _ = child.call("calls:pid_and_path", 0)
    assert first != pid
    with pytest.raises(ChildDied, match="^SIGKILL"):
        child.call("os:kill", first, signal.SIGKILL)
    assert child.call("calls:pid_and_path", 0)[0] not in (pid, first)


def test_a_child_that_died_while_idle_is_replaced_and_close_ends_it(child):
    pid, _ = child.call("calls:pid_and_path", 0)
    os.kill(pid, signal.SIGKILL)                   # e.g. the kernel's OOM killer
    child._proc.wait()
    again, _ = child.call("calls:pid_and_path", 0)
    assert again != pid
    proc = child._proc
    child.close()
    assert proc.returncode == 0 and child._proc is None


def test_a_child_that_does_not_answer_by_the_deadline_is_killed(child):
    """A stuck child (a corrupted heap can spin) is killed at the call's deadline; the next
    call gets a new child."""
    pid, _ = child.call("calls:pid_and_path", 0)
    with pytest.raises(ChildDied, match=r"^no answer within 0.5 s \(killed\)$"):
        child.call("time:sleep", 60, timeout=0.5)
    assert child.call("calls:pid_and_path", 0, timeout=60)[0] != pid
