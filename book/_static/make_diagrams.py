"""Writes book/_static/pipeline.svg and chapter_map.svg, two diagrams laid out by hand (positions below).

Run ``python book/_static/make_diagrams.py`` after changing a chapter's prerequisites (EDGES) or a title."""
from html import escape
from pathlib import Path

HERE = Path(__file__).resolve().parent

FONT = 'font-family="DejaVu Sans, Helvetica, Arial, sans-serif"'


def box(x, y, w, h, lines, fill="#eef3fb", stroke="#4a6fa5", size=15, bold_first=False):
    out = [f'<rect x="{x}" y="{y}" width="{w}" height="{h}" rx="8" fill="{fill}" stroke="{stroke}" stroke-width="1.5"/>']
    n = len(lines)
    for i, line in enumerate(lines):
        ty = y + h / 2 + (i - (n - 1) / 2) * (size + 4) + size * 0.35
        weight = ' font-weight="bold"' if bold_first and i == 0 else ""
        out.append(f'<text x="{x + w / 2}" y="{ty:.1f}" text-anchor="middle" font-size="{size}"{weight} {FONT}>{escape(line)}</text>')
    return "\n".join(out)


def arrow(x1, y1, x2, y2, label=None, dx=0, dy=-6, color="#333"):
    s = f'<line x1="{x1}" y1="{y1}" x2="{x2}" y2="{y2}" stroke="{color}" stroke-width="1.6" marker-end="url(#head)"/>'
    if label:
        s += f'\n<text x="{(x1 + x2) / 2 + dx}" y="{(y1 + y2) / 2 + dy}" text-anchor="middle" font-size="14" {FONT} fill="#333">{escape(label)}</text>'
    return s


def svg(w, h, body, title):
    return f'''<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {w} {h}" width="{w}" height="{h}" role="img" aria-label="{escape(title)}">
<title>{escape(title)}</title>
<defs><marker id="head" viewBox="0 0 10 10" refX="9" refY="5" markerWidth="8" markerHeight="8" orient="auto-start-reverse"><path d="M0,0 L10,5 L0,10 z" fill="#333"/></marker></defs>
<rect width="{w}" height="{h}" fill="white"/>
{body}
</svg>
'''


def pipeline():
    b = []
    b.append(box(10, 150, 120, 56, ["noise x_T", "~ N(0, I)"]))
    b.append(box(165, 140, 262, 76, ["reverse diffusion", "ε_θ: bidirectional transformer", "T = 2000 steps (or fewer)"], bold_first=True))
    b.append(box(467, 140, 200, 76, ["landmark sequence", "x_0 = (L_1, …, L_F)", "F × 68 × 3, mm"], bold_first=True))
    b.append(box(141, 10, 310, 86, ["conditioning, at sampling time only", "a label (Alg. 1) · a text (Alg. 2)", "known frames (Alg. 3)", "a neutral face (Alg. 4)"], fill="#fdf3e6", stroke="#c9822b", bold_first=True))
    b.append(arrow(130, 178, 163, 178))
    b.append(arrow(427, 178, 465, 178))
    b.append(arrow(296, 96, 296, 138))
    b.append(box(452, 290, 230, 76, ["spiral encoder-decoder", "with cross-attention", "(the deformer, Eq. 11)"], fill="#eaf6ec", stroke="#3f8f52", bold_first=True))
    b.append(box(165, 300, 236, 56, ["neutral mesh M", "any face, template topology"], fill="#eaf6ec", stroke="#3f8f52"))
    b.append(box(720, 290, 172, 76, ["animated mesh", "M_f = M + ΔM_f", "OBJ frames, GIF"], fill="#eaf6ec", stroke="#3f8f52", bold_first=True))
    b.append(arrow(567, 216, 567, 288, "ΔL_f = L_f − L", dx=62, dy=4))
    b.append(arrow(401, 328, 450, 328))
    b.append(arrow(682, 328, 718, 328))
    b.append(f'<text x="12" y="250" font-size="14" {FONT} fill="#555">trained once, unconditionally, on landmark sequences (chapters 02–03)</text>')
    b.append(f'<text x="12" y="392" font-size="14" {FONT} fill="#555">trained on meshes (chapter 09); chapter 10 runs the whole pipeline</text>')
    return svg(900, 405, "\n".join(b), "The 4DFM pipeline: a diffusion model of landmark sequences, conditioned at sampling time, then a mesh deformer")


CHAPTERS = {  # id: (title lines, part colour, x, y)
    "01": (["01 The synthetic", "4D face world"], 0, 20, 70),
    "02": (["02 DDPM from", "first principles"], 1, 20, 200),
    "04": (["04 Evaluating", "generated expressions"], 2, 200, 20),
    "03": (["03 The denoiser"], 1, 200, 140),
    "09": (["09 Landmark-guided", "mesh deformation"], 4, 200, 300),
    "05": (["05 Label control"], 3, 380, 70),
    "07": (["07 Expression filling"], 3, 380, 190),
    "06": (["06 Text control"], 3, 560, 10),
    "11": (["11 Fewer steps,", "guidance without", "a classifier"], 5, 560, 95),
    "08": (["08 Geometry-adaptive", "generation"], 3, 560, 210),
    "a1": (["A1 Hearing the order", "and new words"], 6, 740, 10),
    "12": (["12 Fine control:", "AUs and keyframes"], 5, 740, 130),
    "10": (["10 End to end"], 4, 740, 290),
}
EDGES = [("01", "03"), ("02", "03"), ("01", "04"), ("03", "05"), ("04", "05"), ("05", "06"), ("03", "07"),
         ("04", "07"), ("05", "08"), ("07", "08"), ("01", "09"), ("08", "10"), ("09", "10"), ("05", "11"),
         ("08", "12"), ("11", "12"), ("06", "a1")]
PARTS = [("Foundations", "#f2f2f2", "#777"), ("The diffusion model", "#eef3fb", "#4a6fa5"),
         ("Measuring a generator", "#f5eefa", "#8a5aa8"), ("Conditioning the reverse process", "#fdf3e6", "#c9822b"),
         ("From landmarks to meshes", "#eaf6ec", "#3f8f52"), ("Beyond the paper", "#fbecec", "#b24a4a"),
         ("Appendix", "#f7f7e8", "#8a8a3a")]
W, H = 150, 62


def chapter_map():
    b = []
    for a, c in EDGES:
        xa, ya = CHAPTERS[a][2] + W, CHAPTERS[a][3] + H / 2
        xc, yc = CHAPTERS[c][2], CHAPTERS[c][3] + H / 2
        b.append(f'<path d="M{xa},{ya} C{xa + 18},{ya} {xc - 18},{yc} {xc - 2},{yc}" fill="none" stroke="#555" stroke-width="1.4" marker-end="url(#head)"/>')
    for key, (lines, part, x, y) in CHAPTERS.items():
        _, fill, stroke = PARTS[part]
        b.append(box(x, y, W, H, lines, fill=fill, stroke=stroke, size=12))
    for k, (name, fill, stroke) in enumerate(PARTS):
        lx, ly = 20 + 220 * (k % 4), 378 + 20 * (k // 4)
        b.append(f'<rect x="{lx}" y="{ly}" width="14" height="14" rx="3" fill="{fill}" stroke="{stroke}"/>')
        b.append(f'<text x="{lx + 19}" y="{ly + 11}" font-size="11" {FONT}>{escape(name)}</text>')
    return svg(900, 420, "\n".join(b), "Which chapter builds on which: an arrow from a chapter to one that needs it")


if __name__ == "__main__":
    (HERE / "pipeline.svg").write_text(pipeline())
    (HERE / "chapter_map.svg").write_text(chapter_map())
