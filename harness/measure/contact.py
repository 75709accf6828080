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
   samples (0.5 s at the default 20; the penalty is unchanged). The cost is
   :mod:`canebench.measure.kernel_cost`'s, ``ruptures``' own summed ahead.
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

Force-only detector, :func:`detect_force` (for rig logs without IMU, such as
the published field trials): slips and elbows in force against displacement.

* Slips: a fall of more than 30 gf (the rig analysis' threshold), a run of
  falling samples counted once; a fall that only undoes a one-sample jump is a
  load-cell spike, not a slip.
* Elbows: binary segmentation with a significance test. On a stretch, the best
  continuous two-segment (hinge) fit is compared with one line (slips enter as
  level shifts); the improvement is measured in units of the trace's own noise
  (robust scale and lag-1 autocorrelation of its residuals about a running line
  over two minimal segments, as a long-run variance) and kept when it exceeds the
  99th percentile of its maximum under no change, simulated for that exact design.
  Segments are at least 5 samples (2.5 mm, the field fit's minimum) long.
* Classification by the slopes either side: *stiffening* when the slope at
  least doubles while the cane already pushes back (contact force above the field
  fit's 20 gf, for at least a minimal segment since the onset): a second body at
  least as stiff as the cane engaging; *onset* for the same turn before that (the
  contact itself); *softening* when it halves (an early stiff stretch giving way);
  a turn and back within two minimal segments to the former slope is a *dip* or
  *bump*; a significant but smaller change is a *bend* (curvature).
* Truncation rule, as for the IMU: the trial is partial from the first
  stiffening elbow or slip (``truncate_index`` samples kept).

Both detectors are deterministic.
"""

from __future__ import annotations

import functools
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
ALPHA = 0.01
MIN_SEGMENT_SAMPLES = 5
SLOPE_RATIO = 2.0
CONTACT_KINDS = ("stiffening", "drop")
CONTACT_GF = 20.0  # the field fit's "in contact": tared force above 20 gf


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
    onset_index: int | None = None
    noise: dict = field(default_factory=dict)

    @property
    def status(self) -> str:
        """``"excluded"``, ``"partial"`` or ``"full"``, as the paper counts trials."""
        return "excluded" if self.excluded else "partial" if self.detected else "full"


def rig_index(contact_time_s: float, rig_time_s: np.ndarray) -> int:
    """Rig samples strictly before ``contact_time_s`` (the partial trial's length)."""
    return int(np.searchsorted(np.asarray(rig_time_s, float), contact_time_s, side="left"))


def _changepoints(x: np.ndarray, pen_factor: float, jump: int, cost=None) -> list[int]:  # noqa: ANN001
    """``ruptures.Binseg`` change points of one channel (its end left out).

    ``cost`` defaults to :class:`~canebench.measure.kernel_cost.CostRbfPrefix`, the rbf cost with
    constant-time segments (the same change points as ``ruptures``' own rbf cost, about 4x sooner:
    ``canebench bench --contact``); pass ``ruptures.costs.CostRbf()`` for the original.
    """
    import ruptures as rpt

    from .kernel_cost import CostRbfPrefix

    n = len(x)
    cost = CostRbfPrefix(step=jump) if cost is None else cost
    bk = rpt.Binseg(custom_cost=cost, min_size=jump, jump=jump).fit(x).predict(pen=pen_factor * np.log(n))
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


def imu_residuals(imu: pd.DataFrame, window: int = WINDOW) -> np.ndarray:
    """The nine channels (n, 9) minus their centred ``window``-sample rolling mean: what the rule segments."""
    raw = imu[list(CHANNELS)].to_numpy(float)
    return raw - pd.DataFrame(raw).rolling(window, center=True, min_periods=1).mean().to_numpy()


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
    resid = imu_residuals(imu, window)
    cps = {ch: [float(t[i]) for i in _changepoints(resid[:, k], pen_factor, jump)]
           for k, ch in enumerate(CHANNELS)}
    t_cp = _cluster(cps, min_channels, span_s)
    spikes = _spikes(resid[:, [CHANNELS.index(c) for c in CHANNELS if c.startswith("pushed")]], t, spike_ms2)
    t_sp = spikes[0] if spikes else float("nan")
    times = [(v, m) for v, m in ((t_cp, "changepoints"), (t_sp, "spike")) if np.isfinite(v)]
    tc, method = min(times) if times else (float("nan"), "")
    idx = rig_index(tc, rig_time_s) if times and rig_time_s is not None else None
    return ContactResult(bool(times), float(tc), method, len(spikes) > max_spikes, idx, cps, spikes)


def onset_index(force_n: np.ndarray, displacement_mm: np.ndarray) -> int:
    """Contact onset as the field fit finds it (:func:`canebench.measure.field.extract_field_stiffness`, step 4).

    The knee of a flat-then-line fit over the record up to the first 150 gf rise
    (plus 3 samples, at least 8); a knee before the third sample means there is no
    flat stretch, and contact starts at the first sample. Same function and
    constants as the field fit, so a partial trial's onset is the whole trial's.
    """
    from .field import ONSET_LINE_SAMPLES, ONSET_SEARCH_GF, _hinge_onset

    f, x = np.asarray(force_n, float), np.asarray(displacement_mm, float)
    rise = f - np.minimum.accumulate(f)
    big = rise > ONSET_SEARCH_GF * GF_TO_N
    end = max(min(len(f), (int(np.argmax(big)) if big.any() else len(f)) + ONSET_LINE_SAMPLES), min(len(f), 8))
    i0, _ = _hinge_onset(x[:end], f[:end])
    return i0 if i0 >= 2 else 0


def drops(force_n: np.ndarray, i0: int, i1: int, drop_gf: float = DROP_GF) -> list[dict]:
    """Falls of more than ``drop_gf`` in ``force_n[i0:i1]``: slips.

    A fall is a run of consecutive falling samples (one slip may take two
    samples of the 0.5 s log); its size is the force before the run minus the
    force at its end. ``index`` is the run's first (fallen) sample, so a trial
    truncated there keeps everything before the slip. A fall that only undoes a
    one-sample jump (it ends within ``drop_gf`` of the line through the four
    samples before the jump) is a load-cell spike, kind ``"spike"``, not a slip.
    """
    f = np.asarray(force_n, float)
    out: list[dict] = []
    i = i0 + 1
    while i < i1:
        if f[i] < f[i - 1]:
            j = i
            while j + 1 < i1 and f[j + 1] < f[j]:
                j += 1
            fall = (f[i - 1] - f[j]) / GF_TO_N
            if fall > drop_gf:
                # a one-sample spike falls back onto the trend before it (the line through the
                # four samples before the jump); a slip falls below it
                k = np.arange(max(0, i - 5), i - 1)
                spike = len(k) >= 3 and f[j] >= np.polyval(np.polyfit(k, f[k], 1), j) - drop_gf * GF_TO_N
                out.append({"kind": "spike" if spike else "drop", "index": int(i), "samples": int(j - i + 1),
                            "drop_gf": float(fall)})
            i = j + 1
        else:
            i += 1
    return out


def _orth(Z: np.ndarray) -> np.ndarray:
    q, _ = np.linalg.qr(Z)
    return q


def _resid(Q: np.ndarray, Y: np.ndarray) -> np.ndarray:
    return Y - Q @ (Q.T @ Y)


def _hinge_basis(x: np.ndarray, cands: np.ndarray) -> np.ndarray:
    return np.maximum(x[:, None] - x[cands][None, :], 0.0)


def _scan(rH: np.ndarray, den: np.ndarray, ry: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Best continuous hinge per column of ``ry``: its candidate index and ``dSSE``, the drop in the
    residual sum of squares from one line to the two-segment fit."""
    proj = rH.T @ ry  # m x S
    dsse = proj**2 / den[:, None]
    best = np.argmax(dsse, axis=0)
    return best, dsse[best, np.arange(ry.shape[1])]


@functools.lru_cache(maxsize=512)
def _critical(key: tuple, alpha: float, n_sim: int = 2000) -> float:
    """(1 - alpha) quantile of ``max dSSE / sigma^2`` under no change (white noise), by simulation.

    The maximum over candidate knees does not follow a chi-square law (the knee is
    searched for), so its null distribution is simulated for the exact design:
    same abscissae, candidates and level-shift columns; fixed seed, cached.
    """
    xb, cands, steps = key
    x = np.frombuffer(xb, float)
    Z = _design(x, list(steps))
    Q = _orth(Z)
    rH = _resid(Q, _hinge_basis(x, np.asarray(cands)))
    den = (rH**2).sum(axis=0)
    Y = np.random.default_rng(20240612).normal(size=(len(x), n_sim))
    _, w = _scan(rH, den, _resid(Q, Y))
    return float(np.quantile(w, 1.0 - alpha))


def _design(x: np.ndarray, steps: list[int]) -> np.ndarray:
    """Line (1, x) plus one level-shift column per slip inside the stretch."""
    cols = [np.ones_like(x), x - x.mean()]
    cols += [(np.arange(len(x)) >= s).astype(float) for s in steps if 0 < s < len(x)]
    return np.column_stack(cols)


def noise(y: np.ndarray, steps: list[int], half: int) -> tuple[float, float]:
    """The trace's noise from its own residuals: standard deviation and lag-1 autocorrelation.

    Residuals about a running line (least squares over ``2 half + 1`` samples,
    within each stretch between slips): an elbow is a slope change sustained
    over a minimal segment on each side, so whatever the trace does at a shorter
    scale (stick-slip ripple, load-cell noise) is noise for the detector.
    Robust to the few windows that straddle a knee: the scale is the median
    absolute deviation (corrected for the window's own fit), and ``rho`` comes
    from the same robust scale of the residuals' first differences
    (``Var(e_t - e_t-1) = 2 s^2 (1 - rho)``), clipped to [0, 0.9]. The knee test
    divides by the long-run variance ``s^2 (1 + rho) / (1 - rho)``, so serially
    correlated noise needs a larger improvement than white noise to count.
    """
    y = np.asarray(y, float)
    w = 2 * half + 1
    bounds = [0, *[s for s in steps if 0 < s < len(y)], len(y)]
    res = []
    t = np.arange(w) - half
    kern = np.vstack([np.ones(w) / w, t / (t @ t)])  # running mean and slope at the centre
    for a, b in zip(bounds[:-1], bounds[1:]):
        if b - a >= w:
            seg = y[a:b]
            mean = np.convolve(seg, kern[0][::-1], "valid")
            res.append(seg[half:len(seg) - half] - mean)
    if not res:
        return float("nan"), 0.0
    mad = lambda v: 1.4826 * float(np.median(np.abs(v - np.median(v))))  # noqa: E731
    r = np.concatenate(res)
    s = mad(r) / np.sqrt(1.0 - 1.0 / w)
    d = np.concatenate([np.diff(v) for v in res if len(v) > 1])
    rho = 1.0 - (mad(d) / np.sqrt(1.0 - 1.0 / w)) ** 2 / (2 * s * s) if s > 0 else 0.0
    return s, float(min(max(rho, 0.0), 0.9))


def _test(x: np.ndarray, y: np.ndarray, steps: list[int], min_samples: int, alpha: float,
          var: float) -> dict | None:
    """Best continuous two-segment fit of ``y(x)`` against one line; None when no knee is allowed.

    ``W = dSSE / var``, ``var`` the trace's long-run noise variance (:func:`noise`), against
    the ``1 - alpha`` quantile of its maximum under no change (:func:`_critical`).
    Knees leave at least ``min_samples`` samples on each side (the knee sample counts
    on both) and are not next to a slip (which the level-shift column explains).
    """
    n = len(x)
    cands = np.array([c for c in range(min_samples - 1, n - min_samples + 1)
                      if all(abs(c - s) > 1 and abs(c + 1 - s) > 1 for s in steps)], int)
    if len(cands) == 0 or n < 2 * min_samples + 1:
        return None
    xs = (x - x[0]) / (x[-1] - x[0])  # the statistic is invariant to an affine change of x
    Z = _design(xs, steps)
    Q = _orth(Z)
    rH = _resid(Q, _hinge_basis(xs, cands))
    den = (rH**2).sum(axis=0)
    best, dsse = _scan(rH, den, _resid(Q, y[:, None]))
    key = (np.round(xs, 9).tobytes(), tuple(int(c) for c in cands), tuple(int(s) for s in steps))
    return {"knee": int(cands[best[0]]), "W": float(dsse[0] / var), "critical": _critical(key, alpha)}


def _line(x: np.ndarray, y: np.ndarray, steps: list[int]) -> tuple[float, float, float]:
    """Slope of ``y(x)`` (a level shift at each slip inside the stretch), its t statistic, the fitted end value.

    The standard error is inflated by ``(1 + rho) / (1 - rho)``, ``rho`` the residuals'
    lag-1 autocorrelation (clipped to [0, 0.9]), as in the knee test.
    """
    Z = _design(x, steps)
    coef, *_ = np.linalg.lstsq(Z, y, rcond=None)
    e = y - Z @ coef
    dof = len(y) - Z.shape[1]
    end = float(Z[-1] @ coef)
    if dof < 1:
        return float(coef[1]), float("nan"), end
    sse = max(float(e @ e), 1e-300)
    rho = min(max(float(e[1:] @ e[:-1]) / sse, 0.0), 0.9)
    cov = np.linalg.pinv(Z.T @ Z) * sse / dof * (1 + rho) / (1 - rho)
    return float(coef[1]), float(coef[1] / np.sqrt(cov[1, 1])) if cov[1, 1] > 0 else float("inf"), end


def _norm_ppf(p: float) -> float:
    from scipy.stats import norm

    return float(norm.ppf(p))


def detect_force(displacement_mm: np.ndarray, force_n: np.ndarray, *, onset: int | None = None,
                 alpha: float = ALPHA, min_samples: int = MIN_SEGMENT_SAMPLES, ratio: float = SLOPE_RATIO,
                 drop_gf: float = DROP_GF, contact_gf: float = CONTACT_GF, limit_n: float = 1000.0 * GF_TO_N,
                 contact_kinds: tuple[str, ...] = CONTACT_KINDS) -> ContactResult:
    """Force-only detection: elbows in the slope of force against displacement, and slips.

    1. Contact onset as the field fit finds it (:func:`onset_index`, its tare);
       samples from the first raw reading at or above ``limit_n`` (the rig's
       1000 gf stop, which the field fit also drops) are ignored.
    2. Slips (:func:`drops`): falls of more than ``drop_gf`` after the onset.
       Each becomes a level-shift column in every fit below, so a slip is not
       read as an elbow.
    3. Noise (:func:`noise`): robust scale and lag-1 autocorrelation of the
       residuals about a running line over ``2 min_samples + 1`` samples, as a
       long-run variance ``s^2 (1 + rho) / (1 - rho)``.
    4. Binary segmentation from the first sample: on a stretch, the best
       continuous two-segment (hinge) fit is compared with one line; the knee is
       kept when the improvement over the noise variance exceeds the
       ``1 - alpha`` quantile of its maximum under no change (simulated for the
       exact design, :func:`_critical`). Both sides are then searched again.
       Segments are at least ``min_samples`` long.
    5. Features: consecutive knees turning the same way less than two minimal
       segments apart are one (rounded) elbow; a turn and back within two
       minimal segments, with the slope after within ``ratio`` of the slope
       before, is a ``dip`` or ``bump``. Each feature is classified by the
       slopes of the segments either side (each fitted on its own, with its t
       statistic against the same long-run variance):

       * ``stiffening``: the slope after is significantly positive and at least
         ``ratio`` times the slope before, while the cane already pushes back
         (contact force at the knee above ``contact_gf``, the field fit's 20 gf,
         and at least a minimal segment since the onset): a second body at
         least as stiff as the cane engaging;
       * ``onset``: the same turn before that (the contact itself begins);
       * ``softening``: the slope before is significantly positive and at least
         ``ratio`` times the slope after (an early stiff stretch giving way);
       * ``bend``: a significant knee with a smaller change (curvature).
    6. The trial is partial from the first event of ``contact_kinds`` on (default:
       stiffening elbows and slips): ``truncate_index`` keeps the samples before a
       slip, or up to and including an elbow's knee.

    Parameters
    ----------
    displacement_mm, force_n : numpy.ndarray
        One rig trial, displacement in mm (0.5 mm steps), force in N (the raw reading, any tare).
    onset : int, optional
        Contact onset sample (default :func:`onset_index`).
    alpha : float
        Significance level of each knee test and of the slopes' t tests (0.01).
    min_samples : int
        Shortest segment, in samples (5: 2.5 mm, the field fit's minimum for a slope).
    ratio : float
        Slope ratio separating an elbow from curvature (2).
    drop_gf : float
        A slip is a fall of more than this (30 gf, the rig analysis' threshold).
    contact_gf : float
        Contact force (above the tare) below which a stiffening turn is the onset (20 gf).
    limit_n : float
        The rig's force stop on the raw reading (N).
    contact_kinds : tuple of str
        Event kinds that make the trial partial.

    Returns
    -------
    ContactResult
        ``events``: dicts with kind, index, displacement_mm and, for knees,
        end_mm, knees, slope_before/slope_after (N/mm), ratio, W, critical; for
        slips and spikes drop_gf and samples. ``truncate_index``: samples kept;
        time = index * 0.5 s. ``noise``: the trace's sigma (gf) and rho.
    """
    x, f = np.asarray(displacement_mm, float), np.asarray(force_n, float)
    i0 = onset_index(f, x) if onset is None else int(onset)
    over = np.nonzero(f[i0:] >= limit_n)[0]
    i1 = i0 + int(over[0]) if len(over) else len(f)
    events = drops(f, i0, i1, drop_gf)
    for e in events:
        e["displacement_mm"] = float(x[e["index"]])
    slips = [e["index"] for e in events if e["kind"] == "drop"]
    xs, fs = x[:i1], f[:i1].copy()  # knees from the first sample: the contact onset is one (kind "onset")
    for e in events:  # a load-cell spike carries nothing about the cane: its sample is bridged
        k = e["index"] - 1
        if e["kind"] == "spike" and 0 < k < len(fs) - 1:
            fs[k] = 0.5 * (fs[k - 1] + fs[k + 1])
    z = float(_norm_ppf(1.0 - alpha))
    tare = float(f[: i0 + 1].mean()) if i0 >= 2 else float(f[0])  # the field fit's tare
    knees: dict[int, dict] = {}

    def split(a: int, b: int, var: float) -> None:  # stretch [a, b) of xs
        st = [s - a for s in slips if a < s < b]
        r = _test(xs[a:b], fs[a:b], st, min_samples, alpha, var)
        if r is None or not r["W"] > r["critical"]:
            return
        c = a + r["knee"]
        knees[c] = r
        split(a, c + 1, var)
        split(c, b, var)

    sd, rho = noise(fs, slips, min_samples)
    if len(xs) >= 2 * min_samples + 1 and sd > 0:
        split(0, len(xs), sd * sd * (1 + rho) / (1 - rho))
    edges = sorted(knees)
    bounds = [0, *edges, len(xs) - 1]
    seg = []  # (slope, t statistic, fitted value at its end) of each segment between knees
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        seg.append(_line(xs[lo:hi + 1], fs[lo:hi + 1], [s - lo for s in slips if lo < s <= hi]))
    near = 2 * min_samples  # knees closer than two minimal segments belong to one feature
    # a rounded elbow shows as consecutive knees turning the same way: one event, from the
    # slope before the first knee to the slope after the last
    groups: list[list[int]] = []
    for k, c in enumerate(edges):
        up = seg[k + 1][0] > seg[k][0]
        last = groups[-1][-1] if groups else None
        if last is not None and c - edges[last] < near and up == (seg[last + 1][0] > seg[last][0]):
            groups[-1].append(k)
        else:
            groups.append([k])
    def contact(c: int) -> bool:  # loaded at knee c: contact force above the field fit's 20 gf
        k = edges.index(c)
        return (seg[k][2] - tare) / GF_TO_N > contact_gf

    # a dip (or a bump) is a turn one way and back within two minimal segments, after which the
    # slope is back within the ratio of the slope before: a transient, not a change of stiffness
    merged: list[list[int]] = []
    for g in groups:
        if merged:
            h = merged[-1]
            s_in, s_out = seg[h[0]][0], seg[g[-1] + 1][0]
            if (edges[g[0]] - edges[h[-1]] < near and s_in > 0 and s_out > 0 and contact(edges[h[0]])
                    and max(s_in, s_out) < ratio * min(s_in, s_out)
                    and (seg[h[-1] + 1][0] > seg[h[0]][0]) != (seg[g[-1] + 1][0] > seg[g[0]][0])):
                merged[-1] = h + g
                continue
        merged.append(g)
    start = i0  # contact onset: the field fit's, or a later onset knee
    for g in merged:
        c = edges[g[0]]
        (s1, t1, f_knee), (s2, t2, _) = seg[g[0]], seg[g[-1] + 1]
        turn = [seg[k + 1][0] > seg[k][0] for k in g]
        # the cane already pushes back at the knee: a contact force above the field fit's 20 gf
        # (below it no stiffness is measurable) over at least a minimal segment since the onset
        in_contact = (f_knee - tare) / GF_TO_N > contact_gf and c - start >= min_samples - 1
        if not all(turn) and any(turn):
            kind = "dip" if not turn[0] else "bump"
        elif s2 > s1 and t2 > z and s2 >= ratio * max(s1, 0.0):
            kind = "stiffening" if in_contact else "onset"
        elif s1 > s2 and t1 > z and in_contact and s1 >= ratio * max(s2, 0.0):
            kind = "softening"
        else:
            kind = "bend"
        if kind == "onset":
            start = edges[g[-1]]
        r = max((knees[edges[k]] for k in g), key=lambda v: v["W"] / v["critical"])
        events.append({"kind": kind, "index": int(c), "displacement_mm": float(x[c]),
                       "end_mm": float(x[edges[g[-1]]]), "knees": len(g),
                       "slope_before": s1, "slope_after": s2,
                       "ratio": s2 / s1 if s1 > 0 else float("nan"),
                       "W": r["W"], "critical": r["critical"]})
    events.sort(key=lambda e: e["index"])
    cut = [e["index"] + (1 if e["kind"] != "drop" else 0) for e in events if e["kind"] in contact_kinds]
    idx = min(cut) if cut else None
    return ContactResult(bool(cut), 0.5 * idx if cut else float("nan"), "force" if cut else "", False, idx,
                         events=events, onset_index=i0, noise={"sigma_gf": sd / GF_TO_N, "rho": rho})
