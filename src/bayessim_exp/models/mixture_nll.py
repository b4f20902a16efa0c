"""The negative log-likelihood of a Gaussian mixture whose components are given by upper Cholesky
factors U of their precisions: log N(theta; mu, (U^T U)^-1) = sum log diag U - |U (theta - mu)|^2 / 2
- D/2 log 2pi.

`mixture_nll` takes the factors as matrices (the calibration's spread rescales them).
`HeadNLL` takes the mixture head's raw outputs (models/mdnn.py: logits, means, log-diagonals and
strict upper triangles of U side by side) and has its gradient written out: a training step of a small
network on a GPU costs a few microseconds per kernel, whatever the kernel does, and autograd through
the matrix form (U assembled by a scatter, a batched product, log of its diagonal, log-softmax and
log-sum-exp) launches about twice as many kernels as the formulas below.
"""

from __future__ import annotations

import math

import torch

LOG_DIAGONAL_BOUND = 12.0  # log diag U clamped to +-this: exp stays finite, gradients stop beyond it


def mixture_nll(logits: torch.Tensor, means: torch.Tensor, U: torch.Tensor, theta: torch.Tensor) -> torch.Tensor:
    """-log q(theta_n) for logits [N, K], means [N, K, D], precision factors U [N, K, D, D], theta [N, D]."""
    z = (U @ (theta[:, None, :] - means).unsqueeze(-1)).squeeze(-1)
    log_det = torch.log(torch.diagonal(U, dim1=-2, dim2=-1)).sum(-1)
    comp = log_det - 0.5 * (z**2).sum(-1) - 0.5 * means.shape[-1] * math.log(2 * math.pi)
    return -torch.logsumexp(torch.log_softmax(logits, -1) + comp, -1)


class HeadNLL(torch.autograd.Function):
    """-log q(theta_n) [N] from the head's outputs [N, K (1 + 2 D + P)] (P = D (D - 1) / 2 for full
    factors, 0 for diagonal ones; the strict upper triangle of U row by row: U[rows[p], cols[p]]).

    With d = theta - mu, s = exp(log diag U), z = s d + (off-diagonal terms), comp_k = sum log s - |z|^2 / 2
    and r = softmax(logits + comp) (the responsibilities), w = softmax(logits):
    nll = logsumexp(logits) - logsumexp(logits + comp) + D/2 log 2pi, and for an upstream gradient g
    d/dlogits = g (w - r), d/dcomp = -g r, d/dz = g r z, d/dlog s = -g r + (g r z) s d,
    d/dmu = -d/dd, d/dd_j = (g r z_j) s_j + sum over U[i, j] above the diagonal of (g r z_i) U[i, j],
    d/dU[i, j] = (g r z_i) d_j.
    """

    @staticmethod
    def forward(ctx, out: torch.Tensor, theta: torch.Tensor, rows: torch.Tensor, cols: torch.Tensor,
                components: int) -> torch.Tensor:
        n, k, dim, pairs = len(out), components, theta.shape[-1], len(rows)
        logits, means, log_diag_raw, off = torch.split(out, [k, k * dim, k * dim, k * pairs], -1)
        log_diag_raw = log_diag_raw.reshape(n, k, dim)
        log_diag = log_diag_raw.clamp(-LOG_DIAGONAL_BOUND, LOG_DIAGONAL_BOUND)
        diff = theta[:, None, :] - means.reshape(n, k, dim)
        scale = log_diag.exp()
        z_diag = scale * diff
        z, off, diff_cols = z_diag, off.reshape(n, k, pairs), None
        if pairs:
            diff_cols = diff.index_select(-1, cols)
            z = z_diag.index_add(-1, rows, off * diff_cols)
        comp = torch.addcmul(log_diag, z, z, value=-0.5).sum(-1)
        log_w = torch.log_softmax(logits, -1)
        log_r = torch.log_softmax(logits + comp, -1)
        # logsumexp(logits + comp) = (logits + comp - log r)_k for every k: taken where r is largest,
        # so that a far component's large |comp| does not cancel
        log_r_max, top = log_r.max(-1, keepdim=True)
        nll = (log_r_max - (log_w + comp).gather(-1, top)).squeeze(-1) + 0.5 * dim * math.log(2 * math.pi)
        inside = log_diag == log_diag_raw  # where the clamp passes gradients
        ctx.save_for_backward(log_w, log_r, z, z_diag, scale, diff, diff_cols, off, inside, rows, cols)
        return nll

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, grad: torch.Tensor):
        log_w, log_r, z, z_diag, scale, diff, diff_cols, off, inside, rows, cols = ctx.saved_tensors
        n, k, dim = diff.shape
        g = grad[:, None]
        neg_gr = log_r.exp() * -g  # d/dcomp
        d_logits = torch.addcmul(neg_gr, log_w.exp(), g)
        neg_dz = neg_gr[..., None] * z  # -d/dz
        d_log_diag = torch.addcmul(neg_gr[..., None], neg_dz, z_diag, value=-1) * inside
        d_means = neg_dz * scale
        parts = [d_logits, d_means, d_log_diag]
        if len(rows):
            neg_dz_rows = neg_dz.index_select(-1, rows)
            d_means.index_add_(-1, cols, neg_dz_rows * off)
            parts.append(torch.mul(neg_dz_rows, diff_cols).neg_())
        d_out = torch.cat([p.reshape(n, -1) for p in parts], -1)
        d_theta = -d_means.sum(1) if ctx.needs_input_grad[1] else None
        return d_out, d_theta, None, None, None
