"""Renders, GIFs and landmark plots."""
import matplotlib.pyplot as plt
import numpy as np
import pytest

from facelib import viz
from facelib.face import get_template


def test_render_face_draws_a_face():
    t = get_template()
    img = viz.render_face(t.vertices, size=(120, 150))
    assert img.shape == (150, 120, 3) and img.dtype == np.uint8
    face_pixels = (img < 250).any(axis=2)
    assert 0.2 < face_pixels.mean() < 0.9  # a face in the middle, background around it
    assert not face_pixels[:, 0].any() and not face_pixels[:, -1].any()


def test_renderer_updates_geometry_and_colours():
    t = get_template()
    r = viz.FaceRenderer(size=(100, 120))
    a = r.render(t.vertices, scalars=np.zeros(len(t.vertices)), clim=(0, 1))
    b = r.render(t.vertices * [1, 0.8, 1], scalars=np.ones(len(t.vertices)), clim=(0, 1))
    r.close()
    assert np.abs(a.astype(int) - b.astype(int)).mean() > 1


def test_gif_html_and_landmark_plot_validate():
    frames = [np.full((10, 12, 3), k * 20, np.uint8) for k in range(3)]
    html = viz.gif_html(frames)
    assert html.startswith('<img src="data:image/gif;base64,')
    with pytest.raises(ValueError, match=r"landmarks must have shape \(68, 3\)"):
        viz.plot_landmarks(np.zeros((10, 3)))


def test_steps_figure_draws_one_line_per_task_and_sampler_with_its_interval():
    columns = ["task", "sampler", "steps", "s per sequence", "Acc (%)", "95 % interval", "FID", "95 % interval",
               "diversity", "95 % interval"]
    rows = [[task, sampler, k, 0.1, acc, [acc - 5, acc + 5], fid, [fid - 1, fid + 1], 9.0, [8.0, 10.0]]
            for task, acc in (("unconditional", 0.0), ("label control (Alg. 1)", 80.0), ("label control (x)", 70.0))
            for sampler, fid in (("ddpm", 3.0), ("ddim", 5.0)) for k in (10, 50)]
    for r in rows[:4]:  # unconditional: no accuracy
        r[4:6] = ["", ""]
    fig = viz.steps_figure({"columns": columns, "rows": rows})
    unconditional, acc, fid = fig.axes
    assert len(unconditional.lines) == 2 and len(acc.lines) == 4 and len(fid.lines) == 4
    assert list(fid.lines[2].get_ydata()) == [3.0, 3.0] and acc.get_ylabel() == "Acc (%)"
    assert [t.get_text() for t in fid.get_legend().get_texts()][:2] == ["DDPM (Alg. 1)", "DDIM (Alg. 1)"]
    plt.close(fig)


def test_spiral_figure_draws_each_spiral_of_each_vertex_and_numbers_the_longest():
    from facelib.models import spiral
    t = get_template()
    spirals = {n: spiral.template_spirals(0, n) for n in (25, 9)}
    where = {"mouth corner": t.vertex(27, 44), "cheek": t.vertex(40, 47)}
    fig = viz.spiral_figure(t.canonical, t.faces, spirals, where)
    for ax, v in zip(fig.axes, where.values()):
        lines = [line for line in ax.get_lines() if line.get_label().startswith("L = ")]
        assert [len(line.get_xdata()) for line in lines] == [25, 9]
        np.testing.assert_array_equal(lines[1].get_xdata(), t.canonical[spirals[9][v], 0])
        assert [a.get_text() for a in ax.texts] == [str(k) for k in range(25)]
    plt.close(fig)


def test_tradeoff_figure_draws_each_setting_at_its_fid_and_accuracy():
    scores = {"Adagrad, lr 0.03": dict(accuracy=70.0, accuracy_ci=(60.0, 80.0), fid=2.0, fid_ci=(1.0, 4.0)),
              "no guidance": dict(accuracy=10.0, accuracy_ci=(5.0, 15.0), fid=5.0, fid_ci=(3.0, 8.0))}
    ax = viz.tradeoff_figure(scores, "title").axes[0]
    points = [c.get_children()[0] for c in ax.containers]  # each errorbar's data line
    assert [tuple(p.get_xydata()[0]) for p in points] == [(2.0, 70.0), (5.0, 10.0)]
    assert [p.get_marker() for p in points] == ["o", "x"] and ax.get_xscale() == "log"
    plt.close("all")


def test_grouped_bars_draw_one_bar_per_series_and_group():
    fig, ax = plt.subplots()
    viz.grouped_bars(ax, ["a", "b", "c"], {"x": [1, 2, 3], "y": [4, 5, 6]}, "acc", "t")
    heights = [p.get_height() for p in ax.patches]
    assert heights == [1, 2, 3, 4, 5, 6] and [t.get_text() for t in ax.get_xticklabels()] == ["a", "b", "c"]
    plt.close("all")


def test_shade_missing_frames_leaves_each_run_of_given_frames_white():
    fig, ax = plt.subplots()
    viz.shade_missing_frames(ax, [True, True, False, False, True])
    spans = [(p.get_facecolor()[:3], p.get_x(), p.get_x() + p.get_width()) for p in ax.patches]
    grey, white = (0.93,) * 3, (1.0, 1.0, 1.0)
    assert [(tuple(np.round(c, 2)), a, b) for c, a, b in spans] == [
        (grey, -0.5, 4.5), (white, -0.5, 1.5), (white, 3.5, 4.5)]
    plt.close("all")


def test_confusion_figure_writes_each_nonzero_count_in_its_cell():
    counts = np.array([[3, 1], [0, 2]])
    ax = viz.confusion_figure(counts, ["a", "b"], "t").axes[0]
    written = {(t.get_position(), t.get_text()) for t in ax.texts}
    assert written == {((0, 0), "3"), ((1, 0), "1"), ((1, 1), "2")}
    assert np.allclose(ax.images[0].get_array(), [[0.75, 0.25], [0, 1]])
    plt.close("all")


def test_au_curves_figure_draws_the_request_and_each_sequence_per_au():
    names = ("AU1", "AU2", "AU12L")
    requested = np.zeros((40, 3))
    requested[:, 2] = np.linspace(0, 0.8, 40)
    fitted, read = np.full((2, 40, 3), 0.5), np.full((1, 40, 3), 0.3)
    fig = viz.au_curves_figure(requested, {"rig fit": fitted, "R reads": read}, ["AU12L", "AU2"], names)
    smile, brow = fig.axes
    assert smile.get_title() == "AU12L" and brow.get_title() == "AU2" and len(smile.lines) == 1 + 2 + 1
    assert smile.lines[0].get_ydata()[-1] == pytest.approx(0.8) and list(smile.lines[3].get_ydata()[:2]) == [0.3, 0.3]
    assert [t.get_text() for t in brow.get_legend().get_texts()] == ["requested", "rig fit", "R reads"]
    plt.close(fig)


def test_au_curves_figure_draws_the_request_only_where_it_constrains():
    names = ("AU1", "AU2", "AU12L")
    requested, mask = np.zeros((40, 3)), np.zeros((40, 3), dtype=bool)
    mask[:, 2] = True  # AU12L constrained (to 0), AU2 free
    fig = viz.au_curves_figure(requested, {"rig fit": np.full((1, 40, 3), 0.5)}, ["AU12L", "AU2"], names, mask)
    smile, brow = fig.axes
    assert len(smile.lines) == 2 and list(smile.lines[0].get_ydata()[:2]) == [0.0, 0.0]
    assert len(brow.lines) == 1 and brow.get_title() == "AU2 (free)"  # no requested 0-line for a free AU
    assert [t.get_text() for t in brow.get_legend().get_texts()] == ["requested", "rig fit"]
    with pytest.raises(ValueError, match="mask must be a bool array of the request's shape"):
        viz.au_curves_figure(requested, {}, ["AU2"], names, mask[:10])
    plt.close("all")


def test_keyframe_figure_takes_a_position_or_a_zero_displacement():
    neutral = np.zeros((68, 3))
    neutral[54] = [10.0, 0.0, 0.0]
    x = np.broadcast_to(neutral, (1, 40, 68, 3)).copy()
    x[0, :, 54, 1] = np.minimum(np.arange(40), 8)
    by_position = viz.keyframe_figure({"both": x}, {"frame": 25, "landmark": 54, "position": [10.0, 8.0, 0.0]},
                                      neutral, p95=0.7)
    assert by_position.axes[0].lines[1].get_ydata()[0] == pytest.approx(8.0)  # the star: 8 mm from neutral
    assert list(by_position.axes[0].lines[0].get_ydata()[[0, 5, 30]]) == [0.0, 5.0, 8.0]
    held = viz.keyframe_figure({"both": x}, {"frame": 0, "landmark": 54, "displacement": [0, 0, 0]}, neutral, 0.7)
    assert held.axes[0].lines[1].get_ydata()[0] == 0.0 and held.axes[0].lines[0].get_ydata()[5] == 5.0
    with pytest.raises(ValueError, match="one of 'position' or 'displacement'"):
        viz.keyframe_figure({"both": x}, {"frame": 0, "landmark": 54}, neutral, 0.7)
    plt.close("all")


def test_keyframe_figure_plots_the_displacement_along_the_key_and_the_speed():
    neutral = np.zeros((68, 3))
    x = np.zeros((1, 40, 68, 3))
    x[0, :, 54, 1] = np.minimum(np.arange(40), 8)  # the corner rises 1 mm a frame up to 8 mm
    key = {"frame": 25, "landmark": 54, "displacement": [0.0, 8.0, 0.0]}
    fig = viz.keyframe_figure({"replace": x, "both": x + 0.5}, key, neutral, p95=0.7)
    path, speed = fig.axes
    assert list(path.lines[0].get_ydata()[[0, 5, 30]]) == [0.0, 5.0, 8.0]
    assert path.lines[2].get_xdata()[0] == 25 and path.lines[2].get_ydata()[0] == pytest.approx(8.0)  # the key
    assert speed.lines[0].get_ydata()[0] == pytest.approx(1.0) and speed.lines[-1].get_ydata()[0] == 0.7
    plt.close(fig)
