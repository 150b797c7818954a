"""The policy built in a forked child: the same answer as in-process, and every failure recovered."""

from __future__ import annotations

import os
import threading

import numpy as np
import pytest

from fixplan.planner.policy import Policy, PolicyEntry
from fixplan.planner.policy_job import ENV, PendingPolicy, can_fork

pytestmark = pytest.mark.skipif(not hasattr(os, "fork"), reason="the platform has no fork")


def _policy(tag: float) -> Policy:
    entry = PolicyEntry(("A",), "B", "slide", np.array([tag, 2.0, 3.0]), 1.5, tag, "pre-image", True, (), None)
    return Policy({frozenset({"A"}): entry}, frozenset({frozenset({"A"})}), build_time_s=0.25)


def _built_where() -> tuple[Policy, dict[str, int]]:
    """A policy that records the process that built it (its entry's cost is the pid)."""
    return _policy(float(os.getpid())), {"pid": os.getpid()}


def test_forked_build_returns_the_childs_policy_and_memo() -> None:
    job = PendingPolicy(_built_where, fork=True)
    assert job.started_in_child
    policy = job.result()
    child = int(policy.entries[frozenset({"A"})].cost_to_go_m)
    assert child != os.getpid() and job.memo == {"pid": child}
    np.testing.assert_array_equal(policy.entries[frozenset({"A"})].wrench, [child, 2.0, 3.0])
    assert job.reachable == frozenset({frozenset({"A"})})  # attribute access delegates


def test_inline_build_runs_here() -> None:
    job = PendingPolicy(_built_where, fork=False)
    assert not job.started_in_child
    assert int(job.result().entries[frozenset({"A"})].cost_to_go_m) == os.getpid()


def test_a_child_that_raises_is_replaced_by_the_build_here() -> None:
    calls = {"n": 0}
    parent = os.getpid()

    def build() -> tuple[Policy, dict[str, int]]:
        calls["n"] += 1
        if os.getpid() != parent:
            raise RuntimeError("the child's build failed")
        return _policy(7.0), {}

    job = PendingPolicy(build, fork=True)
    assert job.result().entries[frozenset({"A"})].cost_to_go_m == 7.0
    assert calls["n"] == 1  # counted in the parent only: the child's call is in its own copy


def test_a_child_that_dies_is_replaced_by_the_build_here() -> None:
    parent = os.getpid()

    def build() -> tuple[Policy, dict[str, int]]:
        if os.getpid() != parent:
            os._exit(3)  # a crash: nothing written to the pipe
        return _policy(9.0), {}

    assert PendingPolicy(build, fork=True).result().entries[frozenset({"A"})].cost_to_go_m == 9.0


def test_the_build_error_is_raised_by_the_in_process_build() -> None:
    def build() -> tuple[Policy, dict[str, int]]:
        raise ValueError("no policy")

    job = PendingPolicy(build, fork=True)
    with pytest.raises(ValueError, match="no policy"):
        job.result()


def test_the_child_hook_runs_only_in_the_child() -> None:
    seen: list[int] = []
    job = PendingPolicy(_built_where, fork=True, in_child=lambda: seen.append(os.getpid()))
    job.result()
    assert seen == []  # the hook ran in the child's copy of the list


def test_no_fork_outside_the_main_thread_or_when_told(monkeypatch: pytest.MonkeyPatch) -> None:
    out: list[bool] = []
    t = threading.Thread(target=lambda: out.append(can_fork()))
    t.start()
    t.join()
    assert out == [False]
    monkeypatch.setenv(ENV, "inline")
    assert not can_fork()
    assert not PendingPolicy(_built_where).started_in_child


def test_solve_gives_the_same_policy_forked_and_inline(monkeypatch: pytest.MonkeyPatch) -> None:
    from fixplan.fixture import default_fixture_path, load
    from fixplan.planner.solve import solve

    fx = load(default_fixture_path())
    monkeypatch.setenv(ENV, "inline")
    inline = solve(fx)
    monkeypatch.delenv(ENV)
    forked = solve(fx)
    assert inline.status == forked.status == "planned"
    a, b = inline.policy, forked.policy
    assert a is not None and b is not None
    assert a.entries.keys() == b.entries.keys() and a.reachable == b.reachable
    for s, e in a.entries.items():
        f = b.entries[s]
        assert (e.next_state, e.motion, e.source, e.checked) == (f.next_state, f.motion, f.source, f.checked)
        if e.wrench is None:
            assert f.wrench is None
        else:
            np.testing.assert_array_equal(e.wrench, f.wrench)
