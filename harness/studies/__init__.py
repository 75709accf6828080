"""Studies built on the runner: engine agreement, convergence, benchmarks.

Each is a plain function returning a result object with ``.to_df()``; the
:data:`STUDIES` registry names them for the command line and for plugins.
"""

from __future__ import annotations

from typing import Callable

from ..registry import Registry

STUDIES: Registry[Callable] = Registry("study")


def _register_builtin() -> None:
    from .agreement import run_agreement
    from .convergence import converge
    from .contact import contact_study
    from .modulus import modulus_study
    from .paper import morris_study, naive_case, sweep_study

    STUDIES.add("agreement", run_agreement, ("engines", "gate"),
                "every trial on every chain engine against Pinocchio's exact statics; regression gate")
    STUDIES.add("convergence", converge, ("beam", "discretization"),
                "beam convergence and chain/beam stiffness against segment count, per formula")
    STUDIES.add("naive", naive_case, ("paper", "engines"), "the paper's naive case on every engine")
    STUDIES.add("morris", morris_study, ("paper", "sensitivity"), "Method of Morris per trial and engine (SALib)")
    STUDIES.add("sweep", sweep_study, ("paper", "calibration"), "modulus x diameter factor sweep, 5 x 5")
    STUDIES.add("contact", contact_study, ("paper", "field"),
                "contact detection: IMU change points (the paper's rule) and a force-only detector")
    STUDIES.add("modulus", modulus_study, ("paper", "material"),
                "three-point bending: flexural modulus by season, variety and age; Welch t-tests; distributions")


_register_builtin()
