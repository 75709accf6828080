"""``canebench backends``: registered backends, versions, availability, configuration per protocol."""

from __future__ import annotations

import argparse
import warnings


def add_parser(sub: argparse._SubParsersAction) -> None:
    b = sub.add_parser("backends", help="list registered backends, versions, availability")
    b.add_argument("-v", "--verbose", action="store_true", help="show each backend's full configuration per protocol")
    b.set_defaults(fn=main)


def main(a: argparse.Namespace) -> int:
    from ..probe.protocol import PROTOCOLS
    from ..registry import ENTRY_POINT_GROUP, discover

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        reg = discover()
    print(f"entry-point group: {ENTRY_POINT_GROUP}")
    for name, info in sorted(reg.items()):
        state = f"available, {info.kind}, version {info.version}" if info.available else f"UNAVAILABLE: {info.reason}"
        print(f"{name:12s} {state}  [{info.target}]  tags={','.join(info.tags)}")
        if info.available:
            b = info.cls()
            for p in PROTOCOLS.values():
                st = b.settings(p)
                ans = b.answer(p) if hasattr(b, "answer") else info.kind
                if a.verbose:
                    print(f"    {p.name}: answer={ans}; {st}")
                else:
                    print(f"    {p.name}: answer={ans}; integrator={st.get('integrator')}; dt={st.get('dt')}; "
                          f"springs={st.get('springs')}")
                if ans == "quasi-static":
                    print("        (quasi-static: no engine time step is taken; the answer tests the engine's "
                          "kinematics, inverse dynamics and the chain's compilation, not its integrator)")
    return 0

