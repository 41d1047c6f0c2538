"""facelib: the code of *Diffusion for 4D Faces*, a reconstruction of the 4D Facial
Expression Diffusion Model (Zou et al. 2023) on a synthetic face world.

The map of the package, bottom to top.  A module imports only from the layers below it
(tests/test_layout.py checks every import):

0. ``config``: paths, the world, the datasets, and the constants several modules read
   (paper value or our choice).  ``checks``: the checks every setting shares (a
   choice, a number, an integer, a probability).  ``files``: the atomic write.
   ``options``: a setting's command-line option (help, choices, type), written once
   on its field.
1. ``face``: the synthetic face world: template, identities, action units,
   expressions, sequences.  ``metrics``: accuracy, FID, diversity, seams, bootstrap
   intervals.  ``srvf``: square-root velocity.  ``chapters``: run one chapter notebook
   (``make chapter N=05``) and record its time.  ``paper``: the paper's published
   tables, as printed.
2. ``data``: dataset generation and cache, FaceDataset, splits, the landmark
   normaliser.  ``descriptions``: the words for every expression.  ``diffusion``:
   schedules and GaussianDiffusion (Eq. 1-8).  ``viz``: plots, renders, GIFs.
   ``meshio``: OBJ in and out, all or nothing.  ``registration``: a reader's mesh (any
   topology, units, pose) -> the template fitted onto it, motion carried back.
   ``tables``: numbers with their intervals, Markdown tables, the paper's table beside
   ours.
3. ``text``: the offline sentence encoder.  ``models``: networks and their configs
   only.  ``checkpoints``: weights + JSON config, sha256-checked.  ``flow``: rectified
   flow on the DDPM's path (its loss, Euler and Heun).
4. ``guidance``: sampler hooks: Adagrad optimisation (Alg. 1-2), mean shift,
   reconstruction guidance.  ``inpainting``: known frames (Alg. 3).  ``rig_fit``: the
   rig fitted to landmarks.  ``toy``: a 2-D DDPM.
5. ``baselines``: the related papers' models.  ``deformation``: §3.3 mesh deformation.
   ``evaluation``: the independent classifier and its scores.
6. ``tasks``: unconditional, label (Alg. 1), text (Alg. 2), fill (Alg. 3), geometry
   (Alg. 4), and each task's settings (tasks/settings.py).  ``text_eval``:
   measurements of text control: what the head reads, compositions, order and label.
7. ``pipeline``: neutral mesh -> animated meshes.  ``training``: one loop, one recipe
   per model, each recipe's settings (training/settings.py).  ``experiments``: the
   inputs the tables and benchmarks measure the tasks on (Table 1's rows, Table 4's
   inputs, random AU requests and keyframes, the rig fit's floor).
8. ``cli_sample``: the command line's ``sample TASK`` (a subcommand per task, options
   from the tasks' settings).  ``results``: stored full-scale results with their
   provenance (the settings they measured, whichever layer holds them).
9. ``__main__``: the command line: ``python -m facelib
   data|train|sample TASK|neutral|animate|register|chapter|results``.

The public API is the modules themselves: ``from facelib import tasks;
tasks.label_control("high_smile")``.
"""

# The layer of every module and subpackage (the map above); tests/test_layout.py checks
# each import against it.
LAYERS = {
    "config": 0,
    "checks": 0,
    "files": 0,
    "options": 0,
    "face": 1,
    "metrics": 1,
    "srvf": 1,
    "chapters": 1,
    "paper": 1,
    "data": 2,
    "descriptions": 2,
    "diffusion": 2,
    "viz": 2,
    "meshio": 2,
    "registration": 2,
    "tables": 2,
    "text": 3,
    "models": 3,
    "checkpoints": 3,
    "flow": 3,
    "guidance": 4,
    "inpainting": 4,
    "rig_fit": 4,
    "toy": 4,
    "baselines": 5,
    "deformation": 5,
    "evaluation": 5,
    "tasks": 6,
    "text_eval": 6,
    "pipeline": 7,
    "experiments": 7,
    "training": 7,
    "cli_sample": 8,
    "results": 8,
    "__main__": 9,
}
__all__ = [
    "baselines",
    "chapters",
    "checkpoints",
    "checks",
    "cli_sample",
    "config",
    "data",
    "deformation",
    "descriptions",
    "experiments",
    "diffusion",
    "evaluation",
    "face",
    "files",
    "options",
    "flow",
    "guidance",
    "inpainting",
    "meshio",
    "metrics",
    "models",
    "paper",
    "pipeline",
    "registration",
    "results",
    "rig_fit",
    "srvf",
    "tables",
    "tasks",
    "text",
    "text_eval",
    "toy",
    "training",
    "viz",
]
