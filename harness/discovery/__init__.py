"""Discovery: find where simulation and measurement disagree, name the missing
physical effect from the library (:mod:`canebench.model.effects`), add it to
the model and show the gap shrink out of sample (``canebench discover``)."""
