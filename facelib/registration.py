"""A reader's own face mesh -> the template fitted onto it, and motion carried back (the
chapter "Your own face").

The networks know one mesh: the template (4,161 vertices, canonical pose, millimetres).
A mesh from elsewhere has its own vertices, triangles, units and pose, so before it can
be animated the template is *registered* to it, in three stages of decreasing stiffness:

1. **Rigid alignment with scale** (:func:`rigid_alignment`): the principal axes of the
   two surfaces give 24 starting rotations; from each, ICP with the closed-form
   similarity of Umeyama (1991) alternates nearest points and the best rotation, scale
   and translation; the start with the smallest trimmed residual wins.
2. **The identity model** (:func:`fit_identity`): the world's 14 identity modes, pose
   and scale fitted by Gauss-Newton on point-to-plane distances with a N(0, I) prior on
   the modes: what a 3DMM fit (the paper's FLAME fitting, §3.3) does.
3. **Non-rigid ICP** (Amberg et al. 2007, ``trimesh.registration.nricp_amberg``): a
   local affine transform per vertex, smoothness weighted by a stiffness that is
   annealed from stiff to supple, for what the model cannot say.

The 68 landmarks are the fitted template's landmark vertices.  Motion computed on the
fitted template is carried to the reader's vertices by :meth:`FittedTemplate.transfer`:
each vertex follows the closest point of the fitted template's surface (barycentric
interpolation), fading out with its distance from the face.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from . import config
from .options import option
from .checks import check_choice, check_positive_int
from .face import identity
from .face import template as tpl
from .face.surface import closest_points, interpolate

UNITS = config.UNITS_MM  # millimetres per unit
# the largest side of a face (or head) mesh's bounding box, in mm
FACE_EXTENT_MM = (80.0, 500.0)
VERTEX_LIMITS = (300, 200_000)
# a face is 0.6-1.6 times the template's size (rigid alignment's scale)
FACE_SCALE = (0.6, 1.6)
MESH_SUFFIXES = (".obj", ".ply", ".stl", ".off")


@dataclass(frozen=True)
class Registration:
    """Fitting the template to a reader's own face mesh (facelib/registration.py, the
    chapter "Your own face")."""

    # None: detected from the mesh's size (FACE_EXTENT_MM)
    units: str | None = option(None, help="the mesh's units", choices=tuple(UNITS))
    # our choice: points sampled on the mesh's surface, area-weighted (the fit's target)
    samples: int = 40_000
    # similarity ICP (Umeyama): a third from each of 24 starts, the rest from the best
    rigid_iterations: int = 30
    # our choice: each ICP step keeps this share of the closest correspondences (holes,
    # extras)
    trim: float = 0.9
    # our choice: correspondence rounds of the identity-model fit (point to plane)
    model_rounds: int = 30
    # our choice: Gauss-Newton evaluations per round (new correspondences converge
    # faster)
    model_steps: int = 3
    # weight of the N(0, I) prior on the identity coefficients (a 3DMM's prior)
    model_prior: float = 1.0
    # Non-rigid ICP (Amberg et al. 2007, trimesh.registration.nricp_amberg): (stiffness,
    # landmark weight, normal weight, iterations) per stage, the stiffness annealed from
    # stiff to supple.  Our choice (the chapter "Your own face", section 4): stiffer
    # than trimesh's default, since the identity model already brought the template
    # close.
    stiffness: tuple = (
        (1.0, 0.0, 1.0, 10),
        (0.3, 0.0, 1.0, 10),
        (0.1, 0.0, 1.0, 10),
        (0.03, 0.0, 0.5, 10),
    )
    match_distance_mm: float = 10.0  # NRICP ignores correspondences farther than this
    # Our choice (measured in the chapter "Your own face"): after rigid alignment every
    # face of the truth set is within 2.5 mm (trimmed RMS), a sphere, a cube, a hand and
    # a plane at 4.5 mm or more.  A worse fit is refused.
    max_residual_mm: float = 3.5
    # motion carried in full within 5 mm of the fitted face, fading out by 40 mm
    falloff_mm: tuple = (5.0, 40.0)

    def __post_init__(self):
        if self.units is not None:
            check_choice("units", self.units, tuple(UNITS))
        check_positive_int("samples", self.samples)
        check_positive_int("rigid_iterations", self.rigid_iterations)
        check_positive_int("model_rounds", self.model_rounds)
        if not 0.5 <= self.trim <= 1.0:
            raise ValueError(f"trim must be in [0.5, 1], got {self.trim}")
        near, far = self.falloff_mm
        if not 0 <= near < far:
            raise ValueError(
                "falloff_mm must be (near, far) with 0 <= near < far, got"
                f" {self.falloff_mm}"
            )

    def fast(self):
        return replace(self, samples=20_000, rigid_iterations=15)



class NotAFaceError(ValueError):
    """A mesh that the template cannot be placed on closely: ``residual_mm`` (trimmed
    RMS after rigid alignment, mm of the template) and ``scale`` (the template's scale
    factor) say how far it is from a face.
    """

    def __init__(self, message, residual_mm, scale):
        super().__init__(message)
        self.residual_mm, self.scale = residual_mm, scale


@dataclass(frozen=True)
class UserMesh:
    """A reader's mesh as read: vertices (V, 3) in its own units and pose, triangles (K,
    3), and its units."""

    vertices: np.ndarray
    faces: np.ndarray
    units: str
    source: str = "the mesh"

    @property
    def mm(self):
        """The vertices in millimetres (same pose)."""
        return self.vertices * UNITS[self.units]


def _extent(vertices, faces):
    used = vertices[np.unique(faces)]
    return float((used.max(0) - used.min(0)).max())


def detect_units(extent, units=None, source="the mesh"):
    """The units ("mm", "cm" or "m") in which a mesh ``extent`` units across is a face
    (FACE_EXTENT_MM), or ``units`` checked against that size.  A clear error when no
    unit, or not the given one, makes it a face.
    """
    lo, hi = FACE_EXTENT_MM
    fits = [u for u, mm in UNITS.items() if lo <= extent * mm <= hi]
    sizes = ", ".join(f"{extent * mm:.4g} mm in {u}" for u, mm in UNITS.items())
    if units is not None:
        check_choice("units", units, tuple(UNITS))
        if units not in fits:
            raise ValueError(
                f"{source} is {extent:.4g} units across, {extent * UNITS[units]:.4g} mm"
                f" if they are {units}, but a face mesh is {lo:g}-{hi:g} mm across:"
                f" --units {units} contradicts its size"
                + (f"; it looks like {fits[0]}" if fits else f" ({sizes})")
            )
        return units
    if not fits:
        raise ValueError(
            f"{source} is {extent:.4g} units across ({sizes}); a face mesh is"
            f" {lo:g}-{hi:g} mm across in mm, cm or m: rescale it"
        )
    return fits[0]


def check_mesh(vertices, faces, units=None, source="the mesh"):
    """A :class:`UserMesh` from vertices (V, 3) and triangles (K, 3), or a clear error
    naming what is wrong."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3 or len(v) == 0:
        raise ValueError(f"{source} has no vertices of shape (V, 3) (got {v.shape})")
    if f.size == 0:
        raise ValueError(
            f"{source} has {len(v)} vertices but no triangles: a point cloud cannot be"
            " registered; give a triangle mesh (OBJ, PLY, STL or OFF)"
        )
    if f.ndim != 2 or f.shape[1] != 3 or not np.issubdtype(f.dtype, np.integer):
        raise ValueError(
            f"{source}'s faces must be (K, 3) integer triangles, got {f.dtype}"
            f" {f.shape}"
        )
    if f.min() < 0 or f.max() >= len(v):
        raise ValueError(f"{source}'s triangles index vertices outside 0..{len(v) - 1}")
    bad = ~np.isfinite(v).all(1)
    if bad.any():
        n = int(bad.sum())
        raise ValueError(
            f"{source} has {n} {'vertex' if n == 1 else 'vertices'} with NaN or inf"
            " coordinates"
        )
    lo, hi = VERTEX_LIMITS
    if not lo <= len(v) <= hi:
        raise ValueError(
            f"{source} has {len(v)} vertices; allowed: {lo:,} to {hi:,} (decimate or"
            " subdivide it)"
        )
    units = detect_units(_extent(v, f), units, source)
    return UserMesh(v, f.astype(np.int64), units, source)


def read_mesh(path, units=None):
    """Read a mesh file (OBJ, PLY, STL or OFF) as a :class:`UserMesh`, vertices and
    triangles exactly as stored."""
    import trimesh

    path = Path(path)
    if not path.is_file():
        raise ValueError(f"mesh file {path} does not exist")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise ValueError(
            f"{path}: unknown mesh format {path.suffix!r}; allowed:"
            f" {', '.join(MESH_SUFFIXES)}"
        )
    try:
        mesh = trimesh.load(path, process=False, maintain_order=True)
        if isinstance(mesh, trimesh.Scene):
            mesh = mesh.to_mesh()  # a scene's parts, merged
    except Exception as e:  # trimesh raises many types for unreadable files
        raise ValueError(f"cannot read {path} as a mesh: {e}") from e
    if isinstance(mesh, trimesh.PointCloud):
        raise ValueError(
            f"{path} is a point cloud (no triangles), which cannot be registered; give"
            " a triangle mesh (OBJ, PLY, STL or OFF)"
        )
    vertices = np.asarray(getattr(mesh, "vertices", np.zeros((0, 3))))
    faces = np.asarray(getattr(mesh, "faces", np.zeros((0, 3), dtype=np.int64)))
    return check_mesh(vertices, faces.reshape(-1, 3), units, source=str(path))


def similarity(source, target, scale=True):
    """(s, R, t) minimising sum |s R source_i + t - target_i|^2: Umeyama (1991),
    R a proper rotation (no reflection), s = 1 unless ``scale``."""
    ms, mt = source.mean(0), target.mean(0)
    a, b = source - ms, target - mt
    u, sing, vt = np.linalg.svd(b.T @ a / len(a))  # the cross-covariance
    d = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    r = u @ d @ vt
    s = float(np.trace(np.diag(sing) @ d) / ((a**2).sum() / len(a))) if scale else 1.0
    return s, r, mt - s * r @ ms


def _principal_axes(points):
    """The centroid and the principal axes (columns, largest variance first) as a
    right-handed frame, so that matching two frames gives a proper rotation."""
    centre = points.mean(0)
    axes = np.linalg.eigh(np.cov((points - centre).T))[1][:, ::-1].copy()
    if np.linalg.det(axes) < 0:
        axes[:, 2] *= -1
    return centre, axes


def _axis_matches():
    """The 24 rotations that map the coordinate axes onto themselves (signed permutation
    matrices, det 1): every way of matching the principal axes of two surfaces."""
    found = []
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=3):
            m = np.zeros((3, 3))
            m[list(range(3)), list(perm)] = signs
            if np.linalg.det(m) > 0:
                found.append(m)
    return tuple(found)


AXIS_MATCHES = _axis_matches()


def rigid_alignment(points, template_points, settings=Registration()):
    """Scale s, rotation R and translation t that place the template on ``points`` (s R
    x + t), and the trimmed RMS distance (mm of the template) of that placement: the
    best of 24 starts (the principal axes of the two surfaces matched in every order and
    direction that is a rotation, AXIS_MATCHES), each refined by similarity ICP.
    """
    tree = cKDTree(points)
    cu, axes_u = _principal_axes(points)
    ct, axes_t = _principal_axes(template_points)

    def icp(x, s, r, t, iterations):
        keep_n = max(3, int(settings.trim * len(x)))
        for _ in range(iterations):
            d, j = tree.query(s * x @ r.T + t)
            keep = np.argsort(d)[:keep_n]
            s, r, t = similarity(x[keep], points[j[keep]])
        d, _ = tree.query(s * x @ r.T + t)
        return s, r, t, float(np.sqrt(np.mean(np.sort(d)[:keep_n] ** 2)) / s)

    # A third of the iterations from every start with every 8th template point, the rest
    # from the best start with all of them.  Every start has scale 1: the mesh is in mm
    # by now, and faces are about the template's size.
    rotations = [axes_u @ m @ axes_t.T for m in AXIS_MATCHES]
    starts = [
        icp(template_points[::8], 1.0, r, cu - r @ ct, settings.rigid_iterations // 3)
        for r in rotations
    ]
    s, r, t, _ = min(starts, key=lambda start: start[3])
    return icp(
        template_points,
        s,
        r,
        t,
        settings.rigid_iterations - settings.rigid_iterations // 3,
    )


def fit_identity(points, normals, pose, settings=Registration()):
    """The world's identity model fitted to ``points`` (with their surface ``normals``)
    from ``pose`` = (s, R, t): minimises sum_i (n_j . (x_i - p_j))^2 + 0.04 |x_i -
    p_j|^2 + prior |c|^2 over the 14 identity coefficients c, the rotation, translation
    and log-scale, with p_j the nearest point to the model's vertex x_i (re-found every
    round, the farthest 1 - trim ignored).  Returns (vertices (V, 3) placed on the
    points, coefficients, residual mm).
    """
    tree = cKDTree(points)
    s, r, t = pose
    n = identity.NUM_MODES
    x0 = np.concatenate(
        [np.zeros(n), Rotation.from_matrix(r).as_rotvec(), t, [np.log(s)]]
    )

    def model(x):
        rot = Rotation.from_rotvec(x[n : n + 3]).as_matrix()
        return (
            np.exp(x[-1]) * identity.neutral_vertices(x[:n]) @ rot.T + x[n + 3 : n + 6]
        )

    keep_n = max(3, int(settings.trim * tpl.get_template().num_vertices))
    for _ in range(settings.model_rounds):
        d, j = tree.query(model(x0))
        keep = np.argsort(d)[:keep_n]
        target, normal = points[j[keep]], normals[j[keep]]

        def residuals(x):
            dx = model(x)[keep] - target
            return np.concatenate(
                [(dx * normal).sum(1), 0.2 * dx.ravel(), settings.model_prior * x[:n]]
            )

        x0 = least_squares(
            residuals, x0, max_nfev=settings.model_steps, diff_step=1e-4
        ).x
    vertices = model(x0)
    d, _ = tree.query(vertices)
    return vertices, x0[:n], float(np.sqrt(np.mean(np.sort(d)[:keep_n] ** 2)))


def nonrigid(vertices, points, settings=Registration()):
    """Non-rigid ICP (Amberg et al. 2007) of the template's triangles at ``vertices``
    onto ``points``, with the stiffness schedule of ``settings``
    (trimesh.registration.nricp_amberg)."""
    import trimesh

    source = trimesh.Trimesh(vertices, tpl.get_template().faces, process=False)
    return np.asarray(
        trimesh.registration.nricp_amberg(
            source,
            points,
            steps=[list(s) for s in settings.stiffness],
            distance_threshold=settings.match_distance_mm,
            use_faces=False,
        )
    )


def _vertex_regions():
    """Each template vertex's landmark region (LANDMARK_REGIONS) by its nearest landmark
    in canonical coordinates, or "skin" farther than 12 mm from every landmark."""
    t = tpl.get_template()
    d, j = cKDTree(t.canonical[t.landmark_index]).query(t.canonical)
    names = np.array(
        [next(k for k, r in tpl.LANDMARK_REGIONS.items() if i in r) for i in j],
        dtype=object,
    )
    names[d > 12.0] = "skin"
    return names


@dataclass
class FittedTemplate:
    """The template fitted onto a :class:`UserMesh`, and the map that carries motion
    back to the user's vertices.

    ``fitted`` is the template (V, 3) on the user's face in mm and the user's pose;
    ``pose`` = (R, t) takes it to the canonical pose of the networks (``neutral`` =
    fitted R^T + t, as rows).  ``residual_mm``: per region, the median distance from the
    fitted template's vertices to the user's surface."""

    mesh: UserMesh
    fitted: np.ndarray
    pose: tuple
    residual_mm: dict
    seconds: dict
    # (triangle, barycentric, distance mm) of each user vertex
    correspondence: tuple = field(repr=False)
    # the template after each stage (V, 3), user mm and pose
    stages: dict = field(default_factory=dict, repr=False)
    settings: Registration = Registration()

    @property
    def neutral(self):
        """The fitted template in the canonical pose (mm): the neutral mesh that the
        networks animate."""
        r, t = self.pose
        return (self.fitted @ r.T + t).astype(np.float32)

    @property
    def landmarks(self):
        """The 68 landmarks (68, 3) in the user's units and pose."""
        return self.fitted[tpl.get_template().landmark_index] / UNITS[self.mesh.units]

    def colors(self):
        """The template's albedo (V_user, 3) at each user vertex's closest point of the
        fitted template (lips, brows, the mouth interior): for renders of the user's
        mesh."""
        tri, bary, _ = self.correspondence
        return interpolate(
            tpl.get_template().colors, tpl.get_template().faces, tri, bary
        )

    def fitted_in_user_units(self):
        return self.fitted / UNITS[self.mesh.units]

    def transfer(self, frames):
        """Carry template frames (F, V, 3), canonical pose and mm, to the user's mesh:
        (F, V_user, 3) in the user's units and pose.  Each user vertex moves by the
        motion (frame - frame 0) at its closest point of the fitted template, in full
        within falloff_mm[0] of it and fading smoothly to none at falloff_mm[1]: frame
        0 is the user's mesh exactly, and the back of a head does not tear away."""
        frames = np.asarray(frames, dtype=np.float64)
        expected = (tpl.get_template().num_vertices, 3)
        if frames.ndim != 3 or frames.shape[1:] != expected:
            raise ValueError(
                f"frames must be (F, {expected[0]}, 3) template meshes, "
                f"got {frames.shape}"
            )
        tri, bary, dist = self.correspondence
        faces = tpl.get_template().faces
        moved = interpolate(frames - frames[:1], faces, tri, bary)  # (F, V_user, 3)
        near, far = self.settings.falloff_mm
        weight = np.clip((far - dist) / (far - near), 0.0, 1.0)
        weight = weight * weight * (3 - 2 * weight)  # smoothstep: no crease
        r, _ = self.pose
        moved = (moved * weight[None, :, None]) @ r  # canonical -> the user's pose
        return self.mesh.vertices[None] + moved / UNITS[self.mesh.units]


def register(mesh, settings=Registration()):
    """Fit the template onto ``mesh`` (a :class:`UserMesh`): rigid alignment, the
    identity model, non-rigid ICP. Refuses a mesh that is not a face
    (:class:`NotAFaceError`: the rigid residual over settings.max_residual_mm, or a
    scale outside FACE_SCALE) with that residual."""
    import trimesh

    seconds = {}
    t = tpl.get_template()
    tm = trimesh.Trimesh(mesh.mm, mesh.faces, process=False)
    if tm.area <= 0:
        raise ValueError(
            f"{mesh.source} has no surface area (every triangle is degenerate)"
        )
    t0 = time.perf_counter()
    points, face_index = trimesh.sample.sample_surface(tm, settings.samples, seed=0)
    normals = tm.face_normals[face_index]
    s, r, tr, rigid_residual = rigid_alignment(points, t.vertices, settings)
    seconds["rigid"] = time.perf_counter() - t0
    lo, hi = FACE_SCALE
    if rigid_residual > settings.max_residual_mm or not lo <= s <= hi:
        raise NotAFaceError(
            f"{mesh.source} does not look like a face: the best rigid placement of the"
            f" template leaves a residual of {rigid_residual:.2f} mm at {s:.2f} times"
            f" its size; a face fits within {settings.max_residual_mm:g} mm at"
            f" {lo:g}-{hi:g} times the template's size",
            rigid_residual,
            s,
        )
    t0 = time.perf_counter()
    model_fit, _, model_residual = fit_identity(points, normals, (s, r, tr), settings)
    seconds["identity model"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    fitted = nonrigid(model_fit, points, settings)
    seconds["non-rigid"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    _, rot, trans = similarity(fitted, t.vertices, scale=False)
    _, _, dist = closest_points(mesh.mm, mesh.faces, fitted)
    regions = _vertex_regions()
    residual = {
        "all": float(np.median(dist)),
        "rigid (trimmed RMS)": rigid_residual,
        "identity model (trimmed RMS)": model_residual,
    }
    residual.update(
        {
            k: float(np.median(dist[regions == k]))
            for k in (*tpl.LANDMARK_REGIONS, "skin")
        }
    )
    canonical_user = mesh.mm @ rot.T + trans
    correspondence = closest_points(fitted @ rot.T + trans, t.faces, canonical_user)
    seconds["correspondence"] = time.perf_counter() - t0
    stages = {
        "rigid": s * t.vertices @ r.T + tr,
        "identity model": model_fit,
        "non-rigid": fitted,
    }
    return FittedTemplate(
        mesh, fitted, (rot, trans), residual, seconds, correspondence, stages, settings
    )
