"""Loading protocols: the probe's depths, and its depth-time histories.

:func:`quasi_static_depths` gives the depths of a rate-independent run (even steps, or equal
steps of a sphere's contact radius). Each other function returns ``(times_s, depths_m)``,
two float arrays of shape (S,): the end of each FE time step (s, strictly increasing, > 0)
and the probe depth there (m, positive into the specimen, >= 0). The FE
(:func:`warptissue.fem.simulate_indentation` with ``times_s``) starts from depth 0 at time 0
and moves the probe linearly in time between steps, so a history is fully given by these
points.

- :func:`quasi_static_depths`: ``steps`` depths to ``max_depth_m``, even or in equal steps
  of the contact radius sqrt(R d) of a sphere.
- :func:`ramp_hold`: a constant-speed ramp, then a hold with geometrically growing steps
  (stress relaxation; Ahn & Kim's protocol).
- :func:`sine`: a ramp to a preload, then a sine about it.
- :func:`resample_history`: about ``steps`` FE steps for a measured record's own
  depth-time history (the record's displacement column).

Pure NumPy; nothing here starts Warp.

Example:
    >>> from warptissue.loading import ramp_hold
    >>> times, depths = ramp_hold(max_depth_m=0.004, speed_m_per_s=0.008, hold_s=100.0)
    >>> float(times[9]), float(depths[9]), float(times[-1])
    (0.5, 0.004, 100.5)
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from warptissue.errors import InputError

__all__ = ["DEPTH_SPACINGS", "quasi_static_depths", "ramp_hold", "resample_history", "sine"]

DEPTH_SPACINGS: tuple[str, ...] = ("even", "contact_radius")
"""The spacings of :func:`quasi_static_depths`."""

DEPTH_WEIGHT: float = 0.4
"""Share of :func:`resample_history`'s path measure given to the depth travelled (the rest
goes to log time)."""


def _positive(name: str, value: Any, *, allow_zero: bool = False) -> float:
    """``value`` as a finite float > 0 (>= 0 with ``allow_zero``), else an InputError."""
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise InputError("must be a number", key=name, value=value)
    number = float(value)
    if not math.isfinite(number) or number < 0.0 or (number == 0.0 and not allow_zero):
        problem = "must be a finite number >= 0" if allow_zero else "must be a positive number"
        raise InputError(problem, key=name, value=value)
    return number


def _count(name: str, value: Any, minimum: int) -> int:
    """``value`` as an int >= ``minimum``, else an InputError."""
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise InputError("must be an integer", key=name, value=value)
    if value < minimum:
        raise InputError(f"must be at least {minimum}", key=name, value=value)
    return int(value)


def quasi_static_depths(*, max_depth_m: float, steps: int, spacing: str = "even") -> np.ndarray:
    """The depths of a rate-independent run: ``steps`` load steps to ``max_depth_m``.

    ``"even"``: ``d_k = d_max k / n``. ``"contact_radius"``: ``d_k = d_max (k / n)^2``, the
    depths at which a sphere's Hertz contact radius ``a = sqrt(R* d)`` grows in equal steps
    of ``a_max / n`` (k = 1 ... n): fine steps at first touch, where the contact radius
    grows fastest, and the last step ``(2 n - 1) / n^2`` of the depth, about twice the even
    one.

    Args:
        max_depth_m: The last depth, m (> 0).
        steps: The number of load steps n (>= 1).
        spacing: ``"even"`` or ``"contact_radius"`` (:data:`DEPTH_SPACINGS`).

    Returns:
        The depths, shape (steps,), m, positive and strictly increasing.

    Raises:
        InputError: A depth that is not a positive number, a count below 1, or another
            spacing.

    Notes:
        Under a sphere the contact radius follows Hertz, ``a^2 = R* d`` (Johnson, Contact
        Mechanics, 1985, sec. 4.2), so equal steps of ``a`` are ``d_k = (k a_max / n)^2 /
        R* = d_max (k / n)^2`` whatever ``R*`` is. To keep the contact edge within a share
        ``s`` of the near element size ``h`` per step, take ``n >= sqrt(R* d_max) / (s h)``.
        Measured on a sphere on a ball (docs/design-notes/surface-contact.md).
    """
    depth = _positive("max_depth_m", max_depth_m)
    count = _count("steps", steps, 1)
    if spacing not in DEPTH_SPACINGS:
        raise InputError(
            f"must be one of {', '.join(map(repr, DEPTH_SPACINGS))}", key="spacing", value=spacing
        )
    if spacing == "even":
        return np.array([depth * (k + 1) / count for k in range(count)], dtype=np.float64)
    return np.array([depth * ((k + 1) / count) ** 2 for k in range(count)], dtype=np.float64)


def ramp_hold(
    *,
    max_depth_m: float,
    speed_m_per_s: float,
    hold_s: float,
    ramp_steps: int = 10,
    hold_steps: int = 20,
) -> tuple[np.ndarray, np.ndarray]:
    """A constant-speed ramp to ``max_depth_m``, then a hold (stress relaxation).

    The ramp lasts ``t_r = max_depth_m / speed_m_per_s`` in ``ramp_steps`` equal steps. The
    hold's ``hold_steps`` steps end at ``t_r + s_j`` with ``s_j`` spaced geometrically
    (equal steps in log time since the hold began) from ``s_1 = min(t_r / ramp_steps,
    hold_s / hold_steps)`` to ``s_N = hold_s``: relaxation times of soft tissue span about
    1 s to 50 s, and log-spaced steps resolve each decade alike.

    Args:
        max_depth_m: Depth of the hold, m (> 0).
        speed_m_per_s: Ramp speed, m/s (> 0).
        hold_s: Duration of the hold, s (>= 0; 0: the ramp alone).
        ramp_steps: Time steps on the ramp (>= 1).
        hold_steps: Time steps in the hold (>= 1; unused when ``hold_s`` is 0).

    Returns:
        ``(times_s, depths_m)``, each shape (ramp_steps + hold_steps,) (s, m).

    Raises:
        InputError: An argument that is not a positive number / integer (naming it).

    Notes:
        Ahn & Kim indent at up to 8 mm/s and hold for minutes; their two-term Prony series
        has tau_1 ~ 1 s and tau_2 ~ 50 s.
    """
    depth = _positive("max_depth_m", max_depth_m)
    speed = _positive("speed_m_per_s", speed_m_per_s)
    hold = _positive("hold_s", hold_s, allow_zero=True)
    n_ramp = _count("ramp_steps", ramp_steps, 1)
    n_hold = _count("hold_steps", hold_steps, 1)
    ramp_s = depth / speed
    times = [ramp_s * (k + 1) / n_ramp for k in range(n_ramp)]
    depths = [depth * (k + 1) / n_ramp for k in range(n_ramp)]
    if hold > 0.0:
        first = min(ramp_s / n_ramp, hold / n_hold)
        offsets = np.array([hold]) if n_hold == 1 else np.geomspace(first, hold, n_hold)
        times.extend((ramp_s + offsets).tolist())
        depths.extend([depth] * n_hold)
    return np.array(times, dtype=np.float64), np.array(depths, dtype=np.float64)


def sine(
    *,
    preload_depth_m: float,
    amplitude_m: float,
    frequency_Hz: float,
    cycles: int,
    preload_s: float,
    preload_steps: int = 5,
    steps_per_cycle: int = 16,
) -> tuple[np.ndarray, np.ndarray]:
    """A ramp to a preload depth, then ``preload + amplitude sin(2 pi f (t - preload_s))``.

    Args:
        preload_depth_m: Depth about which the probe oscillates, m (> 0).
        amplitude_m: Amplitude of the sine, m (> 0, at most the preload: the probe must not
            leave the specimen).
        frequency_Hz: Frequency, Hz (> 0).
        cycles: Whole cycles (>= 1).
        preload_s: Duration of the ramp to the preload, s (> 0).
        preload_steps: Equal time steps on that ramp (>= 1).
        steps_per_cycle: Equal time steps per cycle (>= 4; a multiple of 4 puts steps on
            the peaks and troughs).

    Returns:
        ``(times_s, depths_m)``, each shape (preload_steps + cycles * steps_per_cycle,).

    Raises:
        InputError: An argument out of range (naming it), or an amplitude above the preload.
    """
    preload = _positive("preload_depth_m", preload_depth_m)
    amplitude = _positive("amplitude_m", amplitude_m)
    frequency = _positive("frequency_Hz", frequency_Hz)
    n_cycles = _count("cycles", cycles, 1)
    ramp_s = _positive("preload_s", preload_s)
    n_ramp = _count("preload_steps", preload_steps, 1)
    n_cycle = _count("steps_per_cycle", steps_per_cycle, 4)
    if amplitude > preload:
        raise InputError(
            f"must not exceed preload_depth_m ({preload!r} m): the probe would leave the specimen",
            key="amplitude_m",
            value=amplitude_m,
        )
    ramp_t = ramp_s * np.arange(1, n_ramp + 1) / n_ramp
    ramp_d = preload * np.arange(1, n_ramp + 1) / n_ramp
    phase = np.arange(1, n_cycles * n_cycle + 1) / n_cycle  # cycles elapsed
    sine_t = ramp_s + phase / frequency
    sine_d = preload + amplitude * np.sin(2.0 * math.pi * phase)
    sine_d[np.abs(sine_d - preload) < 1e-12 * preload] = preload  # sin(k pi) rounding
    return np.concatenate([ramp_t, sine_t]), np.concatenate([ramp_d, sine_d])


def _as_record(time_s: Any, depth_m: Any) -> tuple[np.ndarray, np.ndarray]:
    """Validated 1-D float copies of a record's time and depth."""
    arrays = []
    for name, values in (("time_s", time_s), ("depth_m", depth_m)):
        try:
            array = np.asarray(values, dtype=np.float64)
        except (TypeError, ValueError):
            raise InputError("must be a sequence of numbers", key=name) from None
        if array.ndim != 1:
            raise InputError("must be one-dimensional", key=name, value=array.shape)
        bad = np.flatnonzero(~np.isfinite(array))
        if bad.size:
            raise InputError(
                f"not a finite number at sample {int(bad[0])}", key=name, value=float(array[bad[0]])
            )
        arrays.append(array)
    t, d = arrays
    if t.size != d.size:
        raise InputError(
            f"time_s and depth_m differ in length ({t.size} and {d.size})", key="depth_m"
        )
    if t.size < 2:
        raise InputError("needs at least 2 samples", key="time_s", value=t.size)
    steps = np.flatnonzero(np.diff(t) <= 0.0)
    if steps.size:
        i = int(steps[0])
        raise InputError(
            f"must increase strictly (sample {i + 1} is not after sample {i})",
            key="time_s",
            value=float(t[i + 1]),
        )
    return t, d


def _noise(depth: np.ndarray) -> float:
    """Robust standard deviation of the sample-to-sample noise of ``depth`` (m)."""
    if depth.size < 3:
        return 0.0
    second = np.diff(depth, 2)  # smooth ramps and holds vanish; white noise has var 6 s^2
    return float(1.4826 * np.median(np.abs(second - np.median(second))) / math.sqrt(6.0))


def _turning_points(depth: np.ndarray, threshold: float, tolerance: float) -> list[int]:
    """Indices of the significant local extrema of ``depth`` (a zigzag filter).

    A peak (trough) counts once the depth has come down (up) from it by more than
    ``threshold``; each is placed at the first sample within ``tolerance`` of its value
    since the previous turning point (the knee of a ramp into a noisy hold, not a noise
    spike later on).
    """
    points: list[int] = []
    start = 0
    direction = 0
    extreme = 0
    for i in range(1, depth.size):
        if direction == 0:
            if abs(depth[i] - depth[0]) > threshold:
                direction = 1 if depth[i] > depth[0] else -1
                extreme = i
            continue
        if direction * (depth[i] - depth[extreme]) > 0.0:
            extreme = i
        elif direction * (depth[extreme] - depth[i]) > threshold:
            segment = depth[start : extreme + 1]
            near = np.flatnonzero(direction * (depth[extreme] - segment) <= tolerance)
            point = start + int(near[0])
            points.append(point)
            start, direction, extreme = point, -direction, i
    return points


def resample_history(time_s: Any, depth_m: Any, *, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """About ``steps`` FE time steps that follow a measured depth-time history.

    A record holds thousands of samples; the FE needs a few dozen steps, placed where the
    force changes: along the ramps and sines (where the depth moves) and, in a hold, at
    times spread evenly in log time (relaxation with time constants from about 1 s to
    50 s). So the steps are spaced equally in a monotone path measure

        s(t) = w D(t) + (1 - w) L(t),   w = :data:`DEPTH_WEIGHT`,

    with D the depth travelled (the cumulative |change| of depth, through a noise-proof
    envelope), L = ln(1 + t / t_c) with t_c the time of the first turning point (the end
    of the first ramp), each normalized to 1 over the record. The turning points (the
    deepest point, and every significant peak and trough of a sine) and the last sample are
    always steps: each segment between them gets a share of the steps in proportion to its
    measure, at least one.

    The record's time axis is kept: the FE starts from depth 0 at time 0, so the caller
    passes a record whose time 0 is the contact (as conditioning with a contact point
    gives it), and samples at t <= 0 are dropped. Negative depths (noise about the contact)
    are clipped to 0.

    Args:
        time_s: Sample times, shape (n,), s, strictly increasing.
        depth_m: Probe depth at those times, shape (n,), m.
        steps: About how many FE steps (>= 2); a few more when the record has more turning
            points than that.

    Returns:
        ``(times_s, depths_m)``: strictly increasing times > 0 (s), ending at the last
        sample, and the record's depth linearly interpolated there (m).

    Raises:
        InputError: Fewer than 2 samples (or fewer than 2 after t > 0), a time that does
            not increase, a value that is not finite, or ``steps`` below 2.
    """
    count = _count("steps", steps, 2)
    t, d = _as_record(time_s, depth_m)
    later = t > 0.0
    if np.count_nonzero(later) < 2:
        raise InputError(
            "needs at least 2 samples after time 0 (the contact)", key="time_s", value=float(t[-1])
        )
    t, d = t[later], np.clip(d[later], 0.0, None)
    span = float(np.max(d) - np.min(d))
    noise = _noise(d)
    tolerance = 6.0 * noise
    threshold = max(0.01 * span, 5.0 * noise)
    last = t.size - 1
    anchors = set(_turning_points(d, threshold, tolerance)) if span > 0.0 else set()
    if span > 0.0:
        deepest = int(np.flatnonzero(d >= np.max(d) - tolerance)[0])
        anchors.add(deepest)
    anchors.discard(last)
    anchors = sorted(anchors)
    # The depth travelled, through a monotone envelope between turning points (noise in a
    # hold would otherwise add up to more than the ramp).
    travelled = np.zeros(t.size)
    bounds = [0, *anchors, last]
    total = 0.0
    for start, stop in zip(bounds[:-1], bounds[1:], strict=True):
        piece = d[start : stop + 1]
        rising = piece[-1] >= piece[0]
        envelope = np.maximum.accumulate(piece) if rising else np.minimum.accumulate(piece)
        travelled[start : stop + 1] = total + np.abs(envelope - piece[0])
        total += abs(float(envelope[-1] - piece[0]))
    # The depth at time 0 is 0: the way from there to the first sample counts too.
    travelled += float(d[0])
    total += float(d[0])
    t_c = float(t[anchors[0]]) if anchors else float(t[-1])
    log_time = np.log1p(t / t_c)
    depth_part = travelled / total if total > 0.0 else np.zeros(t.size)
    time_part = log_time / log_time[-1]
    measure = DEPTH_WEIGHT * depth_part + (1.0 - DEPTH_WEIGHT) * time_part
    # Each segment (0 | anchor | ... | last) gets steps in proportion to its measure.
    edges = [0.0, *measure[anchors].tolist(), float(measure[-1])]
    edge_times = [0.0, *t[anchors].tolist(), float(t[-1])]
    widths = np.diff(edges)
    share = np.maximum(count, len(widths)) * widths / widths.sum()
    allotted = np.maximum(1, np.floor(share)).astype(int)
    remainder = share - np.floor(share)
    for j in np.argsort(-remainder, kind="stable"):
        if allotted.sum() >= max(count, len(widths)):
            break
        allotted[j] += 1
    # measure is strictly increasing in t (log time is), so it can be inverted.
    measure_all = np.concatenate([[0.0], measure])
    time_all = np.concatenate([[0.0], t])
    times: list[float] = []
    for j, n in enumerate(allotted):
        targets = edges[j] + widths[j] * np.arange(1, n) / n
        times.extend(np.interp(targets, measure_all, time_all).tolist())
        times.append(edge_times[j + 1])
    out_t = np.array(times, dtype=np.float64)
    keep = np.concatenate([[True], np.diff(out_t) > 0.0])
    out_t = out_t[keep & (out_t > 0.0)]
    return out_t, np.interp(out_t, t, d)
