"""Pictures of the book: matplotlib plots and animations, pyvista off-screen face
renders.

One style for the whole book (:func:`set_style`), one camera and lighting for every face
render (front view, so faces are comparable across chapters), landmark plots with the
iBUG-68 contours, and animations as small looping GIFs embedded in the page.
"""

from __future__ import annotations

import base64
import inspect
import io
import os
import warnings
from dataclasses import dataclass

import numpy as np

# off-screen, no X
os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")

import matplotlib.pyplot as plt  # noqa: E402

from .face import template as tpl  # noqa: E402  (the module)

# iBUG-68 contours: (first, last, closed)
CONTOURS = (
    (0, 16, False),
    (17, 21, False),
    (22, 26, False),
    (27, 30, False),
    (31, 35, False),
    (36, 41, True),
    (42, 47, True),
    (48, 59, True),
    (60, 67, True),
)
VIEWS = {  # camera position, focal point, up: front and three-quarter
    "front": [(0.0, -2.0, 470.0), (0.0, -2.0, 0.0), (0.0, 1.0, 0.0)],
    "three_quarter": [(330.0, 30.0, 450.0), (0.0, -2.0, 0.0), (0.0, 1.0, 0.0)],
    "side": [(560.0, -2.0, 0.0), (0.0, -2.0, 0.0), (0.0, 1.0, 0.0)],
}


def set_style():
    """The book's matplotlib style (call once per notebook)."""
    plt.rcParams.update(
        {
            "figure.dpi": 100,
            "savefig.dpi": 100,
            "font.size": 10,
            "axes.titlesize": 10,
            "axes.grid": True,
            "grid.alpha": 0.3,
            "axes.spines.top": False,
            "axes.spines.right": False,
            "image.cmap": "viridis",
            "legend.frameon": False,
        }
    )


def show_source(obj):
    """Display the source code of a facelib function or class in the notebook."""
    from IPython.display import Markdown, display

    display(Markdown(f"```python\n{inspect.getsource(obj).rstrip()}\n```"))


SKIN_RGB = tpl.SKIN  # one colour for a reader's own mesh, which has no albedo


class FaceRenderer:
    """Off-screen pyvista renderer with the book's fixed camera and lights.

    ``render(vertices)`` returns an RGB image (H, W, 3) uint8.  Colour comes from the
    template's albedo, or from per-vertex ``scalars`` mapped through ``cmap`` within
    ``clim`` (e.g. an error in mm).  Reuse one renderer for many frames: only the vertex
    positions change.
    """

    def __init__(self, size=(320, 400), view="front", faces=None, zoom=1.0):
        # pyvista imports pooch, whose tqdm.auto warns in notebooks without ipywidgets
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="IProgress not found")
            import pyvista as pv
        self._pv = pv
        self.size, self.view, self.zoom = size, view, zoom
        self.faces = tpl.get_template().faces if faces is None else np.asarray(faces)
        self._plotter = None
        self._key = None

    def _setup(self, vertices, colors, scalars, cmap, clim, landmarks):
        pv = self._pv
        faces = np.hstack([np.full((len(self.faces), 1), 3), self.faces]).ravel()
        self.mesh = pv.PolyData(np.asarray(vertices, float), faces)
        p = pv.Plotter(off_screen=True, window_size=self.size, lighting="none")
        kw = dict(
            smooth_shading=True,
            specular=0.15,
            specular_power=15,
            diffuse=0.8,
            ambient=0.28,
        )
        if scalars is not None:
            self.mesh["scalars"] = np.asarray(scalars, float)
            self.actor = p.add_mesh(
                self.mesh,
                scalars="scalars",
                cmap=cmap,
                clim=clim,
                show_scalar_bar=False,
                **kw,
            )
        else:
            rgb = tpl.get_template().colors if colors is None else np.asarray(colors)
            self.mesh["rgb"] = (np.clip(rgb, 0, 1) * 255).astype(np.uint8)
            self.actor = p.add_mesh(self.mesh, scalars="rgb", rgb=True, **kw)
        if landmarks is not None:
            self.points_actor = p.add_mesh(
                pv.PolyData(np.asarray(landmarks, float)),
                color="#1f77b4",
                point_size=7,
                render_points_as_spheres=True,
            )
        p.add_light(
            pv.Light(position=(-180, 220, 420), focal_point=(0, 0, 0), intensity=0.85)
        )
        p.add_light(
            pv.Light(position=(260, -60, 320), focal_point=(0, 0, 0), intensity=0.35)
        )
        p.add_light(
            pv.Light(position=(0, 0, 600), focal_point=(0, 0, 0), intensity=0.15)
        )
        p.set_background("white")
        p.camera_position = VIEWS[self.view]
        p.camera.view_angle = 30.0 / self.zoom
        self._plotter = p

    def render(
        self,
        vertices,
        colors=None,
        scalars=None,
        cmap="magma_r",
        clim=None,
        landmarks=None,
    ):
        key = (
            colors is None,
            scalars is None,
            cmap,
            None if clim is None else tuple(clim),
            landmarks is None,
        )
        if self._plotter is None or key != self._key:
            self.close()
            self._setup(vertices, colors, scalars, cmap, clim, landmarks)
            self._key = key
        else:
            mesh = self.actor.mapper.dataset
            mesh.points = np.asarray(vertices, float)
            name, values = (
                ("scalars", np.asarray(scalars, float))
                if scalars is not None
                else (
                    "rgb",
                    (
                        None
                        if colors is None
                        else (np.clip(colors, 0, 1) * 255).astype(np.uint8)
                    ),
                )
            )
            if values is not None:
                mesh.point_data[name][:] = values
                mesh.point_data.GetArray(name).Modified()
            mesh.compute_normals(inplace=True, cell_normals=False, split_vertices=False)
            if landmarks is not None:
                self.points_actor.mapper.dataset.points = np.asarray(landmarks, float)
            self._plotter.render()
        return self._plotter.screenshot(return_img=True)

    def close(self):
        if self._plotter is not None:
            self._plotter.close()
            self._plotter = None

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass


def render_face(vertices, **kwargs):
    """Render one mesh (V, 3) with the book's camera; keyword arguments go to
    FaceRenderer.render."""
    size = kwargs.pop("size", (320, 400))
    view = kwargs.pop("view", "front")
    r = FaceRenderer(size=size, view=view)
    try:
        return r.render(vertices, **kwargs)
    finally:
        r.close()


@dataclass(frozen=True)
class Heatmap:
    """Per-vertex values shown on the faces of :func:`face_grid`: one array per mesh,
    coloured with ``cmap`` within ``clim`` (None: from 0 to the largest value) under a
    shared colour bar labelled ``label``.
    """

    values: list
    cmap: str = "magma_r"
    clim: tuple | None = None
    label: str = "mm"


def face_grid(
    meshes,
    titles=None,
    ncols=6,
    size=(240, 300),
    view="front",
    panel_width=2.0,
    heatmap=None,
    **render,
):
    """A matplotlib figure with one rendered face per panel (all with the same camera),
    optionally coloured by a :class:`Heatmap`; ``render`` goes to
    :meth:`FaceRenderer.render`."""
    meshes = list(meshes)
    nrows = int(np.ceil(len(meshes) / ncols))
    ncols = min(ncols, len(meshes))
    fig, axes = plt.subplots(
        nrows,
        ncols,
        figsize=(panel_width * ncols, panel_width * 1.25 * nrows),
        squeeze=False,
    )
    clim = None
    if heatmap is not None:
        clim = heatmap.clim or (0.0, float(max(np.max(v) for v in heatmap.values)))
    renderer = FaceRenderer(size=size, view=view)
    try:
        for k, ax in enumerate(axes.ravel()):
            ax.axis("off")
            if k < len(meshes):
                extra = (
                    {}
                    if heatmap is None
                    else dict(scalars=heatmap.values[k], cmap=heatmap.cmap, clim=clim)
                )
                ax.imshow(renderer.render(meshes[k], **extra, **render))
                if titles is not None:
                    ax.set_title(titles[k])
    finally:
        renderer.close()
    fig.tight_layout()
    if heatmap is not None:
        sm = plt.cm.ScalarMappable(cmap=heatmap.cmap, norm=plt.Normalize(*clim))
        fig.colorbar(sm, ax=axes.ravel().tolist(), shrink=0.6, label=heatmap.label)
    return fig


def plot_landmarks(
    landmarks, ax=None, color="C0", label=None, numbers=False, view="front", **kwargs
):
    """Front (x, y) or side (z, y) projection of 68 landmarks with the iBUG-68
    contours."""
    lm = np.asarray(landmarks)
    if lm.shape != (68, 3):
        raise ValueError(f"landmarks must have shape (68, 3), got {lm.shape}")
    ax = ax or plt.gca()
    h = 2 if view == "side" else 0
    for a, b, closed in CONTOURS:
        idx = list(range(a, b + 1)) + ([a] if closed else [])
        ax.plot(lm[idx, h], lm[idx, 1], "-", color=color, lw=1.0, **kwargs)
    ax.plot(lm[:, h], lm[:, 1], "o", color=color, ms=2.5, label=label, **kwargs)
    if numbers:
        for i, p in enumerate(lm):
            ax.annotate(
                str(i),
                (p[h], p[1]),
                fontsize=6,
                xytext=(2, 2),
                textcoords="offset points",
            )
    ax.set_aspect("equal")
    ax.set_xlabel("z (mm)" if view == "side" else "x (mm)")
    ax.set_ylabel("y (mm)")
    return ax


def gif_bytes(frames, fps=12):
    """Encode RGB frames (list of (H, W, 3) uint8) as a looping GIF file's bytes."""
    from PIL import Image

    images = [Image.fromarray(np.asarray(f)) for f in frames]
    buf = io.BytesIO()
    images[0].save(
        buf,
        format="GIF",
        save_all=True,
        append_images=images[1:],
        loop=0,
        # GIF frame times are whole hundredths of a second
        duration=10 * round(100 / fps),
        optimize=True,
    )
    return buf.getvalue()


def gif_html(frames, fps=12, width=None):
    """Encode RGB frames (list of (H, W, 3) uint8) as a looping GIF inside an HTML <img>
    tag."""
    data = base64.b64encode(gif_bytes(frames, fps)).decode()
    style = f' width="{width}"' if width else ""
    return f'<img src="data:image/gif;base64,{data}"{style}/>'


def figure_frames(draw, num_frames, figsize=(4, 4), dpi=80):
    """Render ``draw(fig, f)`` for f in range(num_frames) into RGB frames with
    matplotlib."""
    frames = []
    fig = plt.figure(figsize=figsize, dpi=dpi)
    for f in range(num_frames):
        fig.clear()
        draw(fig, f)
        fig.canvas.draw()
        frames.append(np.asarray(fig.canvas.buffer_rgba())[..., :3].copy())
    plt.close(fig)
    return frames


def reverse_process_frames(
    trace, reference, points_above=700, figsize=(5.2, 3.2), dpi=70
):
    """Frames of a reverse-process animation: for each step t of ``trace`` ({t:
    (x_{t-1}, x0_hat)}, one sequence (F, 68, 3) each, in mm), from the largest t down,
    the last frame of x_{t-1} (left) and of the estimate x0_hat (right), on axes fitted
    to ``reference`` (sequences in mm) with 10 mm to spare.  Above ``points_above`` the
    landmarks are plain points: far from a face, x0_hat may lie far off the frame.
    """
    xy = np.asarray(reference)[..., :2].reshape(-1, 2)
    low, high = xy.min(0) - 10, xy.max(0) + 10
    steps = sorted(trace, reverse=True)

    def draw(fig, k):
        t = steps[k]
        for j, (points, title) in enumerate(
            zip(trace[t], (f"$x_{{{t - 1}}}$", r"$\hat x_0$"))
        ):
            ax = fig.add_subplot(1, 2, j + 1)
            if t > points_above:
                ax.plot(points[-1, :, 0], points[-1, :, 1], ".", ms=2)
            else:
                plot_landmarks(points[-1], ax=ax)
            ax.set(
                xlim=(low[0], high[0]),
                ylim=(low[1], high[1]),
                xticks=[],
                yticks=[],
                xlabel="",
                ylabel="",
                title=f"{title}, step {t}",
            )

    return figure_frames(draw, len(steps), figsize=figsize, dpi=dpi)


def mesh_frames(
    meshes, titles=None, size=(240, 300), view="front", faces=None, **kwargs
):
    """RGB frames of a mesh sequence (F, V, 3), or of several side by side ((S, F, V,
    3)); ``faces``: the triangles of a mesh that is not the template (then pass
       ``colors``, e.g. SKIN_RGB per vertex).
    """
    meshes = np.asarray(meshes)
    if meshes.ndim == 3:
        meshes = meshes[None]
    renderer = FaceRenderer(size=size, view=view, faces=faces)
    try:
        frames = []
        for f in range(meshes.shape[1]):
            panels = [renderer.render(m[f], **kwargs) for m in meshes]
            frames.append(np.concatenate(panels, axis=1))
    finally:
        renderer.close()
    if titles is not None:
        frames = [_caption(fr, titles, size[0]) for fr in frames]
    return frames


def animate_meshes(
    meshes, titles=None, fps=12, size=(240, 300), view="front", width=None, **kwargs
):
    """HTML GIF of a mesh sequence (F, V, 3), or of several side by side ((S, F, V,
    3))."""
    return gif_html(
        mesh_frames(meshes, titles, size, view, **kwargs), fps=fps, width=width
    )


def _caption(frame, titles, panel_width):
    from PIL import Image, ImageDraw

    img = Image.fromarray(frame)
    d = ImageDraw.Draw(img)
    for k, t in enumerate(titles):
        d.text((k * panel_width + 6, 4), str(t), fill=(40, 40, 40))
    return np.asarray(img)


def animate_landmarks(sequences, titles=None, fps=12, panel_size=2.6, dpi=70, lim=None):
    """HTML GIF of landmark sequences (S, F, 68, 3) or (F, 68, 3), front view, side by
    side; ``titles``: one per sequence, or a function of the frame (a caption that
    changes, e.g. the time and what the face is asked to do)."""
    seqs = np.asarray(sequences)
    if seqs.ndim == 3:
        seqs = seqs[None]
    if seqs.ndim != 4 or seqs.shape[-2:] != (68, 3):
        raise ValueError(f"sequences must have shape (S, F, 68, 3), got {seqs.shape}")
    lo, hi = (
        seqs[..., :2].reshape(-1, 2).min(0) - 5,
        seqs[..., :2].reshape(-1, 2).max(0) + 5,
    )

    def draw(fig, f):
        for k, seq in enumerate(seqs):
            ax = fig.add_subplot(1, len(seqs), k + 1)
            plot_landmarks(seq[f], ax=ax, color="C0")
            ax.set(
                xlim=(lo[0], hi[0]),
                ylim=(lo[1], hi[1]),
                xticks=[],
                yticks=[],
                xlabel="",
                ylabel="",
            )
            if callable(titles):
                title = titles(f)
            else:
                title = titles[k] if titles is not None else f"frame {f + 1}"
            ax.set_title(title, fontsize=8)
        fig.tight_layout()

    frames = figure_frames(
        draw, seqs.shape[1], figsize=(panel_size * len(seqs), panel_size * 1.2), dpi=dpi
    )
    return gif_html(frames, fps=fps)


def steps_figure(record, figsize=(11, 3.3)):
    """A stored table of quality against the chain's length
    (benchmarks/fast_sampling.py, steps) as one figure: the FID of unconditional
    sampling, then the accuracy and the FID of label control, against the reverse steps
    (log scale); one line per task and sampler, each with its 95 % interval (the column
    after the measure's) as a band.  Returns the figure."""
    col = {
        name: record["columns"].index(name)
        for name in ("task", "sampler", "steps", "Acc (%)", "FID")
    }
    rows = record["rows"]
    fig, axes = plt.subplots(1, 3, figsize=figsize)
    panels = [
        (axes[0], "unconditional", "FID"),
        (axes[1], "label control", "Acc (%)"),
        (axes[2], "label control", "FID"),
    ]
    for ax, task, measure in panels:
        m = col[measure]
        for i, name in enumerate(
            dict.fromkeys(
                r[col["task"]] for r in rows if r[col["task"]].startswith(task)
            )
        ):
            for sampler, style in (("ddpm", "o--"), ("ddim", "s-")):
                mine = sorted(
                    (
                        r
                        for r in rows
                        if r[col["task"]] == name and r[col["sampler"]] == sampler
                    ),
                    key=lambda r: r[col["steps"]],
                )
                ks = [r[col["steps"]] for r in mine]
                label = f"{sampler.upper()}{name[len(task):]}"
                ax.plot(
                    ks,
                    [r[m] for r in mine],
                    style,
                    color=f"C{i}",
                    label=label,
                    alpha=0.9,
                )
                ax.fill_between(
                    ks,
                    *np.array([r[m + 1] for r in mine], dtype=float).T,
                    color=f"C{i}",
                    alpha=0.12,
                )
        ax.set(
            xscale="log",
            xlabel="reverse steps (of T = 2000)",
            ylabel=measure,
            title=task,
        )
        ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def few_steps_figure(record, figsize=(11, 3.3)):
    """The stored table of quality against the number of network calls
    (benchmarks/few_steps.py): FID, the frame-to-frame speed over the data's (the band
    of +-10 % around 1 shaded; ratios beyond 0.25-4, noise, off the scale) and the
    guided accuracy, one line per sampler (DDPM, DDIM, students, flow), each with its 95
    % interval as a band; log-scaled calls.  Returns the figure."""
    col = {
        name: i for i, name in enumerate(record["columns"]) if name != "95 % interval"
    }
    rows = [r for r in record["rows"] if r[col["FID"]] != ""]
    fig, axes = plt.subplots(1, 3, figsize=figsize)
    panels = zip(axes, ("FID", "speed / data's", "guided Acc (%)"))
    for ax, measure in panels:
        m = col[measure]
        for i, name in enumerate(dict.fromkeys(r[0] for r in rows)):
            mine = sorted(
                (r for r in rows if r[0] == name and r[m] != ""),
                key=lambda r: r[col["network calls"]],
            )
            if not mine:  # a sampler without this measure (Heun: no guided rows)
                continue
            calls = [r[col["network calls"]] for r in mine]
            ax.plot(calls, [r[m] for r in mine], "o-", color=f"C{i}", label=name)
            low, high = np.array([r[m + 1] for r in mine], dtype=float).T
            ax.fill_between(calls, low, high, color=f"C{i}", alpha=0.12)
        if measure == "speed / data's":  # one and two DDIM steps: noise, off the scale
            ax.axhspan(0.9, 1.1, color="0.85", zorder=0)
            ax.set_ylim(0.25, 4)
        ax.set(xscale="log", xlabel="network calls per sequence", ylabel=measure)
        ax.set_yscale("log" if measure != "guided Acc (%)" else "linear")
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    return fig


def long_timeline_figure(sequence, segments, windows, fps=30, figsize=(11, 4.6)):
    """A long sequence (frames, 68, 3) in mm at ``fps``, made window by window from a
    schedule (chapter "Any length"): above, three measures of the face over time (the
    inner-lip gap, the mouth width and the brow-to-lid distance, each from its value
    at the first frame) on the schedule's segments, the joins dotted; below, the
    windows, the frames each shares with the stream before it hatched.  ``segments`` and
    ``windows``: tasks.long.Segment and Window lists (a text in quotes).  Returns the
    figure."""
    x = np.asarray(sequence, dtype=np.float64)
    seconds = np.arange(len(x)) / fps
    fig, (top, bottom) = plt.subplots(
        2, 1, figsize=figsize, sharex=True, gridspec_kw=dict(height_ratios=(3, 1))
    )
    start = 0
    for k, segment in enumerate(segments):
        end = start + segment.frames
        text = getattr(segment, "text", False)
        rest = not text and segment.what in ("neutral", "free")
        top.axvspan(
            start / fps,
            end / fps,
            color="0.93" if rest else f"C{k % 10}",
            alpha=1 if rest else 0.12,
            lw=0,
        )
        top.text(
            (start + end) / 2 / fps,
            1.0,
            f'"{segment.what}"' if text else segment.what.replace("_", " "),
            transform=top.get_xaxis_transform(),
            ha="center",
            va="bottom",
            fontsize=7,
        )
        start = end
    lip = np.linalg.norm(x[:, 62] - x[:, 66], axis=-1)
    width = np.linalg.norm(x[:, 48] - x[:, 54], axis=-1)
    brow = np.mean(
        [np.linalg.norm(x[:, b] - x[:, e], axis=-1) for b, e in ((19, 37), (24, 44))],
        axis=0,
    )
    for values, name in (
        (lip, "inner-lip gap"),
        (width, "mouth width"),
        (brow, "brow to upper lid"),
    ):
        top.plot(seconds, values - values[0], lw=1.1, label=name)
    first = 0
    for w in windows[:-1]:
        first += w.keep
        top.axvline(first / fps, color="0.4", lw=0.6, ls=":")
    top.set(ylabel="change from the first frame (mm)")
    top.legend(fontsize=7, loc="upper right", ncol=3)
    begin = 0
    for k, w in enumerate(windows):
        y = k % 2
        bottom.barh(
            y, w.keep / fps, left=begin / fps, height=0.7, color="C0", alpha=0.55
        )
        if w.known:
            bottom.barh(
                y,
                w.known / fps,
                left=(begin - w.known) / fps,
                height=0.7,
                color="none",
                edgecolor="C3",
                hatch="////",
                lw=0.6,
            )
        begin += w.keep
    bottom.set(yticks=[], xlabel="seconds", ylabel="windows")
    fig.tight_layout()
    return fig


def spiral_figure(canonical, faces, spirals, vertices, radius=14.0, figsize=(10, 4.4)):
    """Spirals (SpiralNet++ neighbour orderings) of a few vertices on the template's
    canonical plane: one panel per vertex of ``vertices`` ({title: vertex index}), one
    line per spiral of ``spirals`` ({length: (V, length) indices}), the positions of the
    longest numbered, the triangles within ``radius`` mm of the vertex drawn under them.
    Returns the figure."""
    fig, axes = plt.subplots(1, len(vertices), figsize=figsize, squeeze=False)
    lengths = sorted(spirals, reverse=True)
    for ax, (title, v) in zip(axes[0], vertices.items()):
        for k, length in enumerate(lengths):
            ax.plot(
                *canonical[spirals[length][v], :2].T,
                "-o",
                color=f"C{(k + 1) % 2}",
                ms=4,
                lw=1,
                label=f"L = {length}",
            )
        for position, u in enumerate(spirals[lengths[0]][v]):
            ax.annotate(
                str(position),
                canonical[u, :2],
                fontsize=7,
                xytext=(3, 2),
                textcoords="offset points",
            )
        near = np.linalg.norm(canonical[:, :2] - canonical[v, :2], axis=1) < radius
        ax.triplot(
            canonical[:, 0],
            canonical[:, 1],
            faces[near[faces].all(1)],
            color="0.85",
            lw=0.5,
            zorder=0,
        )
        ax.set(title=title, xlabel="x0 (mm)", ylabel="y0 (mm)", aspect="equal")
        ax.legend(fontsize=8)
    return fig


def tradeoff_figure(scores, title="", figsize=(7, 4.2)):
    """Control against realism: one point per setting of ``scores`` ({name: evaluation
    score with "accuracy", "fid" and their "_ci" 95 % intervals}), IC accuracy against
    FID (log scale), each with its intervals as error bars; circles for Adagrad rates,
    triangles for mean-shift scales, crosses for the rest (by the name's first word).
    Returns the figure."""
    import matplotlib.ticker as mticker

    fig, ax = plt.subplots(figsize=figsize)
    for name, s in scores.items():
        marker = {"Adagrad,": "o", "mean": "^"}.get(name.split()[0], "x")
        errors = [
            np.abs(np.array(s[k + "_ci"], dtype=float)[:, None] - s[k])
            for k in ("fid", "accuracy")
        ]
        ax.errorbar(
            s["fid"],
            s["accuracy"],
            xerr=errors[0],
            yerr=errors[1],
            capsize=2,
            marker=marker,
            ls="none",
            label=name,
        )
    ax.set(
        xlabel="FID (lower is better, log scale)",
        ylabel="IC accuracy (%)",
        xscale="log",
        title=title,
    )
    ax.xaxis.set_major_locator(mticker.LogLocator(subs=(1, 2, 5)))
    ax.xaxis.set_major_formatter(mticker.FormatStrFormatter("%g"))
    ax.xaxis.set_minor_formatter(mticker.NullFormatter())
    ax.legend(fontsize=8)
    return fig


def grouped_bars(ax, groups, values, ylabel="", title=""):
    """Bars of several series side by side per group: ``values`` {series name: one value
    per group} (e.g. accuracy per requested label, guided against unguided), the group
    names under the bars.
    """
    width = 0.8 / len(values)
    for j, (name, v) in enumerate(values.items()):
        ax.bar(
            np.arange(len(groups)) + (j - (len(values) - 1) / 2) * width,
            v,
            width,
            label=name,
        )
    ax.set_xticks(np.arange(len(groups)), groups, rotation=30, ha="right", fontsize=8)
    ax.set(ylabel=ylabel, title=title)
    ax.legend(fontsize=8, ncol=len(values), loc="upper center")


def shade_missing_frames(ax, known):
    """Grey background over the missing frames of a (F,) mask ``known`` (True: a given
    frame), white over the given ones: the frames an expression-filling plot must
    generate."""
    known = np.asarray(known, dtype=bool)
    edges = np.diff(np.r_[0, known.astype(int), 0])
    ax.axvspan(-0.5, len(known) - 0.5, color="0.93")
    for start, stop in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)):
        ax.axvspan(start - 0.5, stop - 0.5, color="white")


def confusion_figure(counts, class_names, title="", figsize=(6.5, 5.5)):
    """A confusion matrix ``counts`` (true x predicted, as
    :func:`facelib.metrics.confusion_matrix`) coloured by the fraction of each true
    class, with the non-zero counts written in the cells.  Returns the figure.
    """
    counts = np.asarray(counts)
    fig, ax = plt.subplots(figsize=figsize)
    im = ax.imshow(
        counts / np.maximum(counts.sum(1, keepdims=True), 1),
        cmap="Blues",
        vmin=0,
        vmax=1,
    )
    for i, j in zip(*np.nonzero(counts)):
        colour = "white" if counts[i, j] > counts[i].sum() / 2 else "black"
        ax.text(j, i, counts[i, j], ha="center", va="center", fontsize=7, color=colour)
    ax.set_xticks(range(len(counts)), class_names, rotation=60, ha="right", fontsize=8)
    ax.set_yticks(range(len(counts)), class_names, fontsize=8)
    ax.set(xlabel="predicted", ylabel="true", title=title)
    ax.grid(False)
    fig.colorbar(im, ax=ax, shrink=0.7, label="fraction of the true class")
    return fig


def au_curves_figure(requested, curves, aus, au_names, mask=None, figsize=None):
    """Requested against obtained action-unit curves (AU-curve control): one panel per
    AU of ``aus`` (names of ``au_names``), the requested curve (``requested``, (F, A))
    dashed in black where ``mask`` ((F, A) bool, the request's constrained entries;
    None: every entry) is True, and each entry of ``curves`` ({label: (n, F, A) curves,
    e.g. the rig fit of guided sequences, of unguided ones, the regressor's reading}) as
    thin lines of one colour per label; a panel of an AU the request leaves free says so
    in its title.  The legend is in the last panel.  x: frame, y: intensity.  Returns
    the figure."""
    requested = np.asarray(requested, dtype=float)
    mask = np.ones(requested.shape, dtype=bool) if mask is None else np.asarray(mask)
    if mask.shape != requested.shape or mask.dtype != bool:
        raise ValueError(
            f"mask must be a bool array of the request's shape {requested.shape}, got "
            f"{mask.dtype} {mask.shape}"
        )
    unknown = [a for a in aus if a not in au_names]
    if unknown:
        raise ValueError(f"aus: unknown AUs {unknown}; allowed: {', '.join(au_names)}")
    fig, axes = plt.subplots(
        1,
        len(aus),
        figsize=figsize or (3.2 * len(aus), 2.8),
        squeeze=False,
        sharey=True,
    )
    handles = {}
    for ax, name in zip(axes[0], aus):
        k = au_names.index(name)
        if mask[:, k].any():
            handles["requested"] = ax.plot(
                np.where(mask[:, k], requested[:, k], np.nan), "k--", lw=2
            )[0]
        for j, (label, c) in enumerate(curves.items()):
            for seq in np.asarray(c):
                handles[label] = ax.plot(seq[:, k], color=f"C{j}", lw=1, alpha=0.8)[0]
        ax.set(title=name if mask[:, k].any() else f"{name} (free)", xlabel="frame")
    axes[0, 0].set_ylabel("intensity")
    order = ["requested", *curves] if "requested" in handles else list(curves)
    axes[0, -1].legend(
        [handles[h] for h in order], order, fontsize=7, loc="upper right"
    )
    fig.tight_layout()
    return fig


def keyframe_figure(sequences, key, neutral, p95, figsize=(9.5, 3.0)):
    """One landmark keyframe ``key`` (frame, landmark and a ``displacement`` from
    ``neutral`` (68, 3) or a ``position``, mm) met by several methods, ``sequences``
    ({method: (n, F, 68, 3) in mm}).  Left: the keyed landmark's displacement from the
    neutral face along the key's direction (mm; for a key at the neutral position
    itself, its distance from there), the key a star; right: its frame-to-frame speed
    (mm/frame) with the real 95th percentile ``p95`` dashed.  Returns the figure."""
    neutral = np.asarray(neutral, dtype=float)
    targets = [
        k for k in ("position", "displacement") if isinstance(key, dict) and k in key
    ]
    if neutral.shape != (68, 3) or not np.isfinite(neutral).all():
        raise ValueError(
            f"neutral must be finite landmarks (68, 3) in mm, got shape {neutral.shape}"
        )
    if len(targets) != 1 or not {"frame", "landmark"} <= set(key):
        raise ValueError(
            "key needs 'frame', 'landmark' and one of 'position' or 'displacement',"
            f" got {key!r}"
        )
    f, l = key["frame"], key["landmark"]
    target = np.asarray(key[targets[0]], dtype=float) - (
        neutral[l] if targets[0] == "position" else 0.0
    )
    distance = float(np.linalg.norm(target))
    fig, (ax, bx) = plt.subplots(1, 2, figsize=figsize)
    for j, (method, x) in enumerate(sequences.items()):
        path = np.asarray(x, dtype=float)[:, :, l]
        moved = path - neutral[l]
        along = (
            moved @ (target / distance)
            if distance > 0
            else np.linalg.norm(moved, axis=-1)
        )
        speed = np.linalg.norm(np.diff(path, axis=1), axis=-1)
        for i in range(len(path)):
            ax.plot(along[i], color=f"C{j}", lw=1, label=method if i == 0 else None)
            bx.plot(np.arange(1, path.shape[1]) - 0.5, speed[i], color=f"C{j}", lw=1)
    ax.plot([f], [distance], "k*", ms=12, label=f"key (frame {f})")
    bx.axhline(p95, color="k", ls="--", lw=1, label="real 95th percentile")
    what = "displacement along the key" if distance > 0 else "distance from neutral"
    ax.set(xlabel="frame", ylabel=f"landmark {l}: {what} (mm)")
    bx.set(xlabel="frame", ylabel="speed (mm/frame)")
    ax.legend(fontsize=7)
    bx.legend(fontsize=7)
    fig.tight_layout()
    return fig
