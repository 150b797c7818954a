"""Jobs run ahead on a second core: the same answers as in-process, and every failure recovered."""

from __future__ import annotations

import os
import time

import numpy as np
import pytest

from fixplan.planner.spare import ENV, SpareCore, spare_cpu

pytestmark = pytest.mark.skipif(not hasattr(os, "fork"), reason="the platform has no fork")


def _where(job: object) -> tuple[object, int]:
    """The job back, with the process that ran it."""
    if job == "raise":
        raise ValueError("a job that fails")
    if job == "die":
        os._exit(3)
    if job == "sleep":
        time.sleep(30.0)
    return job, os.getpid()


def test_a_job_offered_is_run_in_the_child_and_taken_once() -> None:
    with SpareCore(_where, fork=True) as spare:
        assert spare.active
        assert spare.offer("k", ("a", np.arange(3.0)))
        assert spare.pending("k")
        assert not spare.offer("k2", "b")  # one job at a time: busy until the answer is collected
        found, (job, pid) = spare.take("k")
        assert found and pid != os.getpid()
        assert job[0] == "a" and np.array_equal(job[1], np.arange(3.0))
        assert spare.take("k") == (False, None)  # taken once
        assert (spare.offered, spare.taken) == (1, 1)
        assert spare.offer("k2", "b")  # idle again


def test_a_key_never_offered_is_not_found() -> None:
    with SpareCore(_where, fork=True) as spare:
        spare.offer("k", "a")
        assert spare.take("other") == (False, None)
        assert spare.take("k")[0]


def test_a_job_that_raises_is_not_found_and_the_child_goes_on() -> None:
    with SpareCore(_where, fork=True) as spare:
        spare.offer("bad", "raise")
        assert spare.take("bad") == (False, None)
        assert spare.offer("good", "a")
        assert spare.take("good")[0]


def test_a_child_that_dies_leaves_an_inert_core() -> None:
    with SpareCore(_where, fork=True) as spare:
        spare.offer("k", "die")
        assert spare.take("k") == (False, None)
        assert not spare.active
        assert not spare.offer("k2", "a")


def test_close_drops_a_running_job_at_once() -> None:
    spare = SpareCore(_where, fork=True)
    pid = spare._pid
    assert pid is not None
    spare.offer("k", "sleep")
    t0 = time.perf_counter()
    spare.close()
    assert time.perf_counter() - t0 < 5.0  # not the job's 30 s
    with pytest.raises(ChildProcessError):
        os.waitpid(pid, 0)  # reaped
    assert spare.take("k") == (False, None)


def test_inert_without_a_child() -> None:
    spare = SpareCore(_where, fork=False)
    assert not spare.active
    assert not spare.offer("k", "a")
    assert spare.take("k") == (False, None)


def test_the_environment_forces_it_either_way(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(ENV, "off")
    assert not spare_cpu()
    monkeypatch.setenv(ENV, "on")
    assert spare_cpu() == ((os.cpu_count() or 1) >= 2)
    monkeypatch.setenv(ENV, "auto")
    assert not spare_cpu(idle_cpus=float(os.cpu_count() or 1) + 1.0)  # never that many idle


def test_a_plan_is_the_same_with_and_without_the_second_core(monkeypatch: pytest.MonkeyPatch) -> None:
    """The free-start box: its search asks for siblings and confirms a sequence (both run ahead)."""
    from conftest import PROBLEMS

    import fixplan.planner.spare as spare_module
    from fixplan.fixture import load
    from fixplan.locating import contact_set
    from fixplan.planner.solve import Planner

    fx = load(PROBLEMS / "box-tilted-start.toml")
    counts: list[tuple[int, int]] = []
    close = spare_module.SpareCore.close

    def counting_close(self: SpareCore) -> None:
        if self.active:
            counts.append((self.offered, self.taken))
        close(self)

    monkeypatch.setattr(spare_module.SpareCore, "close", counting_close)
    plans = []
    for mode in ("off", "on"):
        monkeypatch.setenv(ENV, mode)
        planner = Planner(fx)
        touching = contact_set(fx, "start").contacts
        plans.append(planner.plan_from(fx.start, frozenset(c.owner for c in touching if c.kind == "locator")))
    off, on = plans
    if (os.cpu_count() or 1) >= 2:
        assert counts and counts[0][0] >= 1  # jobs were run ahead
    assert off.found and on.found
    assert [t.target for t in off.transitions] == [t.target for t in on.transitions]
    for a, b in zip(off.transitions, on.transitions, strict=True):
        assert a.cost == b.cost
        for pa, pb in zip(a.poses, b.poses, strict=True):
            np.testing.assert_array_equal(pa.p_world, pb.p_world)
            np.testing.assert_array_equal(pa.R_world_body, pb.R_world_body)
        np.testing.assert_array_equal(a.wrenches, b.wrenches)
