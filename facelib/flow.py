"""Rectified flow (Liu et al. 2023; flow matching, Lipman et al. 2023) on the Gaussian
path of the DDPM, with the same denoiser network.

The path joins a clean sequence x_0 (tau = 0) to pure noise eps (tau = 1) by a straight
line,

    x_tau = (1 - tau) x_0 + tau eps,                      u = dx_tau / dtau = eps - x_0,

and the network learns the velocity u_theta(x_tau, tau) = E[u | x_tau] by regression,

    L = E_{tau ~ U(0, 1), x_0, eps} ||u - u_theta(x_tau, tau)||^2.

Sampling integrates dx/dtau = u_theta from tau = 1 (noise) down to tau = 0 with Euler's
or Heun's method.

The same path as the DDPM's.  Divided by s(tau) = sqrt((1 - tau)^2 + tau^2), x_tau is a
variance-preserving sample, sqrt(abar) x_0 + sqrt(1 - abar) eps, at

    abar(tau) = (1 - tau)^2 / ((1 - tau)^2 + tau^2),

so the denoiser of the DDPM runs unchanged on x_tau / s(tau) with this abar (its
``schedule="flow"``: continuous time labels t = tau T) and predicts u
(``prediction="u"``).  Its noise estimate is then eps = x_tau + (1 - tau) u, and the
flow's loss is the DDPM's eps-loss weighted by 1 / (1 - tau)^2.  One Euler step of the
flow is exactly one DDIM step (eta = 0) between the same two noise levels (the flow
chapter derives it; tests/test_flow.py checks it).
"""

from __future__ import annotations

import numpy as np
import torch
from tqdm.auto import tqdm

from .diffusion import device_of, masked_mean

SOLVERS = ("euler", "heun")


def flow_scale(tau):
    """s(tau) = sqrt((1 - tau)^2 + tau^2): x_tau / s(tau) has unit variance for unit x_0
    and eps."""
    return ((1 - tau) ** 2 + tau**2) ** 0.5


def check_solver(solver):
    if solver not in SOLVERS:
        raise ValueError(
            f"unknown ODE solver {solver!r}; allowed: {', '.join(SOLVERS)}"
        )


def check_flow_model(model):
    """A clear error unless ``model`` is a denoiser trained as a rectified flow
    (``DenoiserConfig(schedule="flow", prediction="u")``): another network's output is
    no velocity on this path."""
    c = getattr(model, "config", None)
    made_for = (getattr(c, "schedule", None), getattr(c, "prediction", None))
    if made_for != ("flow", "u"):
        raise ValueError(
            "the rectified flow samples a denoiser trained as a flow (schedule 'flow',"
            f" prediction 'u'), got one of schedule {made_for[0]!r} and prediction"
            f" {made_for[1]!r}: sample it by its GaussianDiffusion (DDPM or DDIM)"
        )


class RectifiedFlow:
    """The straight path between data and noise, its loss and its ODE samplers, for a
    denoiser whose time labels are t = tau T (``DenoiserConfig(schedule="flow",
    prediction="u")``)."""

    def __init__(self, num_steps=2000):
        self.num_steps = num_steps  # T: the time label of tau = 1

    def __repr__(self):
        return f"RectifiedFlow(T={self.num_steps})"

    def interpolate(self, x0, tau, eps):
        """x_tau = (1 - tau) x_0 + tau eps, tau (B,)."""
        tau = tau.to(x0.dtype).reshape(-1, *([1] * (x0.ndim - 1)))
        return (1 - tau) * x0 + tau * eps

    def velocity(self, model, x, tau, mask=None, **model_inputs):
        """u_theta(x_tau, tau): the network reads x_tau / s(tau) at time label tau T."""
        tau = torch.as_tensor(tau, dtype=torch.float32, device=x.device).expand(len(x))
        scale = flow_scale(tau).to(x.dtype).reshape(-1, *([1] * (x.ndim - 1)))
        return model.velocity(x / scale, tau * self.num_steps, mask, **model_inputs)

    def training_loss(
        self, model, x0, tau=None, generator=None, mask=None, eps=None, **model_inputs
    ):
        """E ||u - u_theta(x_tau, tau)||^2 (mean over valid entries), tau ~ U(0, 1) and
        eps ~ N(0, I) drawn from ``generator`` unless given."""
        if tau is None:
            tau = torch.rand(x0.shape[0], generator=generator)
        if eps is None:
            eps = torch.randn(x0.shape, generator=generator, dtype=x0.dtype)
        tau, eps = tau.to(x0.device), eps.to(x0.device)
        if tau.min() < 0 or tau.max() > 1:
            raise ValueError("flow times tau must lie in [0, 1]")
        u_hat = self.velocity(
            model, self.interpolate(x0, tau, eps), tau, mask, **model_inputs
        )
        return masked_mean((eps - x0 - u_hat) ** 2, mask)

    def times(self, steps):
        """The grid 1 = tau_0 > tau_1 > ... > tau_K = 0 of a K-step solve (uniform)."""
        if (
            isinstance(steps, bool)
            or not isinstance(steps, (int, np.integer))
            or steps < 1
        ):
            raise ValueError(
                f"the number of ODE steps must be a positive integer, got {steps!r}"
            )
        return torch.linspace(1.0, 0.0, steps + 1, dtype=torch.float64)

    @torch.no_grad()
    def sample(
        self,
        model,
        shape,
        steps,
        solver="euler",
        generator=None,
        mask=None,
        x=None,
        progress=False,
        **model_inputs,
    ):
        """x_0 from x_1 ~ N(0, I) (or the given ``x``) by ``steps`` steps of Euler's
        method, x_{tau'} = x_tau + (tau' - tau) u_theta(x_tau, tau), or of Heun's (the
        Euler step's end point corrected by the mean of the two slopes; the last step,
        to tau = 0, stays Euler as in Karras et al. 2022): 2 K - 1 network calls."""
        check_solver(solver)
        check_flow_model(model)
        device = device_of(model) or torch.device("cpu")
        if x is None:
            x = torch.randn(shape, generator=generator).to(device)
        grid = self.times(steps)
        for k in tqdm(range(steps), disable=not progress, desc=f"flow ({solver})"):
            tau, nxt = grid[k].item(), grid[k + 1].item()
            u = self.velocity(model, x, tau, mask, **model_inputs)
            x_next = x + (nxt - tau) * u
            if solver == "heun" and nxt > 0:
                u_next = self.velocity(model, x_next, nxt, mask, **model_inputs)
                x_next = x + (nxt - tau) * 0.5 * (u + u_next)
            x = x_next
        return x
