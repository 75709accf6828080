"""Contact detection in probing trials: the paper's IMU rule and a force-only detector.

IMU rule (paper, "Field Trial Contact Detection"), :func:`detect_imu`:

1. Nine accelerometer channels at 40 Hz (pushed cane and two neighbours,
   x/y/z each; format :mod:`canebench.data.imu`).
2. A rolling mean over 20 samples "to account for the slow change in
   orientation during the push". Read here as *detrending*: each channel minus
   its centred 20-sample rolling mean, so the slow drift from the cane's
   rotation is removed and the noise is what the detector sees.
3. ``ruptures`` binary segmentation with a Gaussian (rbf) kernel cost, penalty
   ``22.5 log(n)``, ``n`` the channel's length; candidates every ``jump``
   samples (0.5 s at the default 20; the penalty is unchanged).
4. Contact when change points on at least 4 channels, one of them on the
   pushed cane, fall within 1 s (the earliest such cluster's first change
   point is the contact time), **or** the pushed cane's acceleration spikes
   above 1.5 m/s^2 (deviation from the rolling mean, any axis, and more than
   6 times the local noise, so raised noise after contact is not a spike); the
   earlier of the two wins.
5. A trial with more than ``max_spikes`` separate spikes on the pushed cane is
   excluded (the paper excluded one such trial but gives no threshold).

The contact time maps onto the rig: the rig logs a sample every 0.5 s (its
unwrapped time stamps), and a partial trial keeps the rig samples strictly
before the contact time (``truncate_index`` samples).

Force-only detector, :func:`detect_force`: change points in the slope of force
against displacement after the contact onset (continuous piecewise-linear fit,
``ruptures`` ``clinear`` cost, penalty scaled by the noise variance), classified
as stiffening elbows (slope up: an obstruction), softening elbows, and force
drops (a fall of more than 30 gf between samples: a slip). The same truncation
rule applies: the trial ends at the first stiffening elbow or drop.
Both detectors are deterministic.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..data.imu import CHANNELS
from ..units import GF_TO_N

WINDOW = 20
PEN_FACTOR = 22.5
MIN_CHANNELS = 4
SPAN_S = 1.0
SPIKE_MS2 = 1.5
MAX_SPIKES = 5
DROP_GF = 30.0


@dataclass
class ContactResult:
    """Outcome of contact detection on one trial.

    Attributes
    ----------
    detected : bool
        Contact found.
    contact_time_s : float
        Contact time (s since the rig's first sample); NaN without contact.
    method : str
        ``"changepoints"``, ``"spike"``, ``"force"`` or ``""``.
    excluded : bool
        Too many spikes: the trial is dropped entirely.
    truncate_index : int or None
        Rig samples kept (``[:truncate_index]``) when partial; None keeps all.
    changepoints : dict
        Change-point times (s) per channel.
    spikes_s : list of float
        Times of the pushed-cane spikes.
    events : list of dict
        Force-only events (kind, index, displacement_mm, slopes / drop).
    """

    detected: bool
    contact_time_s: float
    method: str
    excluded: bool = False
    truncate_index: int | None = None
    changepoints: dict[str, list[float]] = field(default_factory=dict)
    spikes_s: list[float] = field(default_factory=list)
    events: list[dict] = field(default_factory=list)

    @property
    def status(self) -> str:
        """``"excluded"``, ``"partial"`` or ``"full"``, as the paper counts trials."""
        return "excluded" if self.excluded else "partial" if self.detected else "full"


def rig_index(contact_time_s: float, rig_time_s: np.ndarray) -> int:
    """Rig samples strictly before ``contact_time_s`` (the partial trial's length)."""
    return int(np.searchsorted(np.asarray(rig_time_s, float), contact_time_s, side="left"))


def _changepoints(x: np.ndarray, pen_factor: float, jump: int) -> list[int]:
    import ruptures as rpt

    n = len(x)
    bk = rpt.Binseg(model="rbf", min_size=jump, jump=jump).fit(x).predict(pen=pen_factor * np.log(n))
    return [b for b in bk if b < n]


def _cluster(cps: dict[str, list[float]], min_channels: int, span_s: float) -> float:
    """Earliest change point starting a ``span_s`` window with >= ``min_channels`` channels, one pushed."""
    events = sorted((t, ch) for ch, ts in cps.items() for t in ts)
    for t0, _ in events:
        chans = {ch for t, ch in events if t0 <= t <= t0 + span_s}
        if len(chans) >= min_channels and any(c.startswith("pushed") for c in chans):
            return t0
    return float("nan")


def _spikes(resid: np.ndarray, t: np.ndarray, thresh: float, local: float = 6.0) -> list[float]:
    """Start times of spikes on any pushed axis; samples < 0.25 s apart are one spike.

    A spike exceeds ``thresh`` and ``local`` times the channel's local noise (rolling
    2 s median absolute deviation), so raised noise after contact is not a run of spikes.
    """
    mad = pd.DataFrame(np.abs(resid)).rolling(80, center=True, min_periods=1).median().to_numpy() / 0.6745
    big = (np.abs(resid) > thresh) & (np.abs(resid) > local * mad)
    out: list[float] = []
    for i in np.nonzero(big.any(axis=1))[0]:
        if not out or t[i] - out[-1] > 0.25:
            out.append(float(t[i]))
    return out


def detect_imu(imu: pd.DataFrame, rig_time_s: np.ndarray | None = None, *, window: int = WINDOW,
               pen_factor: float = PEN_FACTOR, min_channels: int = MIN_CHANNELS, span_s: float = SPAN_S,
               spike_ms2: float = SPIKE_MS2, max_spikes: int = MAX_SPIKES, jump: int = 20) -> ContactResult:
    """The paper's IMU contact rule on one trial (see the module docstring).

    Parameters
    ----------
    imu : pandas.DataFrame
        ``time_s`` and the nine channels of :data:`canebench.data.imu.CHANNELS` (m/s^2, 40 Hz).
    rig_time_s : numpy.ndarray, optional
        Unwrapped rig times (s from its first sample); gives ``truncate_index``.
    window : int
        Rolling-mean window in samples (20: 0.5 s at 40 Hz).
    pen_factor : float
        Penalty ``pen_factor * log(n)`` of the binary segmentation (22.5).
    min_channels : int
        Channels that must change within ``span_s`` (4), one on the pushed cane.
    span_s : float
        Width of that window in seconds (1).
    spike_ms2 : float
        Spike threshold on the pushed cane's detrended acceleration (1.5 m/s^2).
    max_spikes : int
        More spikes than this and the trial is excluded (not given in the paper; 5).
    jump : int
        Candidate change points every ``jump`` samples (speed; 20 = 0.5 s).

    Returns
    -------
    ContactResult
    """
    t = imu["time_s"].to_numpy(float)
    raw = imu[list(CHANNELS)].to_numpy(float)
    trend = pd.DataFrame(raw).rolling(window, center=True, min_periods=1).mean().to_numpy()
    resid = raw - trend
    cps = {ch: [float(t[i]) for i in _changepoints(resid[:, k], pen_factor, jump)]
           for k, ch in enumerate(CHANNELS)}
    t_cp = _cluster(cps, min_channels, span_s)
    spikes = _spikes(resid[:, [CHANNELS.index(c) for c in CHANNELS if c.startswith("pushed")]], t, spike_ms2)
    t_sp = spikes[0] if spikes else float("nan")
    times = [(v, m) for v, m in ((t_cp, "changepoints"), (t_sp, "spike")) if np.isfinite(v)]
    tc, method = min(times) if times else (float("nan"), "")
    idx = rig_index(tc, rig_time_s) if times and rig_time_s is not None else None
    return ContactResult(bool(times), float(tc), method, len(spikes) > max_spikes, idx, cps, spikes)


def _hinge_onset(x: np.ndarray, y: np.ndarray) -> int:
    """Knee of the best flat-then-line fit over the early record (the contact onset)."""
    best, i_best = np.inf, 0
    for i0 in range(0, max(1, len(x) - 3)):
        c = float(y[: i0 + 1].mean()) if i0 >= 2 else float(y[0])
        xr, yr = x[i0:] - x[i0], y[i0:] - c
        b = float((xr @ yr) / (xr @ xr)) if xr @ xr > 0 else 0.0
        sse = float(((y[: i0 + 1] - c) ** 2).sum() + ((yr - b * xr) ** 2).sum())
        if sse < best:
            best, i_best = sse, i0
    return i_best


def _slope(x: np.ndarray, y: np.ndarray) -> float:
    return float(np.polyfit(x, y, 1)[0]) if len(x) >= 2 and np.ptp(x) > 0 else float("nan")


def detect_force(displacement_mm: np.ndarray, force_n: np.ndarray, *, onset_index: int | None = None,
                 pen_sigmas: float = 12.0, min_mm: float = 2.5, ratio: float = 2.0, min_change: float = 0.03,
                 drop_gf: float = DROP_GF, limit_n: float = 1000.0 * GF_TO_N,
                 contact_kinds: tuple[str, ...] = ("stiffening", "drop")) -> ContactResult:
    """Force-only detection: slope change points and drops in force against displacement.

    Parameters
    ----------
    displacement_mm, force_n : numpy.ndarray
        One rig trial, displacement in mm (0.5 mm steps), force in N (any tare).
    onset_index : int, optional
        Contact onset sample; default: the knee of a flat-then-line fit over the
        record up to the first 150 gf rise (a dead zone is not an elbow).
    pen_sigmas : float
        Penalty of the piecewise-linear fit: ``pen_sigmas * sigma^2 * log(n)``, sigma
        the load-cell noise from the second differences (median absolute deviation).
    min_mm : float
        Shortest segment between change points (mm).
    ratio, min_change : float
        A change point is an elbow when the slopes of the segments either side
        differ by a factor of ``ratio`` and by ``min_change`` N/mm.
    drop_gf : float
        A fall of more than this between consecutive samples is a drop (slip).
    limit_n : float
        Samples from the first at or above this (the rig's 1000 gf stop, tared) are ignored.
    contact_kinds : tuple of str
        Event kinds that make the trial partial (truncated at the first of them).

    Returns
    -------
    ContactResult
        ``events``: dicts with kind, index, displacement_mm, slope_before/after (N/mm)
        or drop_gf; ``truncate_index``: samples kept; time = index * 0.5 s.
    """
    import ruptures as rpt

    x, f = np.asarray(displacement_mm, float), np.asarray(force_n, float)
    if onset_index is None:
        rise = f - np.minimum.accumulate(f)
        big = rise > 150 * GF_TO_N
        end = min(len(f), max((int(np.argmax(big)) if big.any() else len(f)) + 3, 8))
        onset_index = _hinge_onset(x[:end], f[:end])
    i0 = int(onset_index)
    over = np.nonzero(f - f[i0] >= limit_n)[0]
    i1 = int(over[0]) if len(over) else len(f)
    events: list[dict] = []
    for i in np.nonzero(np.diff(f[i0:i1]) < -drop_gf * GF_TO_N)[0] + i0 + 1:
        events.append({"kind": "drop", "index": int(i), "displacement_mm": float(x[i]),
                       "drop_gf": float((f[i - 1] - f[i]) / GF_TO_N)})
    xs, fs = x[i0:i1], f[i0:i1]
    step = float(np.median(np.diff(x))) if len(x) > 1 else 0.5
    min_size = max(3, int(round(min_mm / step)))
    if len(fs) >= 2 * min_size + 1:
        sigma = float(np.median(np.abs(np.diff(fs, 2))) / 0.6745 / np.sqrt(6)) or 1e-6
        bk = rpt.Pelt(model="clinear", min_size=min_size, jump=1).fit(fs.reshape(-1, 1)).predict(
            pen=pen_sigmas * sigma**2 * np.log(len(fs)))
        edges = [0, *bk]
        drops = {e["index"] - i0 for e in events}
        for a, b, c in zip(edges[:-2], edges[1:-1], edges[2:]):
            if any(abs(b - d) <= 2 for d in drops):
                continue  # a slip, already reported
            s1, s2 = _slope(xs[a:b + 1], fs[a:b + 1]), _slope(xs[b:c], fs[b:c])
            if min(s1, s2) < 0 and any(a < d < c for d in drops):
                continue  # a falling segment made by a slip inside it, not an elbow
            kind = ("stiffening" if s2 > ratio * max(s1, 0) and s2 - s1 > min_change else
                    "softening" if s1 > ratio * max(s2, 0) and s1 - s2 > min_change else "")
            if kind:
                events.append({"kind": kind, "index": int(b + i0), "displacement_mm": float(x[b + i0]),
                               "slope_before": s1, "slope_after": s2})
    events.sort(key=lambda e: e["index"])
    cut = [e["index"] for e in events if e["kind"] in contact_kinds]
    idx = min(cut) if cut else None
    return ContactResult(bool(cut), 0.5 * idx if cut else float("nan"), "force" if cut else "", False, idx,
                         events=events)
