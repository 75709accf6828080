"""Engine backends. Each module compiles a :class:`canebench.model.chain.Chain` for
one engine; the harness drives them all with the same probe protocol."""
