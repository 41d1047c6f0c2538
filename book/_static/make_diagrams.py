"""Writes book/_static/pipeline.svg, chapter_map.svg, bit.svg and deformer.svg, diagrams laid out by hand (positions below).

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
    "13": (["13 Your own face:", "registration"], 5, 740, 380),
    "14": (["14 Fewer steps still:", "distillation, flow"], 5, 920, 80),
    "15": (["15 Any length:", "windows and joins"], 5, 920, 200),
}
EDGES = [("01", "03"), ("02", "03"), ("01", "04"), ("03", "05"), ("04", "05"), ("05", "06"), ("03", "07"),
         ("04", "07"), ("05", "08"), ("07", "08"), ("01", "09"), ("08", "10"), ("09", "10"), ("05", "11"),
         ("08", "12"), ("11", "12"), ("06", "a1"), ("09", "13"),
         ("10", "13"), ("11", "14"), ("08", "15"), ("06", "15")]
PARTS = [("Foundations", "#f2f2f2", "#777"), ("The diffusion model", "#eef3fb", "#4a6fa5"),
         ("Measuring a generator", "#f5eefa", "#8a5aa8"), ("Conditioning the reverse process", "#fdf3e6", "#c9822b"),
         ("From landmarks to meshes", "#eaf6ec", "#3f8f52"), ("Beyond the paper", "#fbecec", "#b24a4a"),
         ("Appendix", "#f7f7e8", "#8a8a3a")]
W, H = 150, 62


def chapter_map():
    b = []
    for a, c in EDGES:
        if CHAPTERS[a][2] == CHAPTERS[c][2]:  # one above the other: straight down
            x = CHAPTERS[a][2] + W / 2
            b.append(arrow(x, CHAPTERS[a][3] + H, x, CHAPTERS[c][3] - 2))
            continue
        xa, ya = CHAPTERS[a][2] + W, CHAPTERS[a][3] + H / 2
        xc, yc = CHAPTERS[c][2], CHAPTERS[c][3] + H / 2
        b.append(f'<path d="M{xa},{ya} C{xa + 18},{ya} {xc - 18},{yc} {xc - 2},{yc}" fill="none" stroke="#555" stroke-width="1.4" marker-end="url(#head)"/>')
    for key, (lines, part, x, y) in CHAPTERS.items():
        _, fill, stroke = PARTS[part]
        b.append(box(x, y, W, H, lines, fill=fill, stroke=stroke, size=12))
    for k, (name, fill, stroke) in enumerate(PARTS):
        lx, ly = 20 + 220 * (k % 3), 400 + 20 * (k // 3)
        b.append(f'<rect x="{lx}" y="{ly}" width="14" height="14" rx="3" fill="{fill}" stroke="{stroke}"/>')
        b.append(f'<text x="{lx + 19}" y="{ly + 11}" font-size="11" {FONT}>{escape(name)}</text>')
    return svg(1090, 470, "\n".join(b), "Which chapter builds on which: an arrow from a chapter to one that needs it")


def bit():
    """The denoiser eps_theta of models/denoiser.py on the BiT of models/bit.py (DenoiserConfig's sizes)."""
    b = []
    cols = [(20, "1"), (180, "2"), (400, "F")]  # x of each frame column (width 140); "…" between 2 and F
    cw = 140
    for x, f in cols:
        b.append(box(x, 20, cw, 48, [f"frame {f} of x_t", "68 × 3 = 204"], size=13))
        b.append(arrow(x + cw / 2, 68, x + cw / 2, 94))
        b.append(box(x, 96, cw, 70, [f"token h_{f}", f"FE(frame {f})", f"+ PE({f}) + TE(t)"], size=13, bold_first=True))
        b.append(arrow(x + cw / 2, 166, x + cw / 2, 198, "128", dx=18, dy=5))
        b.append(arrow(x + cw / 2, 436, x + cw / 2, 462))
        b.append(box(x, 464, cw, 64, ["LayerNorm,", "Linear 128 → 204", "starts at zero"], size=13))
        b.append(arrow(x + cw / 2, 528, x + cw / 2, 556, "BiT", dx=20, dy=5))
        b.append(arrow(x + cw / 2, 604, x + cw / 2, 630))
        b.append(box(x, 632, cw, 48, [f"ε_θ, frame {f}", "204 numbers"], size=13, fill="#eaf6ec", stroke="#3f8f52"))
    for y in (43, 131, 496, 656):
        b.append(f'<text x="360" y="{y + 5}" text-anchor="middle" font-size="16" {FONT}>…</text>')
    # the encoder: depth pre-norm layers, self-attention over all frames, then a per-frame feed-forward
    b.append(box(10, 200, 540, 236, [], fill="#f7f9fd"))
    b.append(f'<text x="280" y="222" text-anchor="middle" font-size="14" font-weight="bold" {FONT}>4 × transformer encoder layer (depth = 4), pre-norm</text>')
    b.append(box(22, 234, 516, 122, []))
    b.append(f'<text x="280" y="254" text-anchor="middle" font-size="13" {FONT}>self-attention: LayerNorm, 4 heads × 32 (width 128), + token</text>')
    nodes = [x + cw / 2 for x, _ in cols]
    for i, xa in enumerate(nodes):
        for xb in nodes[i + 1:]:
            h = 18 + (xb - xa) * 0.095  # the peak of the arc above its ends
            o = 0 if (xa, xb) == (nodes[0], nodes[-1]) else 8  # neighbours' arcs end beside the longest one's
            b.append(f'<path d="M{xa + o},315 Q{(xa + xb) / 2},{315 - 2 * h:.1f} {xb - o},315" fill="none" stroke="#4a6fa5" stroke-width="1.4" marker-start="url(#head)" marker-end="url(#head)"/>')
    for xn in nodes:
        b.append(f'<circle cx="{xn}" cy="322" r="5" fill="#4a6fa5"/>')
    b.append(f'<text x="360" y="327" text-anchor="middle" font-size="16" {FONT}>…</text>')
    b.append(f'<text x="280" y="345" text-anchor="middle" font-size="13" font-style="italic" {FONT} fill="#333">bidirectional: each frame attends to all frames (no causal mask)</text>')
    b.append(arrow(280, 356, 280, 374))
    b.append(box(22, 376, 516, 48, ["feed-forward, per frame: LayerNorm, Linear 128 → 256,", "GELU, Linear 256 → 128, + token"], size=13))
    # the right-hand column: the step's embedding, the shared maps, the Gaussian estimate
    b.append(box(590, 20, 290, 48, ["diffusion step t", "one per sequence"], size=13))
    b.append(arrow(735, 68, 735, 94))
    b.append(box(590, 96, 290, 70, ["TE(t): sinusoids of t (128), then", "Linear, SiLU, Linear (128 → 128 → 128),", "added to every frame's token"], size=13, fill="#fdf3e6", stroke="#c9822b"))
    b.append(arrow(590, 131, 542, 131))
    b.append(box(590, 200, 290, 70, ["FE: one Linear 204 → 128, the", "same for every frame", "PE(f): sinusoids of f = 1, …, F (128)"], size=13, fill="#fdf3e6", stroke="#c9822b"))
    b.append(box(590, 500, 290, 104, ["ε_Gauss(x_t, t), our addition", "√(1 − ᾱ_t) (ᾱ_t Σ + (1 − ᾱ_t) I)⁻¹ x_t:", "a linear filter of each frame,", "Σ the covariance of training frames"], size=13, fill="#eaf6ec", stroke="#3f8f52", bold_first=True))
    b.append(arrow(590, 580, 552, 580))
    b.append(box(10, 558, 540, 46, ["ε_θ(x_t, t) = ε_Gauss(x_t, t) + BiT(TE + PE + FE)"], size=14, fill="#eaf6ec", stroke="#3f8f52", bold_first=True))
    b.append(f'<text x="590" y="660" font-size="13" {FONT} fill="#555">Each output starts at zero, so training</text>')
    b.append(f'<text x="590" y="678" font-size="13" {FONT} fill="#555">starts from ε_θ = ε_Gauss.</text>')
    return svg(900, 696, "\n".join(b), "The denoiser: one token per frame (FE + PE + TE), a bidirectional transformer, a linear output per frame, plus the Gaussian estimate")


def deformer():
    """The deformer of models/deformer.py (DeformerConfig's sizes; levels of the template: 4161, 1073, 285, 80 vertices)."""
    b = []
    green = dict(fill="#eaf6ec", stroke="#3f8f52")
    lx, rx, cw, h = 40, 650, 210, 46
    enc = [("3 → 16", 0, "4161"), ("16 → 32", 1, "1073"), ("32 → 32", 2, "285"), ("32 → 64", 3, "80"), ("64 → 64", 3, "80")]
    b.append(box(lx, 20, cw, h, ["neutral mesh M, 4161 × 3", "(M − template) / 10 mm"], size=13, bold_first=True, **green))
    for k, (ch, lv, v) in enumerate(enc):
        y = 98 + 78 * k
        b.append(arrow(lx + cw / 2, y - 32, lx + cw / 2, y - 2, "pool" if k in (1, 2, 3) else None, dx=26, dy=5))
        b.append(box(lx, y, cw, h, [f"spiral conv {ch}, ELU", f"level {lv}: {v} vertices"], size=13))
    b.append(arrow(lx + cw / 2, 98 + 78 * 5 - 32, lx + cw / 2, 98 + 78 * 5 - 2))
    b.append(box(lx, 488, cw, h, ["F_e: 80 × 64", "mesh features"], size=13, bold_first=True, fill="#fdf3e6", stroke="#c9822b"))
    b.append(f'<text x="22" y="289" transform="rotate(-90 22 289)" text-anchor="middle" font-size="14" font-weight="bold" {FONT}>Encoder (once per face)</text>')
    dec = [("16 → 3", 0, "4161", ""), ("32 → 16", 1, "1073", ", ELU"), ("32 → 32", 2, "285", ", ELU"),
           ("64 → 32", 3, "80", ", ELU"), ("64 → 64", 3, "80", ", ELU")]
    b.append(box(rx, 20, cw, h, ["animated mesh", "M_f = M + ΔM_f"], size=13, bold_first=True, **green))
    b.append(box(rx, 102, cw, h, ["ΔM_f: 4161 × 3", "× 10 mm"], size=13, bold_first=True, **green))
    b.append(arrow(rx + cw / 2, 102, rx + cw / 2, 68))
    for k, (ch, lv, v, act) in enumerate(dec):
        y = 184 + 82 * k
        b.append(box(rx, y, cw, h, [f"spiral conv {ch}{act}", f"level {lv}: {v} vertices"], size=13))
        b.append(arrow(rx + cw / 2, y, rx + cw / 2, y - 34, "unpool" if 1 <= k <= 3 else None, dx=32, dy=5))
    b.append(box(rx, 594, cw, h, ["Linear 204 → 80 × 64", "the coarse level"], size=13))
    b.append(arrow(rx + cw / 2, 594, rx + cw / 2, 184 + 82 * 4 + h + 2))
    b.append(f'<text x="884" y="330" transform="rotate(90 884 330)" text-anchor="middle" font-size="14" font-weight="bold" {FONT}>Decoder (S2D&#8217;s, per frame)</text>')
    b.append(arrow(lx + cw, 43, rx - 2, 43, "M, added to ΔM_f", dy=-7))
    # the middle: the motion queries the face (Eq. 11)
    b.append(box(285, 110, 330, 52, ["landmark displacement ΔL_f = L_f − L", "68 × 3 = 204, / 10 mm, per frame f"], size=13, bold_first=True, fill="#fdf3e6", stroke="#c9822b"))
    b.append(arrow(430, 162, 430, 248))
    b.append(box(330, 250, 200, 46, ["FC: Linear 204 → 64", "the query"], size=13))
    b.append(arrow(430, 296, 430, 458))
    b.append(box(285, 460, 290, 102, ["cross-attention (Eq. 11)", "softmax(FC(ΔL_f) F_eᵀ / √d) F_e", "keys and values: F_e, d = 64;", "weights over the 80 coarse vertices"], size=13, bold_first=True))
    b.append(arrow(lx + cw, 511, 283, 511))
    b.append(arrow(430, 562, 430, 592))
    b.append(box(285, 594, 330, 46, ["z_id: Linear 64 → 204", "z = κ z_id + ΔL_f (204 values)"], size=13))
    b.append(arrow(615, 617, rx - 2, 617))
    b.append('<line x1="595" y1="162" x2="595" y2="592" stroke="#333" stroke-width="1.6" stroke-dasharray="5 3" marker-end="url(#head)"/>')
    b.append(f'<text x="588" y="222" text-anchor="end" font-size="13" {FONT} fill="#333">skip: + ΔL_f</text>')
    return svg(900, 660, "\n".join(b), "The landmark-guided deformer: a spiral encoder of the neutral mesh, cross-attention driven by the landmark displacement, z = κ z_id + ΔL_f, and a spiral decoder to the vertex displacements")


if __name__ == "__main__":
    (HERE / "pipeline.svg").write_text(pipeline())
    (HERE / "chapter_map.svg").write_text(chapter_map())
    (HERE / "bit.svg").write_text(bit())
    (HERE / "deformer.svg").write_text(deformer())
