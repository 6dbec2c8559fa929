"""Exact hereditary integrals of exponential kernels for piecewise-linear histories.

The Boltzmann (and QLV) superposition integral with a Prony kernel,

    y(t) = w_inf h(t) + sum_i w_i integral_0^t exp(-(t - s) / tau_i) dh(s),

is evaluated with the recursive exponential update. Over a sample interval of length dt in
which the history h rises linearly at the rate r, each internal variable
q_i(t) = integral_0^t exp(-(t - s)/tau_i) dh(s) updates exactly as

    q_i(t + dt) = exp(-dt/tau_i) q_i(t) + r tau_i (1 - exp(-dt/tau_i)),

so the result is exact (to rounding) for any history that is linear between samples,
whatever the sample spacing. A non-zero first sample h(t_0) is a jump at t_0 from zero.
"""

from __future__ import annotations

from itertools import accumulate

import numpy as np

from warptissue.errors import InputError

__all__ = ["exponential_hereditary_states", "validate_history"]


def validate_history(
    time_s: np.ndarray | list[float], history: np.ndarray | list[float], *, name: str
) -> tuple[np.ndarray, np.ndarray]:
    """Check a sampled history: 1-D, equal length, finite, strictly increasing time.

    Args:
        time_s: Sample times, shape (n,), in seconds.
        history: Sampled input, shape (n,) (for example displacement_m).
        name: The history's name, used in error messages.

    Returns:
        The two arrays as float64.

    Raises:
        InputError: Shapes differ, values are not finite or time does not increase.
    """
    time = np.asarray(time_s, dtype=np.float64)
    values = np.asarray(history, dtype=np.float64)
    if time.ndim != 1 or values.shape != time.shape:
        raise InputError(
            f"time_s and {name} must be 1-D arrays of equal length",
            value=(time.shape, values.shape),
        )
    if time.size == 0:
        raise InputError("the history is empty", column="time_s")
    for label, array in (("time_s", time), (name, values)):
        bad = np.flatnonzero(~np.isfinite(array))
        if bad.size:
            raise InputError(
                f"non-finite value at sample {bad[0]}", column=label, value=float(array[bad[0]])
            )
    steps = np.diff(time)
    if np.any(steps <= 0.0):
        first = int(np.flatnonzero(steps <= 0.0)[0]) + 1
        raise InputError(
            f"time must increase strictly; it does not at sample {first}",
            column="time_s",
            value=float(time[first]),
        )
    return time, values


def exponential_hereditary_states(
    time_s: np.ndarray, history: np.ndarray, relaxation_times_s: np.ndarray
) -> np.ndarray:
    """Internal variables q_i(t_n) of exponential kernels driven by a piecewise-linear history.

    Args:
        time_s: Strictly increasing sample times, shape (n,), in seconds.
        history: The driving history h at the samples, shape (n,); linear in between.
        relaxation_times_s: Kernel time constants tau_i > 0, shape (m,), in seconds.

    Returns:
        q of shape (m, n): q[i, k] = integral_{t_0^-}^{t_k} exp(-(t_k - s)/tau_i) dh(s), with
        the jump h(t_0) at the first sample included.

    Notes:
        The recursion ``q_{k+1} = a_k q_k + b_k`` (module docstring) is summed in closed form,
        ``q_k = exp(-C_k) (exp(C_m) q_m + sum_{j=m}^{k-1} b_j exp(C_{j+1}))`` with
        ``C_k = sum_{j<k} dt_j / tau``, by NumPy over blocks of samples in which ``C`` grows by
        less than :data:`BLOCK_DECAY` (so no exponential overflows); each term is the
        recursion's own to rounding. A Python loop runs over the blocks only (one per
        ``BLOCK_DECAY`` relaxation times of the record), not over the samples, unless the
        relaxation time is so far below the sample spacing that the blocks are short; then
        the recursion runs sample by sample.
    """
    taus = np.asarray(relaxation_times_s, dtype=np.float64).reshape(-1)
    states = np.empty((taus.size, time_s.size), dtype=np.float64)
    if time_s.size == 1:
        states[:] = history[0]
        return states
    dt = np.diff(time_s)
    rate = np.diff(history) / dt
    for i, tau in enumerate(taus):
        gain = rate * tau * -np.expm1(-dt / tau)
        decays = np.concatenate([[0.0], np.cumsum(dt / tau)])  # C_k
        states[i] = _summed_recursion(decays, gain, float(history[0]))
    return states


BLOCK_DECAY = 500.0
"""Largest growth of the decay exponent C within one block of samples (exp(500) ~ 1e217)."""


def _summed_recursion(decays: np.ndarray, gains: np.ndarray, first: float) -> np.ndarray:
    """q with ``q_0 = first`` and ``q_{k+1} = exp(-(C_{k+1} - C_k)) q_k + gains_k``.

    Args:
        decays: C_k, non-decreasing, shape (n,), C_0 = 0.
        gains: b_k, shape (n - 1,).
        first: q_0.
    """
    q = np.empty_like(decays)
    q[0] = first
    blocks = np.floor(decays[1:] / BLOCK_DECAY)
    starts = np.concatenate([[0], np.flatnonzero(np.diff(blocks)) + 1, [blocks.size]])
    if len(starts) > 8 + gains.size // 16:
        # Relaxation times far below the sample spacing: few samples a block, so the
        # recursion itself is the cheaper loop.
        factors = np.exp(-np.diff(decays)).tolist()
        return np.fromiter(
            accumulate(
                zip(factors, gains.tolist(), strict=True),
                lambda value, step: step[0] * value + step[1],
                initial=first,
            ),
            dtype=np.float64,
            count=decays.size,
        )
    for start, stop in zip(starts[:-1], starts[1:], strict=True):
        nodes = slice(start + 1, stop + 1)  # q's samples of this block
        reference = blocks[start] * BLOCK_DECAY
        scale = np.exp(decays[nodes] - reference)  # in [1, exp(BLOCK_DECAY))
        carried = q[start] * np.exp(decays[start] - reference)  # <= q[start]; may underflow
        q[nodes] = (carried + np.cumsum(gains[start:stop] * scale)) / scale
    return q
