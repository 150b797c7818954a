"""Plan figures: the plotted data is the verification trace (or the plan's knots), and the CLI writes them safely."""

import re
from pathlib import Path

import matplotlib
import numpy as np
import pytest
from conftest import ROOT

import fixplan
from fixplan.cli import main
from fixplan.errors import InputError
from fixplan.locating import locator_gaps
from fixplan.planner.solve import solve
from fixplan.present.plots import (
    bar_intervals,
    boundaries_s,
    figure_path,
    plan_figure,
    planned_intervals,
    pressed_intervals,
)
from fixplan.present.report import report_markdown

matplotlib.use("Agg")

JAMS = ROOT / "problems" / "naive-order-jams.toml"
WEAK = ROOT / "problems" / "box-weak-hand.toml"


@pytest.fixture(scope="module")
def fixture():
    return fixplan.load(JAMS)


@pytest.fixture(scope="module")
def verified(jams_plan):
    result = jams_plan  # solve(fixture), shared with other modules
    assert result.ok and result.verification is not None and result.verification.trace is not None
    return result


@pytest.fixture(scope="module")
def unverified(fixture):
    return solve(fixture, run_verification=False)


@pytest.fixture(scope="module")
def verified_figure(verified, fixture):
    import matplotlib.pyplot as plt

    fig = plan_figure(verified, fixture)
    yield fig
    plt.close(fig)


def _axes(fig, label):
    found = [ax for ax in fig.axes if ax.get_label() == label]
    assert len(found) == 1, [ax.get_label() for ax in fig.axes]
    return found[0]


def _line(ax, label):
    found = [ln for ln in ax.get_lines() if ln.get_label() == label and ln.get_gid() != "planned"]
    assert len(found) == 1, [ln.get_label() for ln in ax.get_lines()]
    return found[0]


def test_force_and_gap_lines_are_the_trace(verified, verified_figure):
    tr = verified.verification.trace
    for label, data in (("normal_forces", tr.normal_forces_N), ("gaps", tr.gaps_m)):
        ax = _axes(verified_figure, label)
        for i, name in enumerate(tr.names):
            line = _line(ax, name)
            np.testing.assert_array_equal(line.get_xdata(), tr.time_s)
            np.testing.assert_array_equal(line.get_ydata(), data[:, i])
    assert _axes(verified_figure, "gaps").get_yscale() == "symlog"


def test_wrench_lines_are_the_coupling_wrench_and_the_plan(verified, verified_figure):
    tr = verified.verification.trace
    for panel, comps in (("force", ("Fx", "Fy")), ("moment", ("Mz",))):
        ax = _axes(verified_figure, panel)
        for c in comps:
            j = ("Fx", "Fy", "Mz").index(c)
            np.testing.assert_array_equal(_line(ax, c).get_ydata(), tr.coupling_wrench[:, j])
        planned = [ln for ln in ax.get_lines() if ln.get_gid() == "planned"]
        assert len(planned) == len(comps)
        # the plan's wrench per segment: transition 1, segment 0 from t = 0
        first = verified.transitions[0].wrenches[0]
        for ln, c in zip(planned, comps, strict=True):
            assert ln.get_xdata()[0] == 0.0 and ln.get_ydata()[0] == first[("Fx", "Fy", "Mz").index(c)]
            assert ln.get_xdata()[-1] == pytest.approx(sum(verified.durations_s))


def test_state_bars_cover_exactly_the_pressed_samples(verified, verified_figure):
    tr = verified.verification.trace
    ax = _axes(verified_figure, "states")
    expected = pressed_intervals(tr.time_s, tr.pressed, tr.names)
    for name in tr.names:
        bars = bar_intervals(ax, f"pressed:{name}")
        np.testing.assert_allclose(np.reshape(bars, (-1, 2)), np.reshape(expected[name], (-1, 2)))
        assert all(a < b for a, b in bars) and all(b1 < a2 for (_, b1), (a2, _) in zip(bars, bars[1:], strict=False))
        for t, pressed in zip(tr.time_s, tr.pressed, strict=True):
            inside = any(a <= t <= b for a, b in bars)
            assert inside == (name in pressed), (name, t)
    # the plan: B1 from the start, B2 from the end of transition 1, S1 from the end of transition 2
    ends = np.cumsum(verified.durations_s)
    assert verified.sequence == [("B1",), ("B1", "B2"), ("B1", "B2", "S1")]
    for name, start in (("B1", 0.0), ("B2", ends[0]), ("S1", ends[1])):
        # (the plan's nominal schedule; the feedback executor may finish sooner than it)
        np.testing.assert_allclose(bar_intervals(ax, f"planned:{name}"), [(start, max(start, tr.time_s[-1]))])


def test_transition_boundaries_are_marked_in_every_panel(verified, verified_figure):
    ends = np.cumsum(verified.durations_s)
    np.testing.assert_allclose(boundaries_s(verified.durations_s), ends)
    assert len(verified_figure.axes) == 5
    for ax in verified_figure.axes:
        xs = sorted(ln.get_xdata()[0] for ln in ax.get_lines() if ln.get_gid() == "boundary")
        np.testing.assert_allclose(xs, ends)


def test_intervals_from_samples_by_hand():
    t = [0.0, 1.0, 2.0, 3.0, 4.0]
    pressed = [("A",), ("A", "B"), (), ("B",), ("A", "B")]
    got = pressed_intervals(t, pressed, ["A", "B", "C"])
    assert got == {"A": [(0.0, 1.5), (3.5, 4.0)], "B": [(0.5, 1.5), (2.5, 4.0)], "C": []}
    planned = planned_intervals([("A",), ("A", "B")], [2.0], ["A", "B", "C"], 5.0)
    assert planned == {"A": [(0.0, 5.0)], "B": [(2.0, 5.0)], "C": []}


def test_without_a_trace_the_gaps_are_the_plans_knots(unverified, fixture):
    import matplotlib.pyplot as plt

    fig = plan_figure(unverified, fixture)
    try:
        assert [ax.get_label() for ax in fig.axes] == ["gaps", "force", "moment", "states"]
        ax = _axes(fig, "gaps")
        poses = [unverified.transitions[0].poses[0]] + [p for tr in unverified.transitions for p in tr.poses[1:]]
        gaps = np.array([locator_gaps(fixture.workpiece, p, fixture.locators) for p in poses])
        for i, loc in enumerate(fixture.locators):
            (line,) = [ln for ln in ax.get_lines() if ln.get_label() == loc.name]
            np.testing.assert_array_equal(line.get_ydata(), gaps[:, i])
            x = np.asarray(line.get_xdata())
            assert x[0] == 0.0 and x[-1] == pytest.approx(sum(unverified.durations_s))
            assert np.all(np.diff(x) > 0)
        states = _axes(fig, "states")
        assert all(bar_intervals(states, f"pressed:{loc.name}") == [] for loc in fixture.locators)
        assert bar_intervals(states, "planned:S1")[0][0] == pytest.approx(sum(unverified.durations_s))
    finally:
        plt.close(fig)


def test_report_links_figures_only_when_given(verified, fixture):
    assert "## Figures" not in report_markdown(verified, fixture)
    text = report_markdown(verified, fixture, figures=["plan.png"])
    assert "## Figures" in text and "](plan.png)" in text


def test_figure_path_is_beside_the_report():
    assert figure_path(Path("out/plan.md")) == Path("out/plan.png")
    with pytest.raises(InputError, match="overwrite"):
        figure_path(Path("plan.png"))


def _links(md: Path) -> list[Path]:
    return [md.parent / link for link in re.findall(r"!\[[^\]]*\]\(([^)]+)\)", md.read_text())]


def test_cli_writes_the_figure_and_refuses_to_overwrite(tmp_path, capsys):
    md = tmp_path / "sub" / "plan.md"
    png = tmp_path / "sub" / "plan.png"
    assert main(["solve", str(JAMS), "--report", str(md)]) == 0
    assert md.exists() and png.exists() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    links = _links(md)
    assert links == [png] and all(p.exists() for p in links)
    capsys.readouterr()

    before = {p: (p.read_bytes(), p.stat().st_mtime_ns) for p in (md, png)}
    assert main(["solve", str(JAMS), "--report", str(md)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(md) in err[0] and "exists" in err[0]
    md.unlink()
    del before[md]
    assert main(["solve", str(JAMS), "--report", str(md)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(png) in err[0] and "exists" in err[0]
    assert not md.exists() and {p: (p.read_bytes(), p.stat().st_mtime_ns) for p in before} == before

    assert (
        main(["solve", str(JAMS), "--report", str(md), "--no-verify", "--force"]) == 1
    )  # written, but unverified: exit 1
    assert png.stat().st_mtime_ns != before[png][1]
    assert "The plan alone" in md.read_text() and all(p.exists() for p in _links(md))


def test_cli_infeasible_plan_has_no_figure(tmp_path, capsys):
    md = tmp_path / "weak.md"
    assert main(["solve", str(WEAK), "--no-verify", "--report", str(md)]) == 1
    assert md.exists() and not (tmp_path / "weak.png").exists() and _links(md) == []


def test_drawing_leaves_the_callers_backend_alone(fixture, verified, tmp_path):
    """A notebook's inline backend must survive save_map and the plan figure (no matplotlib.use inside)."""
    from fixplan.mapping import jamming_map
    from fixplan.present.maps import save_map
    from fixplan.present.plots import save_plan_figure

    before = matplotlib.get_backend()
    matplotlib.use("svg")
    try:
        save_plan_figure(verified, fixture, tmp_path / "plan.png")
        m = jamming_map(fixture, (0, 2), [(-1.0, 1.0), (-0.1, 0.1)], 3, axis_names=("Fx", "Mz"))
        save_map(m, tmp_path / "map.png")
        assert matplotlib.get_backend() == "svg"
        assert (tmp_path / "plan.png").stat().st_size > 10_000 and (tmp_path / "map.png").stat().st_size > 1_000
    finally:
        matplotlib.use(before)
