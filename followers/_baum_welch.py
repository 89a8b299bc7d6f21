"""Baum–Welch statistics of a left-to-right Gaussian HMM, in log space and banded.

From state i the chain moves to i + j, j = 0 .. J - 1 (``log_a[i, j]``, -inf past the last
state); it starts in state 0 and may end anywhere. Emissions are diagonal Gaussians. The
forward and backward variables are kept as logarithms, so a demonstration far from every
state (a likelihood below 1e-308) is no underflow; a step costs S J, not S².
"""
import numba as nb
import numpy as np


@nb.njit(cache=True)
def _log_sum(a, b):
    if a == -np.inf:
        return b
    if b == -np.inf:
        return a
    if a > b:
        return a + np.log1p(np.exp(b - a))
    return b + np.log1p(np.exp(a - b))


@nb.njit(cache=True)
def emission_log(X, means, var, out):
    """``out[t, i]`` = log N(X[t] | means[i], diag var[i]) for X (N, D), means/var (S, D)."""
    N, D = X.shape
    S = means.shape[0]
    norm = np.zeros(S)
    for i in range(S):
        for d in range(D):
            norm[i] -= 0.5 * np.log(2.0 * np.pi * var[i, d])
    for t in range(N):
        for i in range(S):
            q = 0.0
            for d in range(D):
                diff = X[t, d] - means[i, d]
                q += diff * diff / var[i, d]
            out[t, i] = norm[i] - 0.5 * q


@nb.njit(cache=True)
def forward_backward(log_b, log_a, alpha, beta):
    """Fill ``alpha``, ``beta`` (N, S) with the log forward and backward variables of one
    sequence of emission log-densities ``log_b (N, S)``; returns its log-likelihood."""
    N, S = log_b.shape
    J = log_a.shape[1]
    alpha[0, :] = -np.inf
    alpha[0, 0] = log_b[0, 0]
    for t in range(1, N):
        for i in range(S):
            total = -np.inf
            for j in range(min(J, i + 1)):
                total = _log_sum(total, alpha[t - 1, i - j] + log_a[i - j, j])
            alpha[t, i] = total + log_b[t, i]
    beta[N - 1, :] = 0.0
    for t in range(N - 2, -1, -1):
        for i in range(S):
            total = -np.inf
            for j in range(min(J, S - i)):
                total = _log_sum(total, log_a[i, j] + log_b[t + 1, i + j] + beta[t + 1, i + j])
            beta[t, i] = total
    total = -np.inf
    for i in range(S):
        total = _log_sum(total, alpha[N - 1, i])
    return total


@nb.njit(cache=True)
def accumulate(X, log_b, log_a, alpha, beta, loglik, weight, first, second, moves):
    """Add one sequence's expected counts: state occupancy ``weight (S,)``, its weighted sums
    ``first``, ``second (S, D)`` of X and X², and transitions ``moves (S, J)``."""
    N, S = log_b.shape
    J = log_a.shape[1]
    D = X.shape[1]
    for t in range(N):
        for i in range(S):
            g = np.exp(alpha[t, i] + beta[t, i] - loglik)
            if g == 0.0:
                continue
            weight[i] += g
            for d in range(D):
                first[i, d] += g * X[t, d]
                second[i, d] += g * X[t, d] * X[t, d]
    for t in range(N - 1):
        for i in range(S):
            if alpha[t, i] == -np.inf:
                continue
            for j in range(min(J, S - i)):
                moves[i, j] += np.exp(alpha[t, i] + log_a[i, j] + log_b[t + 1, i + j]
                                      + beta[t + 1, i + j] - loglik)
