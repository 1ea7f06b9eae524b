"""Mitsuba 3: Mitsuba's process-wide state, the LLVM library and the variant lock
(``runtime``); renders of built-in exact scenes or XML files (``render``); BSDF, microfacet
and emitter samplers as batch sample/pdf pairs (``samplers``); planted faults (``faults``);
the failure-aware chi-square and weight checks (``checks``); the catalogue of samplers they
run on (``catalogue``).  Mitsuba is imported only when one of them is used."""
