"""Checks that an effect defined by a time in seconds (a creep's relaxation) is what the residual shows.

A slow relaxation and a rate-independent loop can look alike on one run; they part on runs of
one shape at several speeds: the loop's apparent time follows each run, the relaxation's does not.
And a mode far slower than a run, at a steady start, only sets that run's offset: an effect that
shows nothing once each run's own offset and gain are taken out is not one that can be named.
"""

from __future__ import annotations

import numpy as np

from physics import Signature

from ._shapes import along, free_drops

__all__ = ["not_in_time", "TIMESCALE_MAX_SLOPE"]


#: A ``timescale`` effect's best time on each run alone, fitted over this many grid points per
#: decade from ``TIMESCALE_FROM_S`` to a quarter of the run (wider than the effect's own grid,
#: which is bounded to tell it from faster blocks), and the largest log-log slope of that time
#: against the runs' durations for a time that holds whatever the speed: a loop traced at
#: several speeds reads as a slope of 1 (its apparent time follows the run), one time constant as
#: 0, and a sum of relaxations over a decade (the longer ones taken for each run's offset and gain
#: on short runs) as about 0.65.
TIMESCALE_POINTS, TIMESCALE_FROM_S, TIMESCALE_MAX_SLOPE = 12, 0.02, 0.85


def not_in_time(sig: Signature, traces, gain: float, noise_std: float, min_score: float) -> bool:
    """True when the effect of a ``timescale`` signature ``sig`` fails its checks on the residual
    ``traces`` (``ResidualTrace``; ``gain`` the model's, output per input unit): it explains less
    than ``min_score`` of the residual within the runs, or the best time fitted on each run alone
    grows with the runs' durations (log-log slope above ``TIMESCALE_MAX_SLOPE``). False for any
    other signature."""
    if sig.timescale is None:
        return False
    key, drops, energy, fits = sig.timescale, 0.0, 0.0, []
    for t in traces:
        dur = float(t.time[-1] - t.time[0])
        hi = max(0.25 * dur, 2 * TIMESCALE_FROM_S)
        grid = [{key: float(x)} for x in np.geomspace(TIMESCALE_FROM_S, hi,
                                                       int(TIMESCALE_POINTS * np.log10(hi / TIMESCALE_FROM_S)) + 2)]
        signal = along(t, sig.signal)
        own = np.column_stack([np.ones(t.time.size), signal - signal.mean()])  # this run's offset and gain
        q, _ = np.linalg.qr(own)
        r = t.residual - q @ (q.T @ t.residual)
        f = sig.shapes(signal, t.dt, grid)
        f = f - q @ (q.T @ f)
        drop, _ = free_drops(f, r, gain, sig.positive)
        j = int(np.argmax(drop))
        drops, energy = drops + float(drop[j]), energy + float(r @ r)
        if drop[j] >= min_score * float(r @ r) and np.sqrt(drop[j] / r.size) >= 0.25 * noise_std:
            fits.append((dur, grid[j][key]))
    if energy <= 0 or drops < min_score * energy:
        return True
    durs = np.array([d for d, _ in fits])
    if durs.size >= 2 and durs.max() > 1.5 * durs.min():
        slope = np.polyfit(np.log(durs), np.log([x for _, x in fits]), 1)[0]
        return bool(slope > TIMESCALE_MAX_SLOPE)
    return False
