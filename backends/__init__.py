"""Engine backends. Each module compiles a :class:`canebench.chain.Chain` for
one engine; the harness drives them all with the same probe protocol."""
