"""DART (dartpy) backend: the chain as a skeleton of universal joints.

Each link hangs from a ``UniversalJoint`` (axis 1 = link x, axis 2 = link y
after the first rotation, i.e. the same RX-then-RY pair as every other
backend) with ``setSpringStiffness`` / ``setDampingCoefficient``, which DART
integrates implicitly. The probe force is an external force on the probe
link (``addExtForce``, cleared by every world step).

DART has no built-in PID, so both protocols use the harness PID, explicit,
once per step:

* ``paper``: 25 us, as the reference.
* ``fast``: the largest step below 0.9 x the explicit limit of the PD on the
  mass the probe feels, 2 m_eff / Kd (and 2 sqrt(m_eff / Kp)), computed from
  DART's own mass matrix and Jacobian at rest, capped at 1 ms. (Measured: the
  limit is conservative; runs at 1x to 4x it stayed stable and exact.) Joint springs
  and damping stay implicit, so the PID is the only limit.
"""

from __future__ import annotations

from typing import Any

import dartpy as dart
import numpy as np

from canebench.model.chain import Chain
from canebench.probe.protocol import Protocol
from canebench.probe.stability import choose_step, pid_limit, probe_effective_mass

from .base import DynamicBackend, Simulation


def chain_to_dart(chain: Chain) -> tuple[dart.simulation.World, dart.dynamics.Skeleton]:
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
    return world, skel


class DartSimulation(Simulation):
    native_pid = False

    def __init__(self, chain: Chain, dt: float) -> None:
        self.world, self.skel = chain_to_dart(chain)
        self.dt = dt
        self.world.setTimeStep(dt)
        self.body = self.skel.getBodyNode(chain.push_link)
        self.offset = chain.local(chain.push_link, chain.push_point)
        self.u = np.asarray(chain.direction, float)
        self.p0 = chain.push_point.copy()

    def read(self) -> tuple[float, float]:
        p = self.body.getWorldTransform().multiply(self.offset)
        v = self.body.getLinearVelocity(self.offset)
        return float(self.u @ (p - self.p0)), float(self.u @ v)

    def step(self, force: float) -> None:
        self.body.addExtForce(force * self.u, self.offset, False, True)
        self.world.step()

    def effective_mass(self) -> float:
        J = self.body.getLinearJacobian(self.offset)  # columns: the dofs the body depends on (serial: the first ones)
        Ju = np.zeros(self.skel.getNumDofs())
        Ju[: J.shape[1]] = self.u @ J
        return probe_effective_mass(self.skel.getMassMatrix(), Ju)

    def health(self) -> str | None:
        q = self.skel.getPositions()
        if not np.all(np.isfinite(q)):
            return "DART state is not finite"
        return None


class DartBackend(DynamicBackend):
    name = "dart"
    tags = ("dynamic", "implicit-springs", "harness-pid")
    engine_module = "dartpy"

    def step_for(self, chain: Chain, proto: Protocol) -> tuple[float, float]:
        """(time step, explicit PD limit) for ``chain`` under ``proto``."""
        if proto.controller != "engine":
            return proto.dt, float("nan")
        m_eff = DartSimulation(chain, proto.dt).effective_mass()
        lim = pid_limit(m_eff, proto.kp, proto.kd)
        return choose_step(lim, ceiling=proto.dt, safety=0.9), lim

    def settings(self, proto: Protocol) -> dict[str, Any]:
        fast = proto.controller == "engine"
        return {
            "engine": "dart",
            "version": self.engine_version(),
            "integrator": "semi-implicit Euler with implicit joint springs/damping",
            "dt": "per chain: largest of 1 ms..1 us below 0.9 x explicit PD limit" if fast else proto.dt,
            "substeps": 1,
            "springs": "implicit (joint spring stiffness)",
            "damping": "implicit (joint damping coefficient)",
            "pid": "harness PID, explicit external force, once per step",
            "why": ("DART has no implicit PID; only the explicit PD on the probe mass limits the step" if fast
                    else "paper reference: 40 kHz"),
        }

    def build(self, chain: Chain, proto: Protocol) -> DartSimulation:
        dt, _ = self.step_for(chain, proto)
        return DartSimulation(chain, dt)
