"""canebench: benchmark harness for pseudo-rigid-body models of blueberry canes.

The pipeline is one intermediate representation passed along a line::

    cane description (YAML)  ->  Chain (links, joints, stiffness, mass)  ->  backend
    probe protocol (harness) ->  force/displacement samples  ->  stiffness  ->  score

Only the harness reads YAML or field CSVs; backends only compile a
:class:`canebench.model.chain.Chain`, step it and read it.
"""

__version__ = "0.1.0"
