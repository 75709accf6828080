"""DART (dartpy) backend: the chain as a skeleton of universal joints.

Each link hangs from a ``UniversalJoint`` (axis 1 = link x, axis 2 = link y
after the first rotation, i.e. the same RX-then-RY pair as every other
backend) with ``setSpringStiffness`` / ``setDampingCoefficient``, which DART
integrates implicitly. The probe force is an external force on the probe
link (``addExtForce``, cleared by every world step).

DART has no built-in PID, so both protocols use the harness PID, once per step:

* ``paper``: explicit, at 25 us, as the reference.
* ``fast``: the harness PID with its P and D parts made *implicit* (see
  :meth:`DartSimulation.run_controlled`), at the largest of 5 ms ... 25 us
  below 0.9 x the stability limit of that discrete closed loop
  (:func:`implicit_pd_spectral_radius`, :func:`implicit_step`). With the
  explicit PID (the former fast scheme, below) stiff chains (20 links at
  8 GPa, the Method of Morris' corners) needed 0.2-0.25 ms, i.e. 4000-5000
  DART steps per 1 s setpoint and 4 s per trial; the implicit loop runs them
  at 1-5 ms. A step is taken only if the linearized loop is also stable at
  twice it (:data:`IMPLICIT_SAFETY`): its limit moves during a push (at 0.9 x
  the limit two of 20 Morris points of a real trial became unsettled mid-push).
  On the 54 bundled trials (5 ms on 26, 4 ms on 21, 2.5 ms on 7) the
  stiffness moves by at most 2.2e-4 from the explicit loop's (all at 2.5 ms:
  1e-4; all at 1 ms: 4e-5; first order in h) and agrees with Pinocchio's
  statics to 1.1e-3 (explicit: 1.2e-3); the 54 trials cost 7.9 s instead of
  33 s (``canebench agree``).

The explicit scheme (the ``paper`` loop, and ``fast`` with ``implicit_pd=False``,
:meth:`DartBackend.step_for`): the largest step (capped at the protocol's 1 ms)
below 0.9 x the stability limit of the *discrete closed loop* DART actually integrates:
  semi-implicit Euler whose joint springs and damping are implicit, i.e.
  ``(M + h D + h^2 K) qdd = -K (q + h qd) - D qd + J^T u F``, with the
  harness PID force ``F`` evaluated explicitly from the state at the start of
  the step. The limit is found from the spectral radius of that linear map
  (built from DART's own mass matrix, joint coefficients and probe Jacobian at
  rest), see :func:`closed_loop_spectral_radius`.

  An earlier rule used the explicit PD limit on the bare probe mass,
  ``2 m_eff / Kd``; it ignores that the implicit joint damping stiffens the
  step's response (the ``h D`` term), so it was 1.1x-5x too conservative and
  sent ten of the 54 bundled trials to 0.25-0.8 ms. A single-mode PD bound on
  the implicit mass is not enough either (b4c2t3 passes it at 1 ms and
  diverges); the full linear map predicts that trial's measured boundary
  (stable at 0.9 ms, divergent at 1 ms, analysis 0.93 ms). Gravity's
  configuration stiffness is left out of the map: it moves the radius by
  ~1e-5. The limit moves by under 2 % over a whole push (rest vs. the last
  sample), well inside the 0.9 safety factor. The stiffness these larger
  steps give agrees with the old small steps to ~1e-5 relative.

Per step the loop (:meth:`DartSimulation.run_controlled`) keeps the Python
around a 2-5 us DART step small: the probe point is a ``SimpleFrame`` child of
the probe link, whose world transform and velocity dartpy reads 5-7x faster
than the ``BodyNode`` accessors (same numbers, bit for bit); the projections
on the probe direction and the force vector are done in Python floats. The
skeleton has no collision shapes and no enforced joint limits, so it is not
registered with the constraint solver, which would otherwise run an empty
collision query and constraint scan every step (same numbers, bit for bit).
"""

from __future__ import annotations

from typing import Any, Callable

import dartpy as dart
import numpy as np

from canebench.model.chain import Chain
from canebench.probe.protocol import Protocol
from canebench.probe.stability import choose_step

from .base import DynamicBackend, Simulation

#: The step is the largest choice below this fraction of the closed-loop limit.
SAFETY = 0.9
#: the implicit loop is taken at h only if it is also stable at h / IMPLICIT_SAFETY (its limit moves during a push)
IMPLICIT_SAFETY = 0.5


def chain_to_dart(chain: Chain) -> tuple[dart.simulation.World, dart.dynamics.Skeleton]:
    """Build a DART world holding ``chain`` as a skeleton of universal joints.

    Parameters
    ----------
    chain : Chain
        The backend-agnostic chain.

    Returns
    -------
    world : dartpy.simulation.World
    skel : dartpy.dynamics.Skeleton
        The cane, already added to ``world``.
    """
    world = dart.simulation.World()
    world.setGravity(np.asarray(chain.gravity, float))
    opts = world.getDeactivationOptions()
    opts.mEnabled = False  # a slowly pushed cane must never be put to sleep
    skel = dart.dynamics.Skeleton("cane")
    parent = None
    for j in range(chain.n_links):
        joint, body = skel.createUniversalJointAndBodyNodePair(parent)
        R, p = chain.relative_pose(j)
        T = dart.math.Isometry3()
        T.set_rotation(R)
        T.set_translation(p)
        joint.setTransformFromParentBodyNode(T)
        joint.setAxis1(np.array([1.0, 0.0, 0.0]))
        joint.setAxis2(np.array([0.0, 1.0, 0.0]))
        for k in (0, 1):
            joint.setSpringStiffness(k, float(chain.stiffness[j]))
            joint.setDampingCoefficient(k, float(chain.damping))
            joint.setRestPosition(k, 0.0)
        body.setMass(float(chain.masses[j]))
        body.setMomentOfInertia(*[float(v) for v in chain.inertias[j]], 0.0, 0.0, 0.0)
        body.setLocalCOM(np.array([0.0, 0.0, chain.lengths[j] / 2]))
        parent = body
    world.addSkeleton(skel)
    # No shapes, no enforced limits: nothing for the constraint solver to do.
    # Unregistering the skeleton skips its (empty) collision query and
    # constraint scan each step; the dynamics are bit-for-bit the same.
    world.getConstraintSolver().removeSkeleton(skel)
    return world, skel


def closed_loop_spectral_radius(M: np.ndarray, K: np.ndarray, D: np.ndarray, c: np.ndarray, h: float,
                                 kp: float, ki: float, kd: float) -> float:
    """Spectral radius of one DART step with the explicit harness PID, linearized.

    DART's step (semi-implicit Euler, implicit joint springs and damping)::

        (M + h D + h^2 K) qdd = -K (q + h qd) - D qd + c^T F
        qd' = qd + h qdd,   q' = q + h qd'

    with the harness PID evaluated from the state at the start of the step
    (setpoint 0, derivative on the measured velocity, forward-rectangle
    integral updated before use)::

        I' = I - h c q,   F = -kp c q - kd c qd + ki I'

    Gravity (an explicit, configuration-dependent torque) and the Coriolis
    terms (zero at rest) are left out: gravity moves the radius by ~1e-5.

    Parameters
    ----------
    M : (n, n) array
        Joint-space mass matrix.
    K, D : (n,) arrays
        Joint spring stiffness and damping coefficients (diagonal).
    c : (n,) array
        Probe-direction row of the probe point's Jacobian, ``u^T J``.
    h : float
        Time step (s).
    kp, ki, kd : float
        PID gains.

    Returns
    -------
    float
        Largest eigenvalue modulus of the (2n + 1)-state map (q, qd, I); the
        loop is stable iff it is below 1.
    """
    n = len(K)
    Minv = np.linalg.inv(M + np.diag(h * D + h * h * K))
    # generalized force = Tq q + Tqd qd + TI I
    Tq = -np.diag(K) - np.outer(c, (kp + ki * h) * c)
    Tqd = -np.diag(h * K + D) - kd * np.outer(c, c)
    TI = ki * c
    A = np.zeros((2 * n + 1, 2 * n + 1))
    A[n:2 * n, :n] = h * Minv @ Tq
    A[n:2 * n, n:2 * n] = np.eye(n) + h * Minv @ Tqd
    A[n:2 * n, 2 * n] = h * Minv @ TI
    A[:n] = h * A[n:2 * n]  # q' = q + h qd'
    A[:n, :n] += np.eye(n)
    A[2 * n, :n] = -h * c
    A[2 * n, 2 * n] = 1.0
    return float(np.abs(np.linalg.eigvals(A)).max())


def implicit_pd_spectral_radius(M: np.ndarray, K: np.ndarray, D: np.ndarray, c: np.ndarray, h: float,
                                kp: float, ki: float, kd: float) -> float:
    """Spectral radius of one DART step with the harness PID made implicit (linearized).

    The step of :func:`closed_loop_spectral_radius`, with the probe force chosen so
    that it equals the PID law at the *end* of the step (P and D implicit, the
    integral updated from the start of the step as the protocol's law does)::

        F = (F_e - alpha a0) / (1 + alpha beta),   alpha = kd h + kp h^2
        F_e = kp (-x - h v) + ki I' - kd v,        beta = c (M + h D + h^2 K)^-1 c^T

    ``a0``, the probe's acceleration without the probe force, is estimated from the
    previous step (``(v - v_prev) / h - beta F_prev``), so the state is
    ``(q, qd, I, F_prev, v_prev)``. Setpoint 0, gravity and Coriolis terms left out
    as in the explicit map.

    Returns
    -------
    float
        Largest eigenvalue modulus of the (2n + 3)-state map; stable iff below 1.
    """
    n = len(K)
    Minv = np.linalg.inv(M + np.diag(h * D + h * h * K))
    beta = float(c @ Minv @ c)
    alpha = kd * h + kp * h * h
    N = 2 * n + 3
    E = np.eye(N)
    iI, iF, iv = 2 * n, 2 * n + 1, 2 * n + 2
    X = np.zeros(N)
    X[:n] = c
    V = np.zeros(N)
    V[n:2 * n] = c
    I_new = E[iI] - h * X
    F_e = kp * (-X - h * V) + ki * I_new - kd * V
    a0 = (V - E[iv]) / h - beta * E[iF]
    F = (F_e - alpha * a0) / (1.0 + alpha * beta)
    T = np.zeros((n, N))
    T[:, :n] = -np.diag(K)
    T[:, n:2 * n] = -np.diag(h * K + D)
    qdd = Minv @ (T + np.outer(c, F))
    A = np.zeros((N, N))
    A[n:2 * n] = E[n:2 * n] + h * qdd
    A[:n] = E[:n] + h * A[n:2 * n]
    A[iI], A[iF], A[iv] = I_new, F, V
    return float(np.abs(np.linalg.eigvals(A)).max())


#: steps the implicit fast loop may take, largest first (each divides the protocol's 1 s period)
IMPLICIT_STEPS = (5e-3, 4e-3, 2.5e-3, 2e-3, 1e-3, 8e-4, 5e-4, 4e-4, 2.5e-4, 2e-4, 1e-4, 5e-5, 2.5e-5)


def implicit_step(sim: "DartSimulation", proto: Protocol, steps: tuple[float, ...] = IMPLICIT_STEPS,
                  safety: float = IMPLICIT_SAFETY) -> float:
    """The largest of ``steps`` at which the implicit loop is stable with margin.

    A step ``h`` is taken when the linearized loop (:func:`implicit_pd_spectral_radius`
    at ``sim``'s rest configuration) is stable at ``h`` and at ``h / safety``; the
    list is searched from the top, so only a few eigenvalue problems are solved
    per chain. Returns the smallest choice when none is stable.
    """
    M, K, D, c = sim.linear_model()
    for h in steps:
        if all(implicit_pd_spectral_radius(M, K, D, c, hh, proto.kp, proto.ki, proto.kd) < 1.0
               for hh in (h, h / safety)):
            return h
    return steps[-1]


class DartSimulation(Simulation):
    """One chain in a DART world, stepped with the probe force applied explicitly.

    Parameters
    ----------
    chain : Chain
    dt : float
        Time step (s).
    """

    native_pid = False

    def __init__(self, chain: Chain, dt: float, implicit_pd: bool = False) -> None:
        self.world, self.skel = chain_to_dart(chain)
        self.dt = dt
        self.world.setTimeStep(dt)
        self.implicit_pd = implicit_pd
        self._f_prev = self._v_prev = 0.0  # the implicit loop's memory (force and probe speed of the last step)
        self._beta: float | None = None
        self.body = self.skel.getBodyNode(chain.push_link)
        self.offset = chain.local(chain.push_link, chain.push_point)
        self.u = np.asarray(chain.direction, float)
        self.p0 = chain.push_point.copy()
        # The probe point as a frame rigidly attached to the probe link: a pure
        # observer (not part of the skeleton, no mass), read through dartpy far
        # more cheaply than BodyNode.getWorldTransform / getLinearVelocity(offset).
        T = dart.math.Isometry3()
        T.set_translation(self.offset)
        self.probe = dart.dynamics.SimpleFrame(self.body, "probe", T)

    def read(self) -> tuple[float, float]:
        px, py, pz = self.probe.getWorldTransform().translation().tolist()
        vx, vy, vz = self.probe.getLinearVelocity().tolist()
        (ux, uy, uz), (qx, qy, qz) = self.u.tolist(), self.p0.tolist()
        return (px - qx) * ux + (py - qy) * uy + (pz - qz) * uz, vx * ux + vy * uy + vz * uz

    def step(self, force: float) -> None:
        self.body.addExtForce(force * self.u, self.offset, False, True)
        self.world.step()

    def run_controlled(self, controller: Callable[[float, float], float], n_steps: int, tail: int) -> float:
        """The harness PID, explicit (the base-class loop, inlined) or with implicit P and D.

        With ``implicit_pd`` (the fast protocol) and a :class:`~canebench.probe.protocol.PID`
        controller, see :meth:`_run_implicit`; otherwise the explicit loop below.
        """
        if self.implicit_pd and all(hasattr(controller, a) for a in ("kp", "ki", "kd", "integral", "setpoint")):
            return self._run_implicit(controller, n_steps, tail)
        return self._run_explicit(controller, n_steps, tail)

    def set_step(self, dt: float) -> None:
        """Change the time step (before the first step)."""
        self.dt = dt
        self.world.setTimeStep(dt)
        self._beta = None

    def beta(self) -> float:
        """``c (M + h D + h^2 K)^-1 c^T`` at rest: the probe's speed change per unit force and step, over h."""
        if self._beta is None:
            M, K, D, c = self.linear_model()
            h = self.dt
            self._beta = float(c @ np.linalg.solve(M + np.diag(h * D + h * h * K), c))
        return self._beta

    def _run_implicit(self, pid: Any, n_steps: int, tail: int) -> float:
        """The protocol's PID law with its P and D parts evaluated at the *end* of each step.

        DART applies an external force explicitly, so the force is chosen such
        that it equals the law at the state the step will reach::

            F = kp (sp - x') + ki I - kd v',   v' = v + h (a0 + beta F),   x' = x + h v'

        i.e. ``F = (F_e - alpha a0) / (1 + alpha beta)`` with
        ``F_e = kp (sp - x - h v) + ki I - kd v`` and ``alpha = kd h + kp h^2``;
        ``I`` is updated from the start of the step (forward rectangle, as the law
        says). ``beta`` (:meth:`beta`) is DART's own linear response at rest, and
        ``a0``, the probe's acceleration without the probe force, comes from the
        previous step (``(v - v_prev) / h - beta F_prev``). With these two
        estimates the applied force equals the law exactly whenever the probe is
        settled (``v`` and its change vanish), whatever the error in ``beta`` (an
        error there only moves the stability limit): the sampled force is the
        force that holds the sampled state, as in the explicit loop; while the
        probe creeps at ``v`` they differ by about ``kp h v``. The implicit P and D remove the explicit loop's step limit
        ``~2 m_eff / kd``; what remains is found by :func:`implicit_step`.
        """
        frame_tf, frame_vel = self.probe.getWorldTransform, self.probe.getLinearVelocity
        add_force, world_step = self.body.addExtForce, self.world.step
        offset = self.offset
        (ux, uy, uz), (qx, qy, qz) = self.u.tolist(), self.p0.tolist()
        force = np.zeros(3)
        h, kp, ki, kd, sp = self.dt, pid.kp, pid.ki, pid.kd, pid.setpoint
        alpha = kd * h + kp * h * h
        beta = self.beta()
        den = 1.0 + alpha * beta
        f_prev, v_prev = self._f_prev, self._v_prev
        integral = pid.integral
        vmax = 0.0
        start_tail = n_steps - tail
        for i in range(n_steps):
            px, py, pz = frame_tf().translation().tolist()
            vx, vy, vz = frame_vel().tolist()
            v = vx * ux + vy * uy + vz * uz
            x = (px - qx) * ux + (py - qy) * uy + (pz - qz) * uz
            integral += (sp - x) * h
            f = (kp * (sp - x - h * v) + ki * integral - kd * v - alpha * ((v - v_prev) / h - beta * f_prev)) / den
            force[0], force[1], force[2] = f * ux, f * uy, f * uz
            add_force(force, offset, False, True)
            world_step()
            f_prev, v_prev = f, v
            if i >= start_tail and abs(v) > vmax:
                vmax = abs(v)
        pid.integral = integral
        self._f_prev, self._v_prev = f_prev, v_prev
        return vmax

    def _run_explicit(self, controller: Callable[[float, float], float], n_steps: int, tail: int) -> float:
        """The base-class loop (read, ``controller(x, v)``, apply, step) with
        :meth:`read` and :meth:`step` inlined.

        A DART step of this chain costs only 2-5 us, so the Python around it
        matters as much: dartpy methods are bound once, and the 3-vector
        projections and the force vector are done in Python floats (numpy
        calls on 3-vectors cost ~0.5 us each). Same law and the same float
        operations as :meth:`read` / :meth:`step`, so the result is bit for bit
        the base-class loop's (tests/test_dart_speed.py).
        """
        frame_tf, frame_vel = self.probe.getWorldTransform, self.probe.getLinearVelocity
        add_force, world_step = self.body.addExtForce, self.world.step
        offset = self.offset
        (ux, uy, uz), (qx, qy, qz) = self.u.tolist(), self.p0.tolist()
        force = np.zeros(3)  # reused: addExtForce copies it
        vmax = 0.0
        start_tail = n_steps - tail
        for i in range(n_steps):
            px, py, pz = frame_tf().translation().tolist()
            vx, vy, vz = frame_vel().tolist()
            v = vx * ux + vy * uy + vz * uz
            f = controller((px - qx) * ux + (py - qy) * uy + (pz - qz) * uz, v)
            force[0], force[1], force[2] = f * ux, f * uy, f * uz
            add_force(force, offset, False, True)
            world_step()
            if i >= start_tail and abs(v) > vmax:
                vmax = abs(v)
        return vmax

    def linear_model(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """DART's own linearization data at the current configuration.

        Returns
        -------
        M : (n, n) array
            Mass matrix.
        K, D : (n,) arrays
            Joint spring stiffness and damping coefficients, in dof order.
        c : (n,) array
            ``u^T J`` for the probe point (zero for dofs beyond the probe link).
        """
        n = self.skel.getNumDofs()
        K, D = np.zeros(n), np.zeros(n)
        for j in range(self.skel.getNumJoints()):
            joint = self.skel.getJoint(j)
            for k in range(joint.getNumDofs()):
                i = joint.getIndexInSkeleton(k)
                K[i] = joint.getSpringStiffness(k)
                D[i] = joint.getDampingCoefficient(k)
        J = self.body.getLinearJacobian(self.offset)  # columns: the dofs the body depends on (serial: the first ones)
        c = np.zeros(n)
        c[: J.shape[1]] = self.u @ J
        return self.skel.getMassMatrix(), K, D, c

    def health(self) -> str | None:
        q = self.skel.getPositions()
        if not np.all(np.isfinite(q)):
            return "DART state is not finite"
        return None


def closed_loop_limit(sim: DartSimulation, proto: Protocol, lo: float = 1e-6, hi: float = 1e-2,
                      ratio: float = 1.25) -> float:
    """Smallest step (s) at which DART + the explicit harness PID goes unstable for ``sim``'s chain.

    The loop is linearized at ``sim``'s current (rest) configuration
    (:func:`closed_loop_spectral_radius`). Steps are scanned upward from
    ``lo`` by ``ratio`` and the first unstable bracket is bisected (on log h),
    so every step below the answer is stable even if stability were not
    monotone in h further up (on the 54 bundled trials it is: one crossing
    each). An unstable window narrower than ``ratio`` could be missed.

    Parameters
    ----------
    sim : DartSimulation
    proto : Protocol
        Supplies the PID gains.
    lo, hi : float
        Scan range (s): ``hi`` is returned if the loop is stable up to it,
        ``lo`` if it is not stable even there.
    ratio : float
        Scan ratio between successive steps.

    Returns
    -------
    float
        The limit, to 1e-4 relative.
    """
    M, K, D, c = sim.linear_model()

    def stable(h: float) -> bool:
        return closed_loop_spectral_radius(M, K, D, c, h, proto.kp, proto.ki, proto.kd) < 1.0

    if not stable(lo):
        return lo
    h = lo
    while h < hi:
        nxt = min(h * ratio, hi)
        if not stable(nxt):
            a, b = h, nxt  # stable, unstable
            while b / a > 1.0 + 1e-4:
                mid = float(np.sqrt(a * b))
                a, b = (mid, b) if stable(mid) else (a, mid)
            return a
        h = nxt
    return hi


class DartBackend(DynamicBackend):
    name = "dart"
    tags = ("dynamic", "implicit-springs", "harness-pid")
    engine_module = "dartpy"

    def step_for(self, chain: Chain, proto: Protocol) -> tuple[float, float]:
        """Time step for ``chain`` under ``proto``, and the stability limit it was chosen from.

        Returns
        -------
        dt : float
            ``proto.dt`` for the paper protocol; for ``fast``, the largest
            choice not above ``proto.dt`` and below ``SAFETY`` x the limit.
        limit : float
            The closed-loop stability limit (s), NaN for the paper protocol.
        """
        if proto.controller != "engine":
            return proto.dt, float("nan")
        sim = DartSimulation(chain, proto.dt)
        lim = closed_loop_limit(sim, proto)
        return choose_step(lim, ceiling=proto.dt, safety=SAFETY), lim

    #: fast protocol: the harness PID with implicit P and D (False: the explicit loop of :meth:`step_for`)
    implicit_pd: bool = True

    def settings(self, proto: Protocol) -> dict[str, Any]:
        fast = proto.controller == "engine"
        implicit = fast and self.implicit_pd
        return {
            "engine": "dart",
            "version": self.engine_version(),
            "integrator": "semi-implicit Euler with implicit joint springs/damping",
            "dt": ("per chain: largest of 5 ms..25 us stable with margin (h and h/0.9) in the linearized closed "
                   "loop with the implicit-PD harness PID" if implicit else
                   "per chain: largest of 1 ms..1 us below 0.9 x the stability limit of DART's step with the "
                   "explicit PID (linearized closed loop, implicit springs/damping included)") if fast else proto.dt,
            "substeps": 1,
            "springs": "implicit (joint spring stiffness)",
            "damping": "implicit (joint damping coefficient)",
            "pid": ("harness PID law, P and D evaluated at the end of the step through DART's linearized one-step "
                    "response (external force), integral explicit" if implicit else
                    "harness PID, explicit external force, once per step"),
            "constraints": "none (no shapes, no enforced limits; skeleton not in the constraint solver)",
            "why": ("DART has no implicit PID; the explicit PID's step limit (~2 m_eff/Kd) is removed by making P "
                    "and D implicit, as MuJoCo's and Exudyn's PIDs are" if implicit else
                    "DART has no implicit PID; the explicit PID on the probe is the only step limit, taken from "
                    "the discrete closed loop since DART's implicit damping raises it well above 2 m_eff/Kd"
                    if fast else "paper reference: 40 kHz"),
        }

    def build(self, chain: Chain, proto: Protocol) -> DartSimulation:
        if proto.controller == "engine" and self.implicit_pd:
            sim = DartSimulation(chain, IMPLICIT_STEPS[0], implicit_pd=True)
            sim.set_step(implicit_step(sim, proto))
            return sim
        dt, _ = self.step_for(chain, proto)
        return DartSimulation(chain, dt)
