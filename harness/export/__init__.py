"""Export a cane's chain for other simulators: MJCF, SDFormat, URDF (+ spring sidecar).

* :mod:`.mjcf` - MuJoCo, built with ``MjSpec`` (the same builder the MuJoCo backend compiles);
* :mod:`.sdf` - SDFormat 1.7 with joint springs in ``<dynamics>``;
* :mod:`.urdf` - URDF and a YAML sidecar with the joint springs URDF cannot hold;
* :mod:`.population` - populations drawn from a modulus distribution and caliper uncertainty;
* :mod:`.bundle` - writing a set and its manifest (``canebench export``).

Engines are imported by the format modules only, so importing this package is cheap.
"""

from .bundle import FORMATS, ExportResult, export_canes, export_population, parse_formats

__all__ = ["FORMATS", "ExportResult", "export_canes", "export_population", "parse_formats"]
