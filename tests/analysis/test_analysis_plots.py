"""Point-cloud figures, checked through their artists: labels with units, points drawn, greyed vs coloured."""

from __future__ import annotations

import matplotlib
import numpy as np
import pytest

from cosim.analysis.plots import new_figure, save, scatter_cloud
from cosim.analysis.table import load_results
from cosim.cli.main import main
from tests.analysis.test_analysis_table import make_sweep_table
from tests.helpers.reference import pareto_naive

matplotlib.use("Agg")


def by_gid(ax, gid):
    found = [c for c in ax.collections if c.get_gid() == gid]
    return found[0] if found else None


def test_2d_cloud_greys_filtered_points_and_colours_the_rest(tmp_path):
    table = load_results(make_sweep_table(tmp_path / "s"))
    active = table.where("traj_q_via_2 >= -40")
    fig = new_figure()
    ax, counts = scatter_cloud(fig, table, "traj.q_via[2]", "traj.q_via[4]", color="energy", active=active)
    finite = table.ok_mask()  # the axes are parameters: every row has them
    assert counts.coloured == int(active.sum()) and counts.greyed == int((~active).sum()) and counts.missing == 0
    points, greyed = by_gid(ax, "points"), by_gid(ax, "greyed")
    assert len(points.get_offsets()) == counts.coloured and len(greyed.get_offsets()) == counts.greyed
    assert (points.get_offsets()[:, 0] >= -40).all() and (greyed.get_offsets()[:, 0] < -40).all()
    # greyed points are one grey; coloured ones carry the energy values through the colour map
    assert np.allclose(greyed.get_facecolors()[:, :3], 0.78)
    colour_values = points.get_array()
    assert np.allclose(np.sort(colour_values.compressed() if np.ma.isMaskedArray(colour_values) else colour_values),
                       np.sort(table.values("energy")[active]), equal_nan=True)
    # the colour bar spans the coloured rows only (failed rows have no energy)
    e = table.values("energy")[active]
    assert points.norm.vmin == pytest.approx(np.nanmin(e)) and points.norm.vmax == pytest.approx(np.nanmax(e))
    assert ax.get_xlabel() == "traj.q_via[2] [deg]" and ax.get_ylabel() == "traj.q_via[4] [deg]"
    colorbar_axes = [a for a in fig.axes if a is not ax]
    assert colorbar_axes and colorbar_axes[0].get_ylabel() == "energy [J]"
    assert finite.sum() < len(finite)  # the table really has failed rows


def test_rows_without_a_coordinate_are_counted_not_drawn(tmp_path):
    table = load_results(make_sweep_table(tmp_path / "s"))
    fig = new_figure()
    ax, counts = scatter_cloud(fig, table, "energy", "t_exec")
    assert counts.missing == 3 and counts.coloured == len(table.df) - 3 and counts.greyed == 0
    assert by_gid(ax, "greyed") is None and len(by_gid(ax, "points").get_offsets()) == len(table.df) - 3
    assert ax.get_xlabel() == "energy [J]" and ax.get_ylabel() == "t_exec [s]"


def test_3d_cloud_with_selection_ring(tmp_path):
    table = load_results(make_sweep_table(tmp_path / "s"))
    fig = new_figure()
    ax, counts = scatter_cloud(fig, table, "energy", "t_exec", z="reach", color="traj.q_via[4]", selected=0)
    assert ax.name == "3d" and ax.get_zlabel() == "reach [m]"
    points = by_gid(ax, "points")
    xs, ys, zs = points._offsets3d
    assert len(xs) == counts.coloured == len(table.df) - 3
    assert np.allclose(np.sort(np.asarray(zs)), np.sort(table.values("reach")[table.ok_mask()]))
    ring = by_gid(ax, "selected")
    assert ring is not None and np.asarray(ring._offsets3d[0])[0] == pytest.approx(table.values("energy")[0])


@pytest.mark.parametrize("suffix, magic", [(".png", b"\x89PNG"), (".svg", b"<?xml"), (".pdf", b"%PDF")])
def test_cli_plot_writes_each_format(tmp_path, capsys, suffix, magic):
    path = make_sweep_table(tmp_path / "s")
    out = tmp_path / f"fig{suffix}"
    code = main(["plot", str(path), "--x", "traj.q_via[2]", "--y", "traj.q_via[4]", "--color", "energy",
                 "--where", "energy < 40", "--only-ok", "-o", str(out)])
    assert code == 0
    table = load_results(path)
    ok, below = table.ok_mask(), table.where("energy < 40")
    assert f"{(ok & below).sum()} points coloured, {(ok & ~below).sum()} greyed" in capsys.readouterr().out
    assert out.read_bytes()[:5].startswith(magic)
    if suffix == ".svg":
        text = out.read_text()
        assert "traj.q_via[2] [deg]" in text and "energy [J]" in text


def test_17061_points_draw_with_one_scatter_per_group(tmp_path):
    """Two artists, not one per point (the drawing time is measured by benchmarks/analysis_speed.py)."""
    n2, n4 = 121, 141  # the thesis's grid: 17 061 points
    path = make_sweep_table(tmp_path / "big", n2=n2, n4=n4, failed=0)
    table = load_results(path)
    assert len(table.df) == 17061
    fig = new_figure()
    ax, counts = scatter_cloud(fig, table, "traj.q_via[2]", "traj.q_via[4]", color="energy",
                               active=table.where("energy < 60"))
    save(fig, tmp_path / "big.png")
    assert counts.coloured + counts.greyed == 17061
    assert len(ax.collections) == 2  # greyed + coloured: no per-point artists


def test_pareto_plot_marks_the_front_over_the_cloud(tmp_path, capsys):
    path = make_sweep_table(tmp_path / "s")
    out = tmp_path / "front.png"
    assert main(["pareto", str(path), "--plot", str(out), "--color", "traj.q_via[2]"]) == 0
    assert out.read_bytes()[:4] == b"\x89PNG"
    table = load_results(path)
    expected = pareto_naive(np.column_stack([table.values("energy"), table.values("t_exec")]))
    # draw it again in memory to inspect the artists the command drew
    from cosim.analysis.plots import draw_front

    fig = new_figure()
    ax, _ = scatter_cloud(fig, table, "energy", "t_exec", color="traj.q_via[2]")
    draw_front(ax, table, "energy", "t_exec", expected)
    front = by_gid(ax, "front")
    assert len(front.get_offsets()) == expected.sum()
    assert set(map(tuple, np.round(front.get_offsets(), 9))) == set(
        zip(np.round(table.values("energy")[expected], 9), np.round(table.values("t_exec")[expected], 9)))
    assert "Pareto front" in capsys.readouterr().out
