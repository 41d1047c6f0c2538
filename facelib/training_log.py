"""Loss curves of the training loops: running means written to a history dict."""
import time

import numpy as np


class TrainingLog:
    """Collects per-step values and, every ``every`` steps and at the last one, appends their
    running mean to ``history[name]`` together with the step number and the elapsed seconds.

    ``history`` is a plain dict of lists ({"step": [...], name: [...], ..., "seconds": [...]}),
    saved in the checkpoint's JSON and plotted by the chapters.
    """

    def __init__(self, total_steps, every, *names):
        self.total_steps, self.every = total_steps, every
        self.history = {"step": [], **{name: [] for name in names}, "seconds": []}
        self._running = {name: [] for name in names}
        self._t0 = time.perf_counter()

    def add(self, step, **values):
        """Record the values of (0-based) ``step``; a value may be a float or a 0-d tensor."""
        for name, value in values.items():
            self._running[name].append(float(value))
        if (step + 1) % self.every == 0 or step + 1 == self.total_steps:
            self.history["step"].append(step + 1)
            for name, running in self._running.items():
                self.history[name].append(float(np.mean(running)))
                running.clear()
            self.history["seconds"].append(time.perf_counter() - self._t0)
